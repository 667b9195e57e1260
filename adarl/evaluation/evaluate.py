"""Evaluating the saved policies of runs under chosen dynamics or over a dynamics grid.

`plan` turns runs and an `EvalSpec` into work units (one seed's policy at one grid point),
checking everything first; `adarl.evaluation.parallel` runs them (over a pool of spawned processes
or Ray; policies are NumPy files, so workers need no JAX); `evaluate_runs` does both and returns
one table per run;
`write_evaluation` stores a table as `RUN_DIR/evaluations/<name>.csv` with a JSON sidecar that
records how it was made (the report reads both).

Every episode is deterministic: the policy is deterministic and the environment of every seed's
policy is seeded with the same `eval_seed` (episode k resets with `eval_seed + k`), so all policies
face the same initial states and the same seed gives the same returns.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import pandas as pd

from adarl.envs.tasks import env_options, kwargs_text
from adarl.errors import UsageError
from adarl.evaluation import grid
from adarl.evaluation.parallel import run_units
from adarl.files import atomic_write_json, atomic_write_text
from adarl.results.runs import Run
from adarl.runs import layout
from adarl.runs.checkpoints import policy_files, select_checkpoint
from adarl.runs.layout import EVALUATIONS_DIR, checkpoint_step

EVAL_SEED = 100_000  # far from the seeds training uses for its own environments
COLUMNS = ["step", "seed", "dynamics", "episode", "return", "length", "distance"]


@dataclass(frozen=True)
class EvalSpec:
    """What to evaluate: a base dynamics spec, optional swept axes and held values, how many
    episodes per seed and grid point, which checkpoint (None: the final one)."""

    dynamics: str = "nominal"
    axes: tuple[grid.Axis, ...] = ()
    holds: tuple[tuple[str, float], ...] = ()
    episodes: int = 10
    checkpoint: int | None = None
    eval_seed: int = EVAL_SEED
    max_steps: int | None = None

    @classmethod
    def from_options(
        cls,
        dynamics: str = "nominal",
        sweeps: Sequence[str] = (),
        holds: Sequence[str] = (),
        **kwargs,
    ) -> EvalSpec:
        """Build from CLI strings: `--dynamics`, repeated `--sweep P=LO..HI[:N]`, `--hold P=v`."""
        spec = cls(**kwargs)
        if spec.episodes < 1:
            raise UsageError(f"--episodes must be ≥ 1, got {spec.episodes}")
        if spec.max_steps is not None and spec.max_steps < 1:
            raise UsageError(f"--max-episode-steps must be ≥ 1, got {spec.max_steps}")
        base, axes, held = grid.split_dynamics(dynamics, spec.episodes)
        axes += [grid.parse_axis(s, spec.episodes) for s in sweeps]
        held += [grid.parse_hold(h) for h in holds]
        return replace(spec, dynamics=base, axes=tuple(axes), holds=tuple(held))

    @property
    def name(self) -> str:
        return grid.evaluation_name(self.dynamics, self.axes, self.holds, self.checkpoint)


@dataclass(frozen=True)
class Unit:
    """One seed's policy at one grid point: the smallest piece of work a worker runs."""

    run_index: int
    policy_path: str
    task: str
    seed: int
    step: int
    dynamics: str
    point: tuple[tuple[str, float], ...]
    episodes: int
    eval_seed: int
    max_steps: int | None = None
    label: str = field(default="")
    # `make`'s keywords from the run: physics, model version, env-kwargs, env-module
    env: tuple[tuple[str, str], ...] = ()


# ----------------------------------------------------------------------------- planning
def run_task(run: Run):
    """The `TaskSpec` a run trained on, made as its config says (`env_kwargs`, `env_module`,
    `model_version`: `adarl.envs.tasks.task_of`); an env-module the user did not name is a
    one-line `UsageError` naming the run (`adarl.envs.tasks.check_named`)."""
    from adarl.envs.tasks import check_model, task_of
    from adarl.runs.provenance import read_environment

    check_run_module(run)
    spec = task_of(run.config)
    try:
        record = read_environment(run.path) or {}
    except UsageError:
        record = {}
    check_model(spec, record.get("model"), f"run {run.path}", "evaluating")
    return spec


