"""The rank columns of train.csv against truncations.csv, when several seeds train in one run: a
seed's rank changes only at a truncation step, to that truncation's new rank (one lane per seed,
each narrowed to its own ranks). Expected truncation steps and decisions are worked out here
from the schedule and the ranks, not by the trainer's functions."""

from __future__ import annotations

from collections import defaultdict

import pytest

from adarl.algos import sac_config
from adarl.algos.sac_config import SAC_FAMILY
from adarl.runs.logs import read_csv
from adarl.train import sac_family, trainers


def smoke_config(**overrides):
    values = {
        **SAC_FAMILY["adarl"],
        **sac_config.PRESETS["smoke"],
        "algo": "adarl",
        "task": "hopper",
    }
    return sac_config.SACConfig(**{**values, **overrides})


def expected_truncation_steps(c: sac_config.SACConfig) -> list[int]:
    """Chunk ends (every update_every steps) from update_after on run update_every gradient
    steps each; a truncation happens once truncate_every of them have run since the last."""
    steps, updates, since = [], 0, 0
    for end in range(c.update_every, c.total_steps + 1, c.update_every):
        if end >= c.update_after:
            updates += c.update_every
            since += c.update_every
        if since >= c.truncate_every:
            steps.append(end)
            since = 0
    return steps


def expected_decision(old: int, candidate: int, new: int) -> str:
    """docs/run-format.md: accepted (the cut was made), retained (the retain clause kept the
    old rank), unchanged (the rule proposed no cut: the candidate is the old rank)."""
    if candidate == old:
        return "unchanged"
    return "accepted" if new == candidate else "retained"


@pytest.mark.parametrize(
    "truncated, expected",
    [
        ((5, 5, 5), "unchanged"),  # candidate = old rank: nothing to accept
        ((1, 1, 1), "unchanged"),  # rank 1: the floor
        ((64, 64, 64), "unchanged"),
        ((5, 3, 3), "accepted"),
        ((5, 3, 5), "retained"),
        ((64, 1, 1), "accepted"),
    ],
)
def test_truncation_decision(truncated, expected):
    assert sac_family.truncation_decision(*truncated) == expected
    assert expected_decision(*truncated) == expected


def test_a_seeds_rank_changes_only_at_its_truncations(tmp_path):
    config = smoke_config(
        seeds=(1, 0, 2), rank_rule="cumulative", truncate_every=100, total_steps=900,
        log_every=50, eval_every=900, checkpoint_every=900,
    )  # fmt: skip
    run_dir = tmp_path / "run"
    trainers.train(config, run_dir, progress=False)
    cuts = read_csv(run_dir / "truncations.csv")
    steps = expected_truncation_steps(config)
    assert steps == [550, 650, 750, 850]
    assert sorted({int(r["step"]) for r in cuts}) == steps
    cut = {(int(r["step"]), int(r["seed"]), r["layer"]): r for r in cuts}
    assert len(cut) == len(cuts) == len(steps) * 3 * 3  # steps x seeds x layers, once each
    for r in cuts:
        old, proposed = int(r["old_rank"]), int(r["proposed_rank"])
        candidate, new = int(r["candidate_rank"]), int(r["new_rank"])
        assert candidate == max(1, min(old, proposed))
        assert r["decision"] == expected_decision(old, candidate, new), r

    rows = read_csv(run_dir / "train.csv")
    layers = [c.removeprefix("rank_") for c in rows[0] if c.startswith("rank_")]
    assert sorted(layers) == ["actor_1", "q1_1", "q2_1"]
    history = defaultdict(list)  # (seed, layer) -> [(step, rank)] in step order
    for row in rows:
        for layer in layers:
            history[int(row["seed"]), layer].append((int(row["step"]), int(row[f"rank_{layer}"])))
    width = config.hidden[0]
    for (seed, layer), series in history.items():
        assert [s for s, _ in series] == list(range(500, 901, 50))  # logged once updating
        previous = width  # full width before the first truncation
        for step, rank_ in series:
            if step in steps:
                row = cut[step, seed, layer]
                assert int(row["old_rank"]) == previous, (seed, layer, step)
                assert rank_ == int(row["new_rank"]), (seed, layer, step, rank_, row)
            else:
                assert rank_ == previous, f"seed {seed} {layer}: {previous} -> {rank_} at {step}"
            previous = rank_
    # some seed after the first has a rank above the first seed's: a shared width taken from
    # the wrong seeds would cut it (seeds 1, 0, 2 in this order for that; else the test is blind)
    first = config.seeds[0]
    assert any(
        int(r["new_rank"]) > int(cut[int(r["step"]), first, r["layer"]]["new_rank"])
        for r in cuts
        if int(r["seed"]) != first
    ), "no seed ranks above the first: pick other seeds"


def test_a_rule_that_proposes_no_cut_is_logged_unchanged(tmp_path):
    """The ratio rule (Eq. 7) at β = 1e-9 proposes the full width: no σ_ℓ/σ_1 of a float32
    SVD of a full-rank product is that small, so the candidate is the old rank: `unchanged`,
    and the rank is kept."""
    config = smoke_config(
        seeds=(0,), rank_rule="ratio", beta=1e-9, truncate_every=100, total_steps=550,
        log_every=550, eval_every=550, checkpoint_every=550,
    )  # fmt: skip
    trainers.train(config, tmp_path / "run", progress=False)
    cuts = read_csv(tmp_path / "run" / "truncations.csv")
    assert len(cuts) == 3 and {r["step"] for r in cuts} == {"550"}
    width = str(config.hidden[0])
    for r in cuts:
        assert r["old_rank"] == r["candidate_rank"] == r["new_rank"] == width, r
        assert r["decision"] == "unchanged", r
    last = read_csv(tmp_path / "run" / "train.csv")[-1]
    assert {last["rank_actor_1"], last["rank_q1_1"], last["rank_q2_1"]} == {width}
