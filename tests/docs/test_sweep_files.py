"""The campaign's sweep files under docs/experiments/ train their preset's units one seed per unit:
every unit's config is the preset unit's with `seeds` narrowed to one of its seeds, a fork forks
that seed's own parent, and the files' units together with the units that finished before them
are exactly the preset's, seed by seed (docs/experiments/campaign.md). An algorithm whose seeds
share one vmapped update (RNAC in the campaign's code) keeps the preset's units as they are. A
catch-all file (the whole preset, one seed per unit, run after the others: their units are done
and skipped) trains what they leave."""

import dataclasses
from pathlib import Path

import pytest

from adarl.sweeps import spec
from adarl.train import launch

EXPERIMENTS = Path(__file__).parents[2] / "docs/experiments"
# preset -> (its sweep files, the (task, label) pairs that finished in units of the preset itself)
CAMPAIGN = {
    "table1-ant-humanoid": (
        (
            "table1-ant-humanoid/table1-humanoid-sac.yaml",
            "table1-ant-humanoid/table1-humanoid.yaml",
            "table1-ant-humanoid/table1-ant-rest.yaml",
            "table1-ant-humanoid/table1-rnac.yaml",
        ),
        {
            ("ant", "sac-sparse_sparse_width-256"),
            ("ant", "sac-parseval_parseval_coef-0.001"),
            ("ant", "sac-parseval_parseval_coef-0.0001"),
            ("ant", "sac-parseval_parseval_coef-1e-05"),
        },
    ),
    # session 26 (results/ lost): seeds 2-4, then SAC 0-1, then the whole preset for AdaRL 0-1
    # (finished on 2026-12-06, run again for their controls' fork point) and the controls 0-1
    "paper-schedule-walker2d": (
        (
            "paper-schedule-walker2d/paper-schedule-walker2d-seeds-2-4.yaml",
            "paper-schedule-walker2d/paper-schedule-walker2d-sac-0-1.yaml",
        ),
        set(),
    ),
}
#: preset -> its catch-all file, and the (label, seed) pairs only it trains
CATCH_ALL = {
    "paper-schedule-walker2d": (
        "paper-schedule-walker2d/paper-schedule-walker2d.yaml",
        {
            (label, seed)
            for label in ("adarl_rank_rule-cumulative", "adarl-control-eq5")
            for seed in (0, 1)
        },
    ),
}
PRESET_UNITS = {"rnac"}  # in the preset's units of five (f7f5ab1's RNAC vmapped a run's seeds)


def _seed_units(units):
    """(task, label, seed) -> (unit, its preset seeds)."""
    return {(u.task, u.label, s): u for u in units for s in u.seeds}


@pytest.mark.parametrize("preset", sorted(CAMPAIGN))
def test_each_sweep_file_trains_its_presets_units_one_seed_per_unit(preset):
    files, finished_before = CAMPAIGN[preset]
    expected = _seed_units(spec.load(preset).units)
    got = {}
    for name in files:
        for unit in spec.load(str(EXPERIMENTS / name)).units:
            for seed in unit.seeds:
                key = (unit.task, unit.label, seed)
                assert key not in got, f"{key} twice"
                got[key] = unit
    finished = {k for k in expected if (k[0], k[1]) in finished_before}
    assert len(finished) == 5 * len(finished_before)  # the preset's five seeds of each
    catch_all, left = CATCH_ALL.get(preset, (None, set()))
    left = {k for k in expected if (k[1], k[2]) in left}
    assert set(got) == set(expected) - finished - left
    if catch_all:
        units = spec.load(str(EXPERIMENTS / catch_all)).units
        assert set(_seed_units(units)) == set(expected)  # the whole preset, one seed per unit
        got.update({k: u for k, u in _seed_units(units).items() if k in left})
    for key, unit in got.items():
        of_preset = expected[key]
        if unit.algo in PRESET_UNITS:  # the preset's unit itself
            assert (unit.id, unit.config, unit.start) == (of_preset.id, of_preset.config, of_preset.start)  # fmt: skip
            continue
        assert len(unit.seeds) == 1, unit.id
        assert unit.id == f"{unit.task}/{unit.label}/seeds-{key[2]}"
        assert unit.total_steps == of_preset.total_steps
        assert dataclasses.replace(unit.config, seeds=of_preset.config.seeds) == of_preset.config
        assert list(unit.config.seeds) == [key[2]]
        if isinstance(of_preset.start, launch.ForkOf):  # the seed's own parent, at the same point
            parent = of_preset.start.parent.rsplit("/seeds-", 1)[0] + f"/seeds-{key[2]}"
            assert unit.start == dataclasses.replace(of_preset.start, parent=parent)
        else:  # the same flags but --seeds
            assert unit.start.flags["seeds"] == str(key[2])
            flags = {**unit.start.flags, "seeds": of_preset.start.flags["seeds"]}
            assert dataclasses.replace(unit.start, flags=flags) == of_preset.start
