"""Comparing methods across tasks and seeds: the report's statistics as DataFrames.

Input everywhere is a long table `scores` with columns `task, method, seed, score` (one score
per seed; the report adds `final`, the final checkpoint's). Aggregates over tasks and seeds use
rliable's estimators with stratified-bootstrap intervals; per-task means and differences over a
few seeds use t intervals, exact permutation tests and t-test power. Pure functions (seeded
bootstrap) built on `adarl.stats`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from adarl import stats
from adarl.results.runs import sort_methods, sort_tasks


def score_matrix(scores: pd.DataFrame, method: str, tasks: Sequence[str]) -> np.ndarray:
    """`(n_seeds, n_tasks)` scores of one method. Every task keeps the same number of seeds
    (the smallest count over `tasks`, lowest seeds first), as rliable's arrays require."""
    columns = []
    for task in tasks:
        rows = scores[(scores["method"] == method) & (scores["task"] == task)].sort_values("seed")
        columns.append(rows["score"].to_numpy(float))
    n = min(len(c) for c in columns)
    return np.stack([c[:n] for c in columns], axis=1)


@dataclass(frozen=True)
class Normalised:
    """Min–max normalised score matrices of the methods that ran on every task."""

    tasks: list[str]
    matrices: dict[str, np.ndarray]  # method -> (n_seeds, n_tasks)
    left_out: list[str]  # methods missing some task
    uneven: list[str]  # methods whose tasks have different seed counts (cut to the smallest)


def normalise(scores: pd.DataFrame) -> Normalised:
    """Scores of each task mapped to [0, 1] by the lowest and highest seed's score on that task
    over all methods, for the methods that cover every task in `scores`."""
    tasks = sort_tasks(scores["task"])
    methods = sort_methods(scores["method"])
    covering = [m for m in methods if set(tasks) <= set(scores.loc[scores["method"] == m, "task"])]
    low = scores.groupby("task")["score"].min().reindex(tasks).to_numpy()
    high = scores.groupby("task")["score"].max().reindex(tasks).to_numpy()
    matrices = {
        m: stats.minmax_normalise(score_matrix(scores, m, tasks), low, high) for m in covering
    }
    uneven = [
        m for m in covering if scores[scores["method"] == m].groupby("task").size().nunique() > 1
    ]
    return Normalised(tasks, matrices, [m for m in methods if m not in covering], uneven)


def aggregate_estimates(
    normalised: Normalised, reps: int, confidence: float, seed: int
) -> pd.DataFrame:
    """IQM and mean across tasks and seeds per method, with stratified-bootstrap intervals.
    Columns `method, metric, point, low, high, runs, tasks`."""
    rows = []
    for i, (method, matrix) in enumerate(normalised.matrices.items()):
        for metric, fn in (("IQM", stats.iqm), ("Mean", stats.mean)):
            ci = stats.bootstrap_ci(matrix, fn, reps, confidence, seed + i)
            rows.append(
                {"method": method, "metric": metric, "point": ci.point, "low": ci.low,
                 "high": ci.high, "runs": matrix.shape[0], "tasks": matrix.shape[1]}
            )  # fmt: skip
    return pd.DataFrame(rows, columns=["method", "metric", "point", "low", "high", "runs", "tasks"])


def per_task_estimates(scores: pd.DataFrame, confidence: float = 0.95) -> pd.DataFrame:
    """Per task and method: the mean over seeds with its Student-t interval
    x̄ ± t_{(1+c)/2, n−1} · s/√n (`stats.mean_ci`; no interval from one seed), the sample SD and
    the IQM (point only: a bootstrap interval of an IQM over a few seeds under-covers), and, where
    `scores` has a `final` column (the final checkpoint's score), its mean and t interval.
    Columns `task, method, seeds, mean, mean_low, mean_high, sd, iqm` (+ `final_mean,
    final_low, final_high`)."""
    rows = []
    for task in sort_tasks(scores["task"]):
        for method in sort_methods(scores["method"]):
            sub = scores[(scores["method"] == method) & (scores["task"] == task)]
            if sub.empty:
                continue
            values = sub["score"].to_numpy(float)
            mean = stats.mean_ci(values, confidence)
            row = {"task": task, "method": method, "seeds": len(sub), "mean": mean.point,
                   "mean_low": mean.low, "mean_high": mean.high,
                   "sd": stats.mean_std(values)[1], "iqm": float(stats.iqm(values[:, None]))}  # fmt: skip
            if "final" in sub:
                final = stats.mean_ci(sub["final"].dropna().to_numpy(float), confidence)
                row |= {"final_mean": final.point, "final_low": final.low, "final_high": final.high}
            rows.append(row)
    return pd.DataFrame(rows)