def check_run_module(run: Run) -> None:
    """A one-line `UsageError` if `run` needs an env-module the user did not name."""
    from adarl.envs.tasks import check_named

    check_named(str(run.config.get("env_module") or ""), str(run.path / layout.CONFIG_FILE))


def run_env_options(run: Run) -> dict[str, str]:
    """`make`'s keywords for a run's evaluation envs: its physics and model version, and for a
    Gymnasium id its `env_kwargs` and `env_module` where it has them (a user's XML, the package
    that registers a user's id, which the user must have named: `check_run_module`)."""
    check_run_module(run)
    options = env_options(run.config)
    for key in ("env_kwargs", "env_module"):
        value = run.config.get(key) or ""
        if value:
            options[key] = value if isinstance(value, str) else kwargs_text(value)
    return options


def task_parameters(task) -> list[str]:
    """Names of the physical parameters of `task` (a `TaskSpec` or a name for
    `adarl.envs.get_task`); none for a task with fixed dynamics."""
    from adarl.envs import get_task

    return list(get_task(task).all_params)


def check_dynamics(spec: str, task) -> None:
    """Let `adarl.envs.parse_dynamics` reject a bad spec before any work starts (`task`: a
    `TaskSpec` or a name); a task with fixed dynamics takes `nominal`, `paper` or `default`."""
    from adarl.envs import get_task, parse_dynamics

    task = get_task(task)
    if task.kind == "gym":
        if spec not in ("nominal", "paper", "default"):
            raise UsageError(
                f"task {task.name!r} has fixed dynamics; allowed: nominal (got {spec!r})"
            )
        return
    parse_dynamics(spec, task)


def _addressed_check(task, physics: str):
    """The check `grid.build_grid` runs on an addressed name for `task` (None where the task
    has no addressable elements): `ompo` physics, which edits the compiled model, takes none.
    Whether the element exists is `check_dynamics`'s to say (one line naming the model's)."""
    if task.kind == "gym":
        return None

    def check(name: str) -> None:
        if physics == "ompo":
            raise UsageError(
                f"addressed parameter {name!r} needs physics 'consistent'; allowed for a run "
                f"trained under ompo: {', '.join(task.all_params)}"
            )

    return check


def plan(runs: Sequence[Run], spec: EvalSpec) -> list[Unit]:
    """All units for `runs` under `spec`, validated (checkpoints, seeds, parameters, grid); the
    episodes are counted (`grid.check_episodes`) before any grid is built. Every run's envs are
    made as it trained them (its task spec, physics, model version, env-kwargs, env-module)."""
    points = math.prod(len(a.values) for a in spec.axes)
    seeds = sum(len(run.seeds) for run in runs)
    grid.check_episodes(
        points * seeds * spec.episodes,
        f"{points:,} points x {seeds} seeds x {spec.episodes} episodes",
    )
    units: list[Unit] = []
    grids: dict[tuple, list[dict[str, float]]] = {}
    for index, run in enumerate(runs):
        checkpoint = select_checkpoint(run.path, spec.checkpoint)
        files = policy_files(checkpoint)
        options = run_env_options(run)
        key = (run.task, *sorted(options.items()))
        if key not in grids:
            task = run_task(run)
            check_dynamics(spec.dynamics, task)
            points = grid.build_grid(
                spec.axes,
                spec.holds,
                task_parameters(task),
                task.name,
                _addressed_check(task, options["physics"]),
            )
            for point in points:  # values out of range fail here, before any episode
                check_dynamics(grid.point_label(spec.dynamics, point), task)
            grids[key] = points
        for point in grids[key]:
            for seed, path in files.items():
                units.append(
                    Unit(
                        run_index=index,
                        policy_path=str(path),
                        task=run.task,
                        seed=seed,
                        step=checkpoint_step(checkpoint),
                        dynamics=spec.dynamics,
                        point=tuple(point.items()),
                        episodes=spec.episodes,
                        eval_seed=spec.eval_seed,
                        max_steps=spec.max_steps,
                        label=grid.point_label(spec.dynamics, point),
                        env=tuple(options.items()),
                    )
                )
    return units


