"""Named robustness test sets: the literature's uncertainty sets evaluated on their grids.

    adarl evaluate runs/ --suite m2td3-3d        # 10 x 10 x 10 grid, 30 episodes per point

A suite fixes, per task, the parameters to vary, their ranges, how the grid is spaced, the base
dynamics the other parameters keep and the episodes per point. Its result per seed is the
**worst-case return** (the lowest, over grid points, of the mean return over the point's
episodes) and the **average return** (the mean over grid points), the two numbers M2TD3 and RRLS
publish. Sources, per suite (docs/evaluation.md has the ranges next to their files):

* `m2td3-1d`, `m2td3-2d`, `m2td3-3d`: Tanabe et al. 2022, "Max-Min Off-Policy Actor-Critic Method
  Focusing on Worst-Case Robustness to Model Misspecification" (NeurIPS), code akimotolab/M2TD3:
  ranges from configs/environment/{Hopperv2-1_3, Hopperv2-2_3_3, Hopperv2-3_3_3_4, Walker2dv2-*,
  Antv2-*}.yaml, grid `np.linspace(min, max, 10)` per dimension and 30 episodes per point
  (evaluate.py, `--num_evaluate_point 10`, `--evaluate_num 30`), on Gymnasium's robot.
* `rrls-1d`, `rrls-2d`, `rrls-3d`: Zouitine et al. 2024, "RRLS: Robust Reinforcement Learning
  Suite", code SuReLI/RRLS (commit 0c43dc9): on Hopper, Walker2d and Ant the same ranges
  (rrls/envs/{hopper,walker,ant}.py `*ParamsBound`); on `HalfCheetah-v5`, `InvertedPendulum-v5`
  (1-D and 2-D only) and `HumanoidStandup-v5` RRLS's own sets (rrls/envs/{half_cheetah,pendulum,
  humanoid}.py), as addressed body masses and HalfCheetah's world friction as `friction_scale`.
  Grid: 10 points per dimension with both ends, as M2TD3's; RRLS's rrls/evaluate.py spaces them
  with `np.arange(min, max, (max - min) / 10)`, which leaves the upper bound out of the set it
  evaluates (a defect not copied; `grid_values(..., "arange")` gives its points). RRLS fixes no
  episode count; we keep M2TD3's 30.
* `paper`: the AdaRL paper's training ranges (c ∓ |a| of each schedule formula, adarl.envs.tasks):
  Hopper/Walker2d torso x foot length, Ant/Humanoid gravity x wind, 10 points per dimension
  (linspace), 10 episodes per point, other parameters at the nominal point.

Pure functions here (definitions, grids, summaries); `run_suite` and `write_suite` do the work
and the I/O.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from adarl.errors import UsageError
from adarl.evaluation import grid
from adarl.runs import layout
from adarl.runs.layout import EVALUATIONS_DIR, SUITES_DIR

SUMMARY_COLUMNS = ["suite", "step", "seed", "points", "episodes", "worst", "average", "worst_point"]
SPACINGS = ("linspace", "arange")


@dataclass(frozen=True)
class Range:
    """One varied parameter and the closed interval it is drawn from."""

    param: str
    low: float
    high: float


@dataclass(frozen=True)
class Suite:
    """One task's uncertainty set and how it is evaluated."""

    name: str
    task: str
    ranges: tuple[Range, ...]
    source: str
    points: int = 10  # per dimension
    spacing: str = "linspace"  # linspace: both ends; arange: upper end left out (RRLS's code)
    base: str = "fixed"  # dynamics of the parameters not varied: fixed = Gymnasium's robot
    episodes: int = 30

    def axes(self) -> tuple[grid.Axis, ...]:
        """The grid's axes, in the order of `ranges` (the last one varies fastest)."""
        return tuple(
            grid.Axis(r.param, grid_values(r.low, r.high, self.points, self.spacing), r.param)
            for r in self.ranges
        )

    @property
    def size(self) -> int:
        return self.points ** len(self.ranges)


