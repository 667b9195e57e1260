"""Issue 55 §4, the device backend: its accelerator memory check counts every seed's replay
buffer (an n-seed run that fits one seed's buffers but not n seeds' is refused before anything
is written, with n × one seed's figure), and a state exactly on a healthy-range bound terminates
as Gymnasium's host task does (open ranges: the bound itself is unhealthy)."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

from adarl.cli.main import main
from adarl.train import guards

pytest.importorskip("mujoco.mjx", reason="the device backend needs mujoco-mjx")


def _train(tmp_path, seeds: str) -> list[str]:
    return ["train", "--backend", "device", "--algo", "sac", "--preset", "smoke", "--seeds", seeds,
            "--buffer-size", "20000000", "--total-steps", "200", "--out", str(tmp_path / "run"),
            "--no-progress"]  # fmt: skip


def test_the_device_memory_check_counts_n_seeds_buffers(tmp_path, capsys, monkeypatch):
    seen = []
    check = guards.check_device_memory

    def spy(n_seeds, buffers, networks, lower):
        seen.append((n_seeds, buffers, networks))
        check(n_seeds, buffers, networks, lower)  # refuses (UsageError) what does not fit
        # let through: stop here, before 20M-row buffers are allocated
        raise AssertionError(f"{n_seeds} seeds' {buffers + networks} bytes passed the check")

    monkeypatch.setattr("adarl.train.sac_family.check_device_memory", spy)
    monkeypatch.setattr(guards, "machine_memory", lambda: 2**60)  # the host has room
    monkeypatch.setattr(guards, "accelerator_memory", lambda: 1)  # nothing fits: the figure only
    assert main(_train(tmp_path, "0")) == 2
    n1, one_buffers, one_networks = seen[-1]
    assert n1 == 1 and one_buffers > 20_000_000 * 4 * (11 + 3)
    capsys.readouterr()
    monkeypatch.setattr(
        guards, "accelerator_memory", lambda: int(1.5 * (one_buffers + one_networks))
    )
    assert main(_train(tmp_path, "0-3")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "4 seeds" in err and "the accelerator has" in err, err
    n4, four_buffers, _ = seen[-1]
    assert n4 == 4 and four_buffers == 4 * one_buffers
    shown = float(re.search(r"buffers ([\d.,]+) GiB", err).group(1).replace(",", ""))
    assert abs(shown - four_buffers / 2**30) <= 0.05 + 1e-9
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    "task, index", [("hopper", 1), ("hopper", 2), ("walker2d", 1), ("walker2d", 2)]
)
def test_a_state_on_a_healthy_bound_terminates_as_on_the_host(task, index):
    """qpos[1] (z) or qpos[2] (the angle) exactly on a bound of Gymnasium's healthy range: the
    host env says unhealthy (open range) and so does the device task's rule; just inside, both
    say healthy."""
    import gymnasium
    import jax.numpy as jnp

    from adarl.device.tasks import RULES

    env = gymnasium.make(f"{task.capitalize()}-v5").unwrapped
    env.reset(seed=0)
    rules = RULES[task]
    key = "_healthy_z_range" if index == 1 else "_healthy_angle_range"
    bounds = getattr(env, key)
    for bound, step in ((bounds[0], +1e-3), (bounds[1], -1e-3)):
        if not np.isfinite(bound):  # Hopper's z has no upper bound
            continue
        for value, want in ((bound, False), (bound + step, True)):
            qpos, qvel = env.init_qpos.copy(), np.zeros(env.model.nv)
            qpos[1] = 1.25 if index != 1 else qpos[1]
            qpos[index] = value
            env.set_state(qpos, qvel)
            assert bool(env.is_healthy) is want, (task, key, value)
            data = SimpleNamespace(qpos=jnp.asarray(qpos), qvel=jnp.asarray(qvel))
            _, healthy = rules.reward(data, jnp.zeros(env.action_space.shape), 0.0)
            assert bool(healthy) is want, (task, key, value)
    env.close()
