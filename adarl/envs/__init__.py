"""MuJoCo tasks with uncertain, episode-varying dynamics (Hopper, Walker2d, Ant, Humanoid).

    env = make("hopper", dynamics="paper", seed=0)
    obs, info = env.reset()          # info["dynamics"], info["episode_index"]
    make("hopper", "ompo", physics="ompo", model_version="v4")  # as the paper's OMPO code ran it

Task facts and schedules import without MuJoCo; `make`/`make_vec` load it on first use.
"""

import importlib

from adarl.envs.dynamics import DynamicsSchedule, parse_dynamics
from adarl.envs.params import PARAMS, Sinusoid
from adarl.envs.tasks import PHYSICS, VERSIONS, TaskSpec, env_options, get_task, list_tasks

__all__ = [
    "PARAMS",
    "PHYSICS",
    "VERSIONS",
    "DynamicsEnv",
    "DynamicsSchedule",
    "Sinusoid",
    "TaskSpec",
    "check_dynamics",
    "env_options",
    "get_task",
    "list_tasks",
    "make",
    "make_vec",
    "parse_dynamics",
]

_LAZY = {"make", "make_vec", "DynamicsEnv", "check_dynamics"}


def __getattr__(name):
    if name in _LAZY:
        try:
            module = importlib.import_module("adarl.envs.env")
        except AttributeError as exc:
            # `from adarl.envs import make` would report it as a missing name, hiding the cause
            raise ImportError(f"importing adarl.envs.env failed: {exc!r}") from exc
        return getattr(module, name)
    raise AttributeError(f"module 'adarl.envs' has no attribute {name!r}")