def grid_values(low: float, high: float, points: int, spacing: str) -> tuple[float, ...]:
    """`points` values from `low` to `high`: `np.linspace` (both ends, M2TD3's evaluate.py) or
    `low + k (high - low) / points`, k < points (RRLS's `np.arange(low, high, step)` without its
    floating-point risk of an extra point)."""
    if spacing == "linspace":
        values = np.linspace(low, high, points)
    elif spacing == "arange":
        values = low + (high - low) * np.arange(points) / points
    else:
        raise UsageError(f"unknown grid spacing {spacing!r}; allowed: {', '.join(SPACINGS)}")
    return tuple(float(f"{v:.12g}") for v in values)


# ----------------------------------------------------------------------------- definitions
_M2TD3 = "Tanabe et al. 2022 (M2TD3), akimotolab/M2TD3 configs/environment/{file}.yaml"
_RRLS = "Zouitine et al. 2024 (RRLS), SuReLI/RRLS rrls/envs/{file}.py {bound}"
#: Sliding friction of every geom of Gymnasium's half_cheetah.xml (its default class; condim 3).
HALF_CHEETAH_FRICTION = 0.4

#: (M2TD3 config file, RRLS file, ranges) per task and dimension; RRLS's bounds equal M2TD3's.
_LITERATURE = {
    "hopper": [
        ("Hopperv2-1_3", "hopper", [Range("floor_friction", 0.1, 3.0)]),
        ("Hopperv2-2_3_3", "hopper", [Range("floor_friction", 0.1, 3.0), Range("torso_mass", 0.1, 3.0)]),
        (
            "Hopperv2-3_3_3_4",
            "hopper",
            [
                Range("floor_friction", 0.1, 3.0),
                Range("torso_mass", 0.1, 3.0),
                Range("thigh_mass", 0.1, 4.0),
            ],
        ),
    ],
    "walker2d": [
        ("Walker2dv2-1_4", "walker", [Range("floor_friction", 0.1, 4.0)]),
        ("Walker2dv2-2_4_5", "walker", [Range("floor_friction", 0.1, 4.0), Range("torso_mass", 0.1, 5.0)]),
        (
            "Walker2dv2-3_4_5_6",
            "walker",
            [
                Range("floor_friction", 0.1, 4.0),
                Range("torso_mass", 0.1, 5.0),
                Range("thigh_mass", 0.1, 6.0),
            ],
        ),
    ],
    "ant": [
        ("Antv2-1_3", "ant", [Range("torso_mass", 0.1, 3.0)]),
        ("Antv2-2_3_3", "ant", [Range("torso_mass", 0.1, 3.0), Range("front_left_leg_mass", 0.01, 3.0)]),
        (
            "Antv2-3_3_3_3",
            "ant",
            [
                Range("torso_mass", 0.1, 3.0),
                Range("front_left_leg_mass", 0.01, 3.0),
                Range("front_right_leg_mass", 0.01, 3.0),
            ],
        ),
    ],
}  # fmt: skip
_BOUNDS = ("ONE_DIM", "TWO_DIM", "THREE_DIM")


def _world_friction(low: float, high: float) -> Range:
    """RRLS's HalfCheetah `worldfriction` [low, high]: it writes `geom_friction[:, 0]`, every
    geom's sliding friction (rrls/envs/half_cheetah.py:175), which on Gymnasium's model, every geom
    at 0.4 and condim 3 (torsional and rolling friction unused), is `friction_scale` = value / 0.4.
    Setting the floor's alone would differ below 0.4: MuJoCo takes the larger of two geoms'."""
    return Range("friction_scale", low / HALF_CHEETAH_FRICTION, high / HALF_CHEETAH_FRICTION)


