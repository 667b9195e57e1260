"""Deterministic evaluation episodes of a policy under chosen dynamics (no JAX needed)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def run_episodes(
    policy: Callable[[np.ndarray], np.ndarray],
    task: str,
    dynamics: str,
    n_episodes: int,
    seed: int,
    *,
    max_steps: int | None = None,
    **overrides,
) -> list[dict]:
    """Run `n_episodes` deterministic episodes of `policy` on `task` under `dynamics`.

    `dynamics` is any spec `adarl.envs.parse_dynamics` accepts (`nominal`, `default`,
    `fixed:torso_length=0.5,…`); `overrides` are fixed parameter values on top. The env is seeded
    with `seed`, so the same policy, dynamics and seed give the same returns. Returns one dict per
    episode: `episode, return, length`, `distance` (forward displacement of the root body, x of
    `qpos`: a policy that only balances earns Hopper's healthy reward with a distance near 0) and
    `params`, the episode's physical parameters (name -> value; the evaluation tables' columns
    `adarl.runs.layout.param_column`).
    `max_steps` (optional) cuts every episode after that many steps (for quick checks).
    """
    from adarl.envs import make

    env = make(task, dynamics=dynamics, seed=seed, **overrides)
    rows = []
    try:
        for k in range(n_episodes):
            obs, info = env.reset(seed=seed + k)
            start_x = _root_x(env)
            total, length, done = 0.0, 0, False
            while not done:
                obs, reward, terminated, truncated, info = env.step(policy(obs))
                total += float(reward)
                length += 1
                done = terminated or truncated or (max_steps is not None and length >= max_steps)
            distance = _root_x(env) - start_x
            params = {name: float(v) for name, v in info["dynamics"].items()}
            rows.append(
                {
                    "episode": k,
                    "return": total,
                    "length": length,
                    "distance": distance,
                    "params": params,
                }
            )
    finally:
        env.close()
    return rows


def _root_x(env) -> float:
    """x of the root body (first `qpos` entry) of a MuJoCo env; NaN for other envs."""
    data = getattr(env.unwrapped, "data", None)
    return float(data.qpos[0]) if data is not None else float("nan")