# ----------------------------------------------------------------------------- running
def evaluate_runs(
    runs: Sequence[Run],
    spec: EvalSpec,
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    progress: bool = False,
) -> list[pd.DataFrame]:
    """Evaluate every seed of every run; one table per run (columns `COLUMNS` then `p_*`).
    `workers`, `backend`, `address`: as `parallel.run_units`."""
    return tables(runs, plan(runs, spec), workers, backend, address, progress, "evaluate")


def tables(
    runs: Sequence[Run],
    units: Sequence[Unit],
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    progress: bool = False,
    desc: str = "evaluate",
) -> list[pd.DataFrame]:
    """Run the `units` planned for `runs` (`parallel.run_units`); one episode table per run."""
    results = run_units(units, workers, backend, address, progress, desc)
    per_run: list[list[dict]] = [[] for _ in runs]
    for unit, rows in zip(units, results):
        per_run[unit.run_index].extend(rows)
    return [_table(rows) for rows in per_run]


def _table(rows: list[dict]) -> pd.DataFrame:
    df = pd.DataFrame(rows)
    if df.empty:
        return pd.DataFrame(columns=COLUMNS)
    params = sorted(layout.param_columns(df.columns))
    return df[COLUMNS + params]


# ----------------------------------------------------------------------------- output
def default_output(run: Run, spec: EvalSpec) -> Path:
    return run.path / EVALUATIONS_DIR / f"{spec.name}.csv"


def check_not_smaller(path: Path, episodes: int) -> None:
    """Refuse (one-line `UsageError`) to replace the evaluation stored at `path` (one row per
    episode) with one of fewer `episodes` in all: a quick look (fewer episodes, a coarser
    suite grid) must not overwrite an hour's evaluation. One as large or larger replaces it (a
    rerun, or the full grid after a coarse look)."""
    try:
        with open(path, "rb") as f:
            stored = sum(1 for _ in f) - 1  # the header
    except OSError:
        return  # nothing stored
    if episodes < stored:
        raise UsageError(
            f"{path} holds {stored:,} episodes, more than the {episodes:,} of this evaluation "
            "that would replace it; move it and its .json away first"
        )


def write_evaluation(
    table: pd.DataFrame,
    path: Path,
    spec: EvalSpec,
    run: Run,
    command: str | None = None,
    extra: dict | None = None,
) -> Path:
    """Write the CSV and its JSON sidecar (same stem), each atomically, the sidecar last;
    `extra` adds (or replaces) sidecar entries."""
    path = Path(path)
    atomic_write_text(path, table.to_csv(index=False, float_format="%.6g"))
    meta = {
        "name": spec.name,
        "run": str(run.path),
        "task": run.task,
        **{k: run.config[k] for k in ("env_kwargs", "env_module") if run.config.get(k)},
        "dynamics": spec.dynamics,
        "sweep": {a.name: list(a.values) for a in spec.axes},
        "hold": dict(spec.holds),
        "episodes": spec.episodes,
        "checkpoint_step": int(table["step"].iloc[0]) if len(table) else None,
        "final_checkpoint": spec.checkpoint is None,
        "eval_seed": spec.eval_seed,
        "max_episode_steps": spec.max_steps,
        "seeds": sorted(int(s) for s in table["seed"].unique()),
        "command": command,
    } | dict(extra or {})
    atomic_write_json(layout.evaluation_sidecar(path), meta)  # last
    return path


def summarise(table: pd.DataFrame) -> pd.DataFrame:
    """Per grid point: the mean and standard deviation over seeds of each seed's mean return."""
    per_seed = table.groupby(["dynamics", "seed"], sort=False)["return"].mean().reset_index()
    out = per_seed.groupby("dynamics", sort=False)["return"].agg(["mean", "std", "count"])
    return out.rename(columns={"count": "seeds"}).reset_index()
