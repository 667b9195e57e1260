"""Any registered Gymnasium env not built on `MujocoEnv` as a fixed-dynamics task, named by its id
(`Pendulum-v1`, or `gym:Pendulum-v1` as older runs recorded it).

The same interface as the MuJoCo tasks: `episode_index`, empty `dynamics_params`,
`info["dynamics"]`/`info["episode_index"]` and `get_state`/`set_state`. An env's state is
captured when it is its `state` attribute (classic control) and the env's RNG; for any other env
a checkpoint records that it cannot be, and resuming from it is refused in one line (never a
silently inexact resume).
"""

from __future__ import annotations

import copy

import gymnasium
import numpy as np

from adarl.errors import UsageError

PREFIX = "gym:"  # how older runs named these tasks


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
        state = {
            "episode_index": self.episode_index,
            "started": self._started,
            "elapsed": self._elapsed,
            "pending_seed": self._pending_seed,
            "np_random": copy.deepcopy(raw.np_random.bit_generator.state),
        }
        captured = getattr(raw, "state", None)
        if (
            isinstance(captured, np.ndarray | list | tuple)
            and np.asarray(captured).dtype.kind in "fiu"
        ):
            state["state"] = np.array(captured, dtype=np.float64)
        else:  # resuming from this checkpoint is refused (set_state)
            state["uncapturable"] = f"{type(raw).__name__} keeps its state outside a `state` array"
        return state

    def set_state(self, state: dict) -> None:
        if "state" not in state:
            raise UsageError(
                f"cannot resume this run exactly: its env's state was not captured "
                f"({state.get('uncapturable', 'no state in the checkpoint')}); allowed: start a "
                "new run (adarl resumes exactly the MuJoCo tasks and envs with a `state` array)"
            )
        raw = self.env.unwrapped
        self.episode_index = int(state["episode_index"])
        self._started = bool(state["started"])
        self._elapsed = int(state["elapsed"])
        self._pending_seed = state["pending_seed"]
        raw.np_random.bit_generator.state = state["np_random"]
        raw.state = np.asarray(state["state"], dtype=np.float64)


def check_plain(spec, dynamics, overrides) -> None:
    """A one-line `UsageError` unless `dynamics` keeps `spec`'s own physics and nothing is set."""
    if dynamics not in ("paper", "nominal", "default"):
        raise UsageError(f"task {spec.name!r} has fixed dynamics; got dynamics {dynamics!r}")
    if overrides:
        raise UsageError(
            f"task {spec.name!r} has no physical parameters; got {', '.join(overrides)}"
        )


def make_plain(
    task, dynamics="default", seed: int | None = 0, max_episode_steps: int = 1000, **overrides
) -> PlainEnv:
    """A Gymnasium env that is not a MuJoCo task (`task`: its id or `TaskSpec`) as a task; its
    dynamics are Gymnasium's own and cannot be changed."""
    from adarl.envs.tasks import get_task, make_raw_env

    spec = get_task(task)
    check_plain(spec, dynamics, overrides)
    return PlainEnv(make_raw_env(spec), seed, max_episode_steps)
