"""Issue 55 §4: the envelope's rate after the run's T stays at base·min_ratio, and
`total_updates` agrees with the gradient steps a run makes, also when `update_after` equals
`total_steps` (the loop's rule: a chunk ending at or after `update_after` updates)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from adarl.algos import sac_config, schedule
from adarl.algos.sac_config import SAC_FAMILY
from adarl.runs import checkpoints
from adarl.train import trainers


@pytest.mark.parametrize("t", [3000, 3001, 4500, 10**6])
def test_the_envelope_after_t_stays_at_base_times_min_ratio(t):
    rate = schedule.envelope_learning_rate(t, 0, 3e-3, 100, 3000, 0.1, False)
    assert float(rate) == pytest.approx(3e-3 * 0.1, rel=1e-6)
    restart = schedule.restart_learning_rate(t, 3e-3, 100, 3000, 0.1)
    assert float(restart) == pytest.approx(3e-3 * 0.1, rel=1e-6)


def loop_updates(c) -> int:
    """The updates the loop makes, stepped as `Learner.advance` steps: chunk by chunk to the end
    (`chunk_end`), `update_every` for a chunk for which `chunk_updates` holds."""
    step, updates = 0, 0
    while step < c.total_steps:
        end = schedule.chunk_end(c, step)
        updates += c.update_every * schedule.chunk_updates(c, end)
        step = end
    return updates


BASE = sac_config.SACConfig(
    **{**SAC_FAMILY["sac"], **sac_config.PRESETS["smoke"], "algo": "sac", "task": "hopper"}
)


@pytest.mark.parametrize(
    "total, after, every",
    [
        (2000, 500, 50),
        (1000, 1000, 50),
        (1000, 1001, 50),
        (1030, 1000, 50),
        (90, 90, 100),
        (7, 0, 3),
    ],
)
def test_total_updates_is_what_the_loop_makes(total, after, every):
    c = dataclasses.replace(BASE, total_steps=total, update_after=after, update_every=every)
    assert schedule.total_updates(c) == loop_updates(c)
    assert len(schedule.updating_chunks(c)) * every == loop_updates(c)


def test_update_after_equal_to_total_steps_in_a_run(tmp_path):
    """A run with update_after == total_steps makes `total_updates` gradient steps: one chunk,
    the last (its end reaches update_after), as its checkpoint's counter says."""
    c = dataclasses.replace(
        BASE, seeds=(0,), total_steps=100, update_after=100, start_steps=100, update_every=50
    )
    c = dataclasses.replace(c, log_every=100, eval_every=100, checkpoint_every=100)
    assert schedule.total_updates(c) == 50 == loop_updates(c)
    trainers.train(c, tmp_path / "run", progress=False)
    arrays, _ = checkpoints.load_checkpoint(checkpoints.checkpoint_dirs(tmp_path / "run")[-1])
    counts = [a for name, a in arrays.items() if name.endswith("['n_updates']")]
    assert counts and all(int(np.asarray(a).ravel()[0]) == 50 for a in counts), list(arrays)[:20]
