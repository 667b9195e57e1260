"""The task contract: what the training loop, the learners, evaluation and the Gymnasium wrapper
need of a task, whatever its kind. Every task `adarl.envs.make` returns implements it: the
paper's four and any other MuJoCo env (`DynamicsEnv`), and any other Gymnasium env (`PlainEnv`);
tests/envs/test_task_contract.py checks each kind against it.

    reset(seed=, options=) -> (obs, info)   info["dynamics"]: the episode's parameters (a dict,
                                            {} for fixed dynamics), info["episode_index"]: i
    step(action) -> (obs, reward, terminated, truncated, info)   the same two info keys; the
                                            time limit `max_episode_steps` truncates
    episode_index                           the current episode's index i (the schedule's input)
    dynamics_params                         the current episode's parameters (None before reset)
    get_state() -> dict / set_state(dict)   everything a step depends on: a task restored from
                                            `get_state()` continues bit for bit (a `PlainEnv` whose
                                            state cannot be captured refuses `set_state` in one
                                            line: never a silently inexact resume)
    close()

Adding a task of your own: docs/envs.md, "Your own task" (any registered Gymnasium id) and
"Adding a task" (a named task with its own schedule).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class Task(Protocol):
    """An adarl task (see the module docstring)."""

    observation_space: Any
    action_space: Any
    max_episode_steps: int

    @property
    def episode_index(self) -> int: ...

    @property
    def dynamics_params(self) -> dict[str, float] | None: ...

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple: ...

    def step(self, action) -> tuple: ...

    def get_state(self) -> dict: ...

    def set_state(self, state: dict) -> None: ...

    def close(self) -> None: ...
