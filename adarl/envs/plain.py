"""Any registered Gymnasium env as a fixed-dynamics task, named `gym:<id>` (e.g. `gym:Pendulum-v1`).

Used for quick learning checks (the trainer's Pendulum test) with the same interface as the
MuJoCo tasks: `episode_index`, empty `dynamics_params`, `info["dynamics"]`/`info["episode_index"]`
and `get_state`/`set_state` (for envs whose state is the `state` attribute, like classic control).
"""

from __future__ import annotations

import copy

import gymnasium
import numpy as np

from adarl.errors import UsageError

PREFIX = "gym:"


class PlainEnv(gymnasium.Wrapper):
    """A Gymnasium env with a time limit and the adarl task interface, dynamics never change."""

    def __init__(self, env: gymnasium.Env, seed: int | None, max_episode_steps: int):
        super().__init__(env)
        self.max_episode_steps = max_episode_steps
        self._pending_seed = seed
        self.episode_index = 0
        self._started = False
        self._elapsed = 0
        self.dynamics_params: dict[str, float] = {}

    def reset(self, *, seed=None, options=None):
        if self._started:
            self.episode_index += 1
        self._started = True
        if seed is None:
            seed, self._pending_seed = self._pending_seed, None
        obs, info = self.env.reset(seed=seed, options=options)
        self._elapsed = 0
        return obs, dict(info, dynamics=self.dynamics_params, episode_index=self.episode_index)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._elapsed += 1
        truncated = truncated or self._elapsed >= self.max_episode_steps
        info = dict(info, dynamics=self.dynamics_params, episode_index=self.episode_index)
        return obs, reward, terminated, truncated, info

    def get_state(self) -> dict:
        raw = self.env.unwrapped
        return {
            "episode_index": self.episode_index,
            "started": self._started,
            "elapsed": self._elapsed,
            "pending_seed": self._pending_seed,
            "np_random": copy.deepcopy(raw.np_random.bit_generator.state),
            "state": np.array(raw.state, dtype=np.float64),
        }

    def set_state(self, state: dict) -> None:
        raw = self.env.unwrapped
        self.episode_index = int(state["episode_index"])
        self._started = bool(state["started"])
        self._elapsed = int(state["elapsed"])
        self._pending_seed = state["pending_seed"]
        raw.np_random.bit_generator.state = state["np_random"]
        raw.state = np.asarray(state["state"], dtype=np.float64)


def make_plain(
    task: str, dynamics="default", seed: int | None = 0, max_episode_steps: int = 1000, **overrides
) -> PlainEnv:
    """`gym:<id>` as a task; its dynamics are Gymnasium's own and cannot be changed."""
    if dynamics not in ("paper", "nominal", "default"):
        raise UsageError(f"task {task!r} has fixed dynamics; got dynamics {dynamics!r}")
    if overrides:
        raise UsageError(f"task {task!r} has no physical parameters; got {', '.join(overrides)}")
    env_id = task[len(PREFIX) :]
    try:
        raw = gymnasium.make(env_id, disable_env_checker=True).unwrapped
    except gymnasium.error.Error as exc:
        raise UsageError(f"unknown Gymnasium env {env_id!r} in task {task!r}") from exc
    return PlainEnv(raw, seed, max_episode_steps)