#: RRLS's own sets on Gymnasium tasks outside the paper's four, as adarl's parameters: (RRLS
#: file, its bounds class, the ranges of ONE_DIM, TWO_DIM, THREE_DIM in RRLS's order). Each
#: RRLS mass `body_mass[i]` is the body Gymnasium's XML has at index i (`body:NAME.mass`).
_RRLS_OWN = {
    "HalfCheetah-v5": (
        "half_cheetah",
        "HalfCheetahParamsBound",
        [
            [_world_friction(0.1, 3.0)],
            [_world_friction(0.1, 4.0), Range("body:torso.mass", 0.1, 7.0)],
            [
                _world_friction(0.1, 4.0),
                Range("body:torso.mass", 0.1, 7.0),
                Range("body:bthigh.mass", 0.1, 3.0),
            ],
        ],
    ),
    "InvertedPendulum-v5": (
        "pendulum",
        "InvertedPendulumParamsBound",
        [
            [Range("body:pole.mass", 1.0, 31.0)],
            [Range("body:pole.mass", 1.0, 31.0), Range("body:cart.mass", 1.0, 11.0)],
        ],
    ),
    "HumanoidStandup-v5": (
        "humanoid",
        "HumanoidStandupParamsBound",
        [
            [Range("body:torso.mass", 0.1, 16.0)],
            [Range("body:torso.mass", 0.1, 16.0), Range("body:right_foot.mass", 0.1, 8.0)],
            [
                Range("body:torso.mass", 0.1, 16.0),
                Range("body:left_thigh.mass", 0.1, 5.0),
                Range("body:right_foot.mass", 0.1, 8.0),
            ],
        ],
    ),
}


def _literature_suites() -> dict[str, dict[str, Suite]]:
    suites: dict[str, dict[str, Suite]] = {}
    for task, sets in _LITERATURE.items():
        for dim, (config, rrls_file, ranges) in enumerate(sets, start=1):
            m2td3 = Suite(f"m2td3-{dim}d", task, tuple(ranges), _M2TD3.format(file=config))
            bound = f"{rrls_file.capitalize()}ParamsBound.{_BOUNDS[dim - 1]}"
            rrls = replace(
                m2td3, name=f"rrls-{dim}d", source=_RRLS.format(file=rrls_file, bound=bound)
            )
            for suite in (m2td3, rrls):
                suites.setdefault(suite.name, {})[task] = suite
    for task, (rrls_file, bounds, sets) in _RRLS_OWN.items():
        for dim, ranges in enumerate(sets, start=1):
            source = _RRLS.format(file=rrls_file, bound=f"{bounds}.{_BOUNDS[dim - 1]}")
            suites[f"rrls-{dim}d"][task] = Suite(f"rrls-{dim}d", task, tuple(ranges), source)
    return dict(sorted(suites.items()))  # m2td3-1d, m2td3-2d, …, rrls-3d


def _paper_suites() -> dict[str, Suite]:
    from adarl.envs.tasks import TASKS

    return {
        name: Suite(
            "paper",
            name,
            tuple(Range(p, s.low, s.high) for p, s in spec.schedules["paper"].items()),
            "AdaRL appendix, 'Model Uncertainty Setting': c ∓ |a| of each schedule "
            "(adarl/envs/tasks.py)",
            base="nominal",
            episodes=10,
        )
        for name, spec in TASKS.items()
    }


#: Suite name -> task -> `Suite`.
SUITES: dict[str, dict[str, Suite]] = _literature_suites() | {"paper": _paper_suites()}


def suite_task(task: str) -> str:
    """The key a task has in `SUITES`: the paper's names in lower case, a Gymnasium id without
    its `gym:` prefix (`gym:HalfCheetah-v5` is `HalfCheetah-v5`)."""
    from adarl.envs.tasks import GYM_PREFIX, TASKS

    task = str(task).strip()
    task = task[len(GYM_PREFIX) :] if task.startswith(GYM_PREFIX) else task
    return task.lower() if task.lower() in TASKS else task


