"""Gymnasium ids for the four tasks, and `TaskEnv`, the env behind them (RRLS-style parameters).

    import adarl  # registers adarl/Hopper-v0, adarl/Walker2d-v0, adarl/Ant-v0, adarl/Humanoid-v0
    env = gymnasium.make("adarl/Hopper-v0", dynamics="paper", physics="consistent", model_version="v5")
    obs, info = env.reset(options={"torso_length": 0.5, "foot_length": 0.3})
    env.unwrapped.get_params()  # {"torso_length": 0.5, "foot_length": 0.3, ...}

Gymnasium 1.x loads no plugin entry points, so the ids are registered by `import adarl` (or by
`gymnasium.make("adarl:adarl/Hopper-v0")`, which imports adarl first).
"""

from __future__ import annotations

import sys
from collections.abc import Mapping

import gymnasium

from adarl.envs.tasks import TASKS
from adarl.errors import UsageError

NAMESPACE = "adarl"
#: Gymnasium id -> task name.
IDS = {f"{NAMESPACE}/{t.gym_id.split('-')[0]}-v0": t.name for t in TASKS.values()}
#: Gymnasium's TimeLimit ends episodes (as for Hopper-v5); the inner env counts no limit.
MAX_EPISODE_STEPS = 1000


def register_envs() -> None:
    """Register the ids in `IDS` with Gymnasium (again: no-op)."""
    for env_id, task in IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                env_id,
                entry_point=_entry_point(env_id, task),
                kwargs={"task": task},
                max_episode_steps=MAX_EPISODE_STEPS,
            )


class TaskEnv(gymnasium.Env):
    """An adarl task as a plain `gymnasium.Env`, with RRLS's parameter API.

    Takes `adarl.envs.make`'s options, except that `seed` defaults to None (fresh entropy, as
    Gymnasium envs do) and the time limit is Gymnasium's (`gymnasium.make(..., max_episode_steps=)`).
    `set_params(**values)` / `reset(options=values)` hold values on top of the schedule for this
    and later episodes until changed or `clear_params()`; `get_params()` returns the parameters
    in force; `info["dynamics"]` carries them (a copy) at every reset and step.
    """

    metadata = {"render_modes": ["human", "rgb_array", "depth_array", "rgbd_tuple"]}

    def __init__(
        self,
        task: str = "hopper",
        dynamics="paper",
        seed: int | None = None,
        *,
        render_mode: str | None = None,
        physics: str = "consistent",
        model_version: str = "v5",
        **overrides: float,
    ):
        from adarl.envs.env import make

        self.env = make(
            task,
            dynamics,
            seed,
            max_episode_steps=sys.maxsize,
            render_mode=render_mode,
            physics=physics,
            model_version=model_version,
            **overrides,
        )
        self.task = self.env.task
        self.observation_space = self.env.observation_space
        self.action_space = self.env.action_space
        self.metadata = self.env.unwrapped.metadata
        self.render_mode = render_mode
        self._schedule = self.env.schedule  # the schedule before held values
        self._held: dict[str, float] = {}

    # ---- parameter API (RRLS) -------------------------------------------------------------
    def get_params(self) -> dict[str, float]:
        """The parameters in force (before the first reset: those it will use)."""
        params = self.env.dynamics_params
        if params is None:
            params = self.env._episode_params(self.env.episode_index)
        return dict(params)

    def set_params(self, params: Mapping[str, float] | None = None, **values: float) -> None:
        """Hold `values` (a dict or keywords) from now on, on top of the schedule; a running
        episode switches model at once, as in RRLS. Bad names or values: one-line UsageError."""
        if params is not None and not isinstance(params, Mapping):
            raise UsageError(f"bad parameters {params!r}; allowed: a dict of NAME: VALUE")
        values = {**(params or {}), **values}
        self._hold(values)
        current = self.env.dynamics_params
        if current is not None and values:
            self.env._install({**current, **self._held})

    def clear_params(self) -> None:
        """Drop held values: later episodes follow the schedule again."""
        self._held = {}
        self.env.schedule = self._schedule

    def _hold(self, values: Mapping[str, float]) -> None:
        if not isinstance(values, Mapping):
            raise UsageError(f"bad parameters {values!r}; allowed: a dict of NAME: VALUE")
        schedule = self._schedule.with_overrides(**{**self._held, **values})  # checks them
        self._held = {name: schedule.constants[name] for name in {**self._held, **values}}
        self.env.schedule = schedule

    # ---- gymnasium API ----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start the next episode; `options` are parameters to hold (RRLS: `set_params`)."""
        super().reset(seed=seed)
        if options is not None:
            self._hold(options)
        obs, info = self.env.reset(seed=seed)
        info["dynamics"] = dict(info["dynamics"])  # a new dict per call, as Gymnasium asks
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        info["dynamics"] = dict(info["dynamics"])
        return obs, reward, terminated, truncated, info

    def render(self):
        return self.env.render()

    def close(self):
        self.env.close()


class _IdEntryPoint:
    """The entry point of one id: `TaskEnv` of the id's task. Gymnasium passes the registered
    `task=` with the caller's keywords on top, so a `task=` naming another task (an undocumented
    keyword: the id names the task) is refused in one line, not built under the wrong id."""

    metadata = TaskEnv.metadata

    def __init__(self, env_id: str, task: str):
        self.env_id, self.task = env_id, task

    def __call__(self, task: str | None = None, **kwargs) -> TaskEnv:
        if task is not None and task != self.task:
            other = next((i for i, t in IDS.items() if t == task), None)
            instead = f'gymnasium.make("{other}", ...)' if other else f"one of {', '.join(IDS)}"
            raise UsageError(
                f"gymnasium.make({self.env_id!r}) takes no task={task!r}: the id names the task "
                f"({self.task}); for {task} use {instead}"
            )
        return TaskEnv(task=self.task, **kwargs)


def _entry_point(env_id: str, task: str) -> str:
    """A "module:attribute" entry point of `env_id` (Gymnasium resolves it on `make`)."""
    name = f"make_{task}"
    globals()[name] = _IdEntryPoint(env_id, task)
    return f"{__name__}:{name}"


register_envs()  # at import: `import adarl` imports this module when Gymnasium loads
