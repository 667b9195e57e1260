"""`run_episodes`: the forward distance it records is Gymnasium's own x velocity integrated."""

import numpy as np
import pytest

from adarl.envs import make
from adarl.envs.rollout import run_episodes


@pytest.mark.parametrize("task", ["hopper", "ant"])
def test_distance_is_the_integrated_x_velocity(task):
    rng = np.random.default_rng(0)
    weights = rng.normal(size=(make(task, "nominal").action_space.shape[0],))

    def policy(obs):  # deterministic, moves the body
        return np.tanh(weights * obs[: len(weights)].sum())

    rows = run_episodes(policy, task, "nominal", 2, seed=5, max_steps=60)
    env = make(task, "nominal", seed=5)
    for k, row in enumerate(rows):
        obs, _ = env.reset(seed=5 + k)
        moved = 0.0
        for _ in range(row["length"]):
            obs, _, _, _, info = env.step(policy(obs))
            moved += info["x_velocity"] * env.unwrapped.dt
        assert row["distance"] == pytest.approx(moved, abs=1e-9)
        assert abs(row["distance"]) > 1e-4  # it did move: the check is not 0 == 0
