"""Comparing methods across tasks and seeds: the report's statistics as DataFrames.

Input everywhere is a long table `scores` with columns `task, method, seed, score` (one final
return per seed). Pure functions (seeded bootstrap) built on `adarl.evaluation.stats`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from adarl.evaluation import stats
from adarl.evaluation.runs import sort_methods, sort_tasks


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


def per_task_estimates(
    scores: pd.DataFrame, reps: int, confidence: float, seed: int
) -> pd.DataFrame:
    """IQM and mean of the raw scores per task and method, with bootstrap intervals. Columns
    `task, method, seeds, iqm, iqm_low, iqm_high, mean, mean_low, mean_high`."""
    rows = []
    for t, task in enumerate(sort_tasks(scores["task"])):
        for m, method in enumerate(sort_methods(scores["method"])):
            sub = scores[(scores["method"] == method) & (scores["task"] == task)]
            if sub.empty:
                continue
            matrix = sub["score"].to_numpy(float)[:, None]
            iqm = stats.bootstrap_ci(matrix, stats.iqm, reps, confidence, seed + 100 * t + m)
            mean = stats.bootstrap_ci(matrix, stats.mean, reps, confidence, seed + 100 * t + m)
            rows.append(
                {"task": task, "method": method, "seeds": len(sub),
                 "iqm": iqm.point, "iqm_low": iqm.low, "iqm_high": iqm.high,
                 "mean": mean.point, "mean_low": mean.low, "mean_high": mean.high}
            )  # fmt: skip
    return pd.DataFrame(rows)


def improvement_estimates(
    scores: pd.DataFrame, reference: str, reps: int, confidence: float, seed: int
) -> pd.DataFrame:
    """P(reference > baseline) for every other method, on the tasks both ran (raw scores: the
    statistic only compares scores within a task). Columns `baseline, tasks, point, low, high`."""
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
            {"baseline": method, "tasks": " ".join(common), "point": ci.point, "low": ci.low,
             "high": ci.high}
        )  # fmt: skip
    return pd.DataFrame(rows, columns=["baseline", "tasks", "point", "low", "high"])


def profile_estimates(
    normalised: Normalised, taus: np.ndarray, reps: int, confidence: float, seed: int
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Performance profile `(profile, low, high)` over `taus` per method."""
    return {
        method: stats.performance_profile_ci(matrix, taus, reps, confidence, seed + i)
        for i, (method, matrix) in enumerate(normalised.matrices.items())
    }
