"""Issue 55 §4: the loop's behaviour that planted bugs got past: each seed's evaluation runs
from its own environment seed (1,000,000 + s), a NaN evaluation return is never a seed's best,
and a resumed truncations.csv keeps the legacy column set its header has."""

from __future__ import annotations

import math
from types import SimpleNamespace

from synthetic_runs import policy_arrays

from adarl.envs import rollout
from adarl.runs import layout
from adarl.train import loop as loop_module
from adarl.train.sac_family import LEGACY_TRUNCATION_COLUMNS, TRUNCATION_COLUMNS


class Recorder:
    def __init__(self):
        self.rows = []

    def write(self, *args):
        self.rows.append(args)


def fake_learner(seeds, **config):
    config = {"on_divergence": "stop", "task": "hopper", "eval_episodes": 2, **config}
    return SimpleNamespace(
        config=SimpleNamespace(**config),
        seeds=list(seeds),
        policies=lambda: [policy_arrays(11, 3, s) for s in seeds],
        env_options={},
        extra_logs={layout.TRUNCATIONS_CSV: (TRUNCATION_COLUMNS, LEGACY_TRUNCATION_COLUMNS)},
    )


def test_each_seed_is_evaluated_from_its_own_environment_seed(tmp_path, monkeypatch):
    calls = []

    def run_episodes(policy, task, label, episodes, seed, **options):
        calls.append((label, seed))
        return [{"episode": e, "return": 10.0 * e, "length": 5} for e in range(episodes)]

    monkeypatch.setattr(rollout, "run_episodes", run_episodes)
    learner = fake_learner([3, 7, 0], eval_dynamics=("nominal", "paper"))
    loop = loop_module.Loop(learner, tmp_path, progress=False)
    loop.logs, loop.tb = {layout.EVAL_CSV: Recorder()}, Recorder()
    loop.step = 500
    loop.evaluate()
    want = [(label, 1_000_000 + s) for s in (3, 7, 0) for label in ("nominal", "paper")]
    assert calls == want


def test_a_nan_evaluation_return_is_never_the_best():
    arrays = policy_arrays(11, 3, 0)
    best = loop_module.BestPolicies([0, 1])
    best.offer(0, 100, math.nan, arrays)  # first: still not a best
    assert 0 not in best.record
    best.offer(0, 200, 50.0, arrays)
    best.offer(0, 300, math.nan, arrays)  # after: the finite one stays
    best.offer(0, 400, math.inf, arrays)
    assert best.record[0] == {"step": 200, "return": 50.0}
    best.offer(1, 100, -math.inf, arrays)
    assert 1 not in best.record and set(best.checkpoint_files()) == {"best_policy_seed_0.npz"}


def test_a_resume_keeps_the_legacy_truncation_columns(tmp_path):
    learner = fake_learner([0])
    loop = loop_module.Loop(learner, tmp_path, progress=False)
    shuffled = list(reversed(LEGACY_TRUNCATION_COLUMNS))  # a header's order does not matter
    (tmp_path / layout.TRUNCATIONS_CSV).write_text(",".join(shuffled) + "\n1,2,3,4,5,6\n")
    assert loop.extra_columns(resuming=True) == {layout.TRUNCATIONS_CSV: LEGACY_TRUNCATION_COLUMNS}
    assert loop.extra_columns(resuming=False) == {layout.TRUNCATIONS_CSV: TRUNCATION_COLUMNS}
    (tmp_path / layout.TRUNCATIONS_CSV).write_text(",".join(TRUNCATION_COLUMNS) + "\n")
    assert loop.extra_columns(resuming=True) == {layout.TRUNCATIONS_CSV: TRUNCATION_COLUMNS}
