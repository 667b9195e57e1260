"""The algorithm registry: the protocol roles the report reads instead of algorithm names, and
the configs it resolves."""

import dataclasses
import json
from pathlib import Path

import pytest

from adarl.algos import registry
from adarl.algos.config import RunConfig


def test_protocol_roles_come_from_the_registry():
    roles = {
        name: {role: registry.role(name, role) for role in ("adapts_rank", "rank_sweep", "best_of")}
        for name in registry.ALGOS
    }
    assert [n for n, r in roles.items() if r["adapts_rank"]] == ["adarl"]
    assert [n for n, r in roles.items() if r["rank_sweep"]] == ["sac-fixed-rank"]
    assert {n: r["best_of"] for n, r in roles.items() if r["best_of"]} == {
        "sac-parseval": "parseval_coef"
    }
    # a run of an algorithm this version does not know plays no role
    assert registry.role("td3", "adapts_rank") is False and registry.role("td3", "best_of") is None
    assert registry.REFERENCE in registry.ALGOS
    assert set(registry.REPORT_ORDER) <= set(registry.ALGOS)


# every algorithm × preset × task (and none), resolved by the registry before the config spine
# (adarl 2c09826): each class's defaults, and per case the fields that differ from them
RESOLVED = json.loads((Path(__file__).parents[1] / "data" / "resolved-configs.json").read_text())
# fields added since, with the value every config had before them
TASK_FIELDS = {"env_kwargs": "", "env_module": ""}  # issue 53: any Gymnasium id
ADDED = {
    "RNACConfig": {"algo": "rnac", "max_episode_steps": 1000, **TASK_FIELDS},
    "SACConfig": {"backend": "host", "device_solver": "xml", **TASK_FIELDS},
}
# fields retired since (registry.Algorithm.retired_fields), with the value every config had
RETIRED = {"SACConfig": {"lanes": 0}}


def _plain(config) -> dict:
    return json.loads(json.dumps(dataclasses.asdict(config)))


@pytest.mark.parametrize("case", sorted(RESOLVED["resolved"]))
def test_configs_resolve_to_the_values_they_always_had(case):
    algo, preset, *words = case.split()
    flags = dict(zip([w.removeprefix("--") for w in words[::2]], words[1::2], strict=True))
    config = registry.resolve_config(algo, preset, flags)
    name = type(config).__name__
    want = {**RESOLVED["class_defaults"][name], **ADDED.get(name, {})}
    want = {**want, **RESOLVED["resolved"][case]}
    for field, value in RETIRED.get(name, {}).items():
        assert want.pop(field) == value == registry.get(algo).retired_fields[field].today
    assert _plain(config) == want


def test_the_cases_cover_every_algorithm_and_preset():
    covered = {tuple(case.split()[:2]) for case in RESOLVED["resolved"]}
    assert covered == {(a.name, p) for a in registry.ALGORITHMS.values() for p in a.presets}


@pytest.mark.parametrize("algo", registry.ALGOS)
def test_every_algorithm_has_a_trainer_and_a_valid_default_config(algo):
    from adarl.train.trainers import trainer

    assert callable(trainer(algo))
    flags = {"rank": 7} if algo == "sac-fixed-rank" else {}
    config = registry.resolve_config(algo, flags=flags)
    assert isinstance(config, RunConfig) and config.algo == algo
