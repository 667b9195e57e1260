"""The fields every algorithm's config has, validated once: `RunConfig`, which `SACConfig`
(`adarl.algos.sac_config`) and `RNACConfig` (`adarl.algos.rnac_config`) extend with their
hyperparameters (redeclaring a field changes only its default). JAX-free, so the CLI's parser
and the report read configs without loading the maths.

The comment beside each field is its `adarl train --help` text (`registry.field_help`); the
field names are those of config.yaml (docs/run-format.md) and of the flags (`--total-steps`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from adarl.envs.tasks import PHYSICS, TASKS, VERSIONS
from adarl.errors import EVAL_DYNAMICS_EMPTY, ON_DIVERGENCE, UsageError, check_choice, check_numbers


@dataclass(frozen=True)
class RunConfig:
    """What every run has: the algorithm, the task and its environment, the seeds, the budget,
    and when it evaluates, logs and checkpoints."""

    # --- run
    algo: str = ""  # the algorithm (adarl train --algo)
    # hopper, walker2d, ant, humanoid, or any Gymnasium id, e.g. HalfCheetah-v5 (adarl tasks)
    task: str = "hopper"
    # Gymnasium keywords of the task's env, k=v,k=v or JSON, e.g. xml_file=my_robot.xml
    env_kwargs: str = ""
    env_module: str = ""  # a module to import first, which registers the task's Gymnasium id
    # physics schedule: paper, ompo, nominal, uniform, default, fixed:p=v,…; uniform:p=LOW..HIGH
    # varies p by episode (outside the paper's four tasks, only what the spec names; docs/envs.md)
    dynamics: str = "paper"
    physics: str = "consistent"  # consistent (recompile: masses follow geometry) or ompo
    model_version: str = "v5"  # Gymnasium's v5 or v4 (the port of the paper's Gym v3) models
    max_episode_steps: int = 1000  # time limit of an episode (truncation)
    seeds: tuple[int, ...] = (0,)  # seeds trained together in one process, e.g. 0-4
    total_steps: int = 1_000_000  # environment steps per seed
    # --- evaluation, logging, checkpoints (in environment steps per seed)
    eval_every: int = 10_000  # environment steps between evaluations
    eval_episodes: int = 5  # deterministic episodes per seed and evaluation dynamics
    eval_dynamics: tuple[str, ...] = ("nominal",)  # dynamics to evaluate under (comma-separated)
    log_every: int = 5_000  # environment steps between train.csv rows
    checkpoint_every: int = 50_000  # environment steps between checkpoints
    keep_checkpoints: int = 2  # newest checkpoints kept on disk (0: all)
    # a non-finite loss, parameter or return: stop (exit code 3) or continue (docs/reliability.md)
    on_divergence: str = "stop"

    def validate(self):
        """Raise a one-line UsageError on a bad shared field; return self. Each algorithm's
        `validate` calls this first, then checks its own fields."""
        check_numbers(self)
        check_choice("physics", self.physics, PHYSICS)
        check_choice("model version", self.model_version, VERSIONS)
        check_choice("on-divergence", self.on_divergence, ON_DIVERGENCE)
        for name in (
            "total_steps",
            "max_episode_steps",
            "eval_every",
            "eval_episodes",  # 0 would silently skip every evaluation
            "log_every",
            "checkpoint_every",
        ):
            if getattr(self, name) <= 0:
                raise UsageError(f"{name.replace('_', '-')} must be > 0, got {getattr(self, name)}")
        if self.keep_checkpoints < 0:
            raise UsageError(f"keep-checkpoints must be ≥ 0, got {self.keep_checkpoints}")
        if not self.seeds:
            raise UsageError("seeds is empty; give at least one seed, e.g. --seeds 0-4")
        if len(set(self.seeds)) != len(self.seeds):
            raise UsageError(f"seeds contain duplicates: {list(self.seeds)}")
        if min(self.seeds) < 0:
            raise UsageError(f"seeds must be ≥ 0, got {list(self.seeds)}")
        if not self.eval_dynamics:
            raise UsageError(EVAL_DYNAMICS_EMPTY)
        return self

    def env_options(self) -> dict:
        """`adarl.envs.make`'s keywords for this run's environments, spelt as the fields are."""
        options = {
            "physics": self.physics,
            "model_version": self.model_version,
            "max_episode_steps": self.max_episode_steps,
        }
        if self.env_kwargs or self.env_module:  # a paper task's make() takes neither
            options |= {"env_kwargs": self.env_kwargs, "env_module": self.env_module}
        return options


@dataclass(frozen=True)
class BudgetRule:
    """A config field that follows the step budget on a task outside the paper's four, where
    neither a flag nor the preset sets it (`registry.resolve_config`; issue 62)."""

    text: str  # the rule, as --help, the start line and the summary say it
    value: Callable[[int], int]  # total_steps -> the field's value


def follows_budget(task) -> bool:
    """Do the budget rules apply to `task`: is it outside the paper's four (hopper, walker2d,
    ant, humanoid, which keep the paper's settings)?"""
    return str(task).strip().lower() not in TASKS