DIFFERENCE_COLUMNS = [
    "task", "baseline", "seeds", "difference", "low", "high", "p_value", "sd", "detectable",
    "target", "seeds_for_target",
]  # fmt: skip


def comparison_row(comparison: stats.Comparison) -> dict:
    """The columns of one `stats.Comparison` in the report's tables (`DIFFERENCE_COLUMNS`
    from `seeds` on)."""
    c = comparison
    return {
        "seeds": f"{c.n_x} vs {c.n_y}",
        "difference": c.difference.point,
        "low": c.difference.low,
        "high": c.difference.high,
        "p_value": c.p_value,
        "sd": c.sd,
        "detectable": c.detectable,
        "target": c.target,
        "seeds_for_target": c.seeds_for_target,
    }


def difference_estimates(
    scores: pd.DataFrame,
    reference: str,
    confidence: float = 0.95,
    target: float = 300.0,
    power: float = 0.8,
    alpha: float = 0.05,
) -> pd.DataFrame:
    """Per task, mean(reference) − mean(baseline) for every other method that ran the task
    (`stats.compare_groups`: Welch interval, exact permutation p-value, pooled SD, the smallest
    difference detectable at `power` with these seeds, the seeds per arm `target` would need).
    Columns `DIFFERENCE_COLUMNS`."""
    rows = []
    for task in sort_tasks(scores["task"]):
        on_task = scores[scores["task"] == task]
        x = on_task.loc[on_task["method"] == reference, "score"].to_numpy(float)
        if not len(x):
            continue
        for method in sort_methods(on_task["method"]):
            if method == reference:
                continue
            y = on_task.loc[on_task["method"] == method, "score"].to_numpy(float)
            comparison = stats.compare_groups(x, y, target, confidence, power, alpha)
            rows.append({"task": task, "baseline": method, **comparison_row(comparison)})
    return pd.DataFrame(rows, columns=DIFFERENCE_COLUMNS)


def improvement_estimates(
    scores: pd.DataFrame, reference: str, reps: int, confidence: float, seed: int
) -> pd.DataFrame:
    """P(reference > baseline) for every other method, on the tasks both ran (raw scores: the
    statistic only compares scores within a task). Columns `baseline, tasks, seeds` ("5 vs 5",
    per task), `min_seeds, point, low, high`."""
    tasks = sort_tasks(scores["task"])
    ran = {m: set(g["task"]) for m, g in scores.groupby("method")}
    rows = []
    for i, method in enumerate(m for m in sort_methods(scores["method"]) if m != reference):
        common = [t for t in tasks if t in ran.get(reference, ()) and t in ran[method]]
        if not common:
            continue
        x, y = score_matrix(scores, reference, common), score_matrix(scores, method, common)
        ci = stats.probability_of_improvement_ci(x, y, reps, confidence, seed + i)
        rows.append(
            {"baseline": method, "tasks": " ".join(common), "seeds": f"{len(x)} vs {len(y)}",
             "min_seeds": min(len(x), len(y)), "point": ci.point, "low": ci.low,
             "high": ci.high}
        )  # fmt: skip
    columns = ["baseline", "tasks", "seeds", "min_seeds", "point", "low", "high"]
    return pd.DataFrame(rows, columns=columns)


def profile_estimates(
    normalised: Normalised, taus: np.ndarray, reps: int, confidence: float, seed: int
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Performance profile `(profile, low, high)` over `taus` per method."""
    return {
        method: stats.performance_profile_ci(matrix, taus, reps, confidence, seed + i)
        for i, (method, matrix) in enumerate(normalised.matrices.items())
    }