def get_suite(name: str, task: str, points: int | None = None) -> Suite:
    """The suite `name` for `task` (with `points` per dimension instead of its own, when given:
    `adarl evaluate --suite NAME --points N`, a coarser grid over the same ranges); a one-line
    `UsageError` naming the value and what is allowed when the name is unknown or the suite has
    no set for the task."""
    if name not in SUITES:
        raise UsageError(f"unknown suite {name!r}; allowed: {', '.join(SUITES)}")
    task = suite_task(task)
    if task not in SUITES[name]:
        allowed = [n for n, by_task in SUITES.items() if task in by_task]
        raise UsageError(
            f"suite {name!r} does not apply to task {task!r} (it covers "
            f"{', '.join(SUITES[name])}); allowed for {task}: {', '.join(allowed) or 'none'}"
        )
    if points is not None:
        if points < 2:
            raise UsageError(f"--points must be ≥ 2, got {points}")
        return replace(SUITES[name][task], points=points)
    return SUITES[name][task]


def file_name(suite: str, checkpoint: int | None = None) -> str:
    """Stem of a suite's files in a run folder: `suite-m2td3-3d` (`…_step-N` for a checkpoint)."""
    return f"suite-{suite}" + ("" if checkpoint is None else f"_step-{checkpoint}")


# ----------------------------------------------------------------------------- summaries
def point_means(table: pd.DataFrame) -> pd.DataFrame:
    """Mean return over each point's episodes, per seed: columns `step, seed, dynamics, return`
    plus the point's `p_*` values, one row per seed and grid point (in the table's order)."""
    params = layout.param_columns(table.columns)
    keys = ["step", "seed", "dynamics", *params]
    return table.groupby(keys, sort=False, as_index=False)["return"].mean()


def seed_summary(table: pd.DataFrame, suite: str) -> pd.DataFrame:
    """Per seed: the worst-case return (the lowest point mean) and the average return (the mean
    of the point means) over the grid, as M2TD3 and RRLS report them, with the worst point."""
    means = point_means(table)
    episodes = table.groupby(["seed", "dynamics"], sort=False).size()
    rows = []
    for (step, seed), group in means.groupby(["step", "seed"], sort=True):
        worst = group.loc[group["return"].idxmin()]
        rows.append(
            {
                "suite": suite,
                "step": int(step),
                "seed": int(seed),
                "points": len(group),
                "episodes": int(episodes.loc[seed].min()),
                "worst": float(worst["return"]),
                "average": float(group["return"].mean()),
                "worst_point": worst["dynamics"],
            }
        )
    return pd.DataFrame(rows, columns=SUMMARY_COLUMNS)


# ----------------------------------------------------------------------------- running
def suite_spec(suite: Suite, episodes: int | None = None, **kwargs):
    """The `EvalSpec` of a suite (its grid as swept axes over its base dynamics)."""
    from adarl.evaluation.evaluate import EvalSpec

    return EvalSpec(
        dynamics=suite.base,
        axes=suite.axes(),
        episodes=suite.episodes if episodes is None else episodes,
        **kwargs,
    )


def plan_suite(
    runs: Sequence, name: str, episodes: int | None = None, points: int | None = None, **kwargs
) -> list:
    """Every unit of work (one seed at one grid point) of suite `name` for `runs`, all checked
    before any episode runs: unknown suite, a run whose task the suite does not cover, bad
    checkpoints (one-line `UsageError`s)."""
    from adarl.evaluation.evaluate import plan

    suites = [get_suite(name, run.task, points) for run in runs]  # every run checked first
    for run in runs:
        check_model(run, name)
    seeds: dict[tuple[int, int], int] = {}  # (points, episodes) -> seeds: counted, not built
    for suite, run in zip(suites, runs):
        key = (suite.size, suite.episodes if episodes is None else episodes)
        seeds[key] = seeds.get(key, 0) + len(run.seeds)
    grid.check_episodes(
        sum(p * e * n for (p, e), n in seeds.items()),
        " + ".join(f"{p:,} points x {n} seeds x {e} episodes" for (p, e), n in seeds.items()),
    )
    units = []
    for index, (run, suite) in enumerate(zip(runs, suites)):
        spec = suite_spec(suite, episodes, **kwargs)
        units += [replace(u, run_index=index) for u in plan([run], spec)]
    return units


def check_model(run, name: str) -> None:
    """A one-line `UsageError` if `run` trained a Gymnasium id on a model of its own
    (`env_kwargs` with `xml_file`): a published set is defined on Gymnasium's model."""
    from adarl.envs.tasks import parse_env_kwargs

    kwargs = parse_env_kwargs(run.config.get("env_kwargs") or "")
    if "xml_file" in kwargs:
        raise UsageError(
            f"suite {name!r} is defined on Gymnasium's {suite_task(run.task)} model, but "
            f"{run.path} trained on xml_file={kwargs['xml_file']}; allowed: a run on "
            "Gymnasium's model (evaluate yours with --sweep)"
        )


def run_suite(
    runs: Sequence,
    name: str,
    episodes: int | None = None,
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    progress: bool = True,
    points: int | None = None,
    **kwargs,
) -> list[pd.DataFrame]:
    """Evaluate every seed of every run on suite `name`; one episode table per run."""
    from adarl.evaluation.evaluate import tables

    units = plan_suite(runs, name, episodes, points, **kwargs)
    return tables(runs, units, workers, backend, address, progress, desc=f"suite {name}")


def summary_path(run, name: str, checkpoint: int | None = None) -> Path:
    """`RUN_DIR/suites/<name>.csv` (`…_step-N` for a checkpoint): a run's per-seed summary."""
    return run.path / SUITES_DIR / f"{file_name(name, checkpoint).removeprefix('suite-')}.csv"


def write_suite(
    table: pd.DataFrame,
    run,
    name: str,
    episodes: int | None = None,
    checkpoint: int | None = None,
    command: str | None = None,
    points: int | None = None,
    **kwargs,
) -> tuple[Path, Path]:
    """Store a run's suite result: the episode table as an evaluation
    (`RUN_DIR/evaluations/suite-<name>.{csv,json}`, the sidecar naming the suite) and the
    per-seed summary `RUN_DIR/suites/<name>.csv`. Returns both CSV paths."""
    from adarl.evaluation.evaluate import write_evaluation
    from adarl.files import atomic_write_text

    suite = get_suite(name, run.task, points)
    stem = file_name(name, checkpoint)
    spec = suite_spec(suite, episodes, checkpoint=checkpoint, **kwargs)
    extra = {
        "name": stem,
        "suite": name,
        "suite_source": suite.source,
        "suite_ranges": {r.param: [r.low, r.high] for r in suite.ranges},
        "suite_spacing": suite.spacing,
        "suite_points": suite.points,
    }
    episodes_path = run.path / EVALUATIONS_DIR / f"{stem}.csv"
    write_evaluation(table, episodes_path, spec, run, command, extra=extra)
    summary_file = summary_path(run, name, checkpoint)
    summary = seed_summary(table, name)
    atomic_write_text(summary_file, summary.to_csv(index=False, float_format="%.6g"))
    return episodes_path, summary_file


def format_summary(summary: pd.DataFrame) -> str:
    """One line: worst-case and average return, mean ± std over seeds."""

    def text(column: str) -> str:
        values = summary[column].to_numpy(float)
        std = "" if len(values) < 2 else f" ± {np.std(values, ddof=1):.1f}"
        return f"{values.mean():.1f}{std}"

    seeds = len(summary)
    points = int(summary["points"].iloc[0]) if seeds else 0
    return (
        f"worst-case {text('worst')}, average {text('average')} over {points} points "
        f"and {seeds} seed(s)"
    )
