"""Statistics for comparing methods across tasks and seeds (Agarwal et al., 2021, "Deep RL at
the edge of the statistical precipice"; the `rliable` library).

Scores are arrays of shape `(n_runs, n_tasks)`: one entry per seed ("run") and task, usually a
normalised final return. Every estimator also accepts leading batch dimensions
`(..., n_runs, n_tasks)`, which is how the bootstrap evaluates thousands of resamples at once.
The point estimators equal `rliable.metrics` (the tests check it); confidence intervals use the
stratified bootstrap of `rliable.library.StratifiedBootstrap` (runs resampled with replacement
within each task, percentile intervals). That part of rliable needs the `arch` package, which
does not import with pandas ≥ 3, so it is reimplemented here in NumPy, vectorised and seeded.

All functions are pure: same input and seed, same output.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.stats

_CHUNK = 1000  # bootstrap resamples evaluated at once (bounds memory)


@dataclass(frozen=True)
class Interval:
    """A point estimate with a confidence interval [low, high]."""

    point: float
    low: float
    high: float


# ----------------------------------------------------------------------------- point estimates
def iqm(scores: np.ndarray) -> np.ndarray:
    """Interquartile mean: the mean of the middle 50% of all runs × tasks scores (25% trimmed
    from each end, as `scipy.stats.trim_mean(…, 0.25)`); `rliable.metrics.aggregate_iqm`."""
    scores = np.asarray(scores, float)
    flat = scores.reshape(*scores.shape[:-2], -1)
    return scipy.stats.trim_mean(flat, 0.25, axis=-1)


def mean(scores: np.ndarray) -> np.ndarray:
    """Mean over tasks of the mean over runs; `rliable.metrics.aggregate_mean`."""
    return np.asarray(scores, float).mean(axis=-2).mean(axis=-1)


def median(scores: np.ndarray) -> np.ndarray:
    """Median over tasks of the mean over runs; `rliable.metrics.aggregate_median`."""
    return np.median(np.asarray(scores, float).mean(axis=-2), axis=-1)


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """P(X > Y): for each task, the probability that a random run of X scores higher than a
    random run of Y, ties counting one half (the Mann–Whitney U statistic over n_x·n_y), then
    averaged over tasks; `rliable.metrics.probability_of_improvement`.

    `x` is `(..., n_x, n_tasks)`, `y` is `(..., n_y, n_tasks)`.
    """
    x = np.asarray(x, float)[..., :, None, :]
    y = np.asarray(y, float)[..., None, :, :]
    per_task = (x > y).mean(axis=(-3, -2)) + 0.5 * (x == y).mean(axis=(-3, -2))
    return per_task.mean(axis=-1)


def performance_profile(scores: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """Score distribution: for each threshold τ, the fraction of all runs × tasks scores that
    exceed τ (rliable's `run_score_deviation`). Returns `(..., len(taus))`."""
    scores = np.asarray(scores, float)[..., None]
    return (scores > np.asarray(taus, float)).mean(axis=(-3, -2))


# ----------------------------------------------------------------------------- bootstrap
def stratified_resample(scores: np.ndarray, reps: int, rng: np.random.Generator) -> np.ndarray:
    """`reps` stratified bootstrap resamples of `(n_runs, n_tasks)` scores: within each task,
    `n_runs` runs drawn with replacement. Returns `(reps, n_runs, n_tasks)`."""
    scores = np.asarray(scores, float)
    n_runs, n_tasks = scores.shape
    idx = rng.integers(0, n_runs, size=(reps, n_runs, n_tasks))
    return np.take_along_axis(scores[None], idx, axis=1)


def _percentiles(samples: np.ndarray, confidence: float) -> tuple[np.ndarray, np.ndarray]:
    alpha = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(samples, [alpha, 100.0 - alpha], axis=0)
    return low, high


def _chunks(reps: int):
    done = 0
    while done < reps:
        n = min(_CHUNK, reps - done)
        yield n
        done += n


def bootstrap_ci(
    scores: np.ndarray,
    statistic: Callable[[np.ndarray], np.ndarray],
    reps: int = 10_000,
    confidence: float = 0.95,
    seed: int = 0,
) -> Interval:
    """`statistic(scores)` with a stratified-bootstrap percentile confidence interval.

    `statistic` must accept a batch `(reps, n_runs, n_tasks)` (as `iqm` and `mean` do).
    """
    scores = np.asarray(scores, float)
    rng = np.random.default_rng(seed)
    samples = np.concatenate(
        [np.atleast_1d(statistic(stratified_resample(scores, n, rng))) for n in _chunks(reps)]
    )
    low, high = _percentiles(samples, confidence)
    return Interval(float(statistic(scores)), float(low), float(high))


def probability_of_improvement_ci(
    x: np.ndarray, y: np.ndarray, reps: int = 10_000, confidence: float = 0.95, seed: int = 0
) -> Interval:
    """P(X > Y) with a confidence interval; X and Y are resampled independently, each stratified
    by task (rliable's `StratifiedIndependentBootstrap`)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    rng = np.random.default_rng(seed)
    samples = np.concatenate(
        [
            probability_of_improvement(
                stratified_resample(x, n, rng), stratified_resample(y, n, rng)
            )
            for n in _chunks(reps)
        ]
    )
    low, high = _percentiles(samples, confidence)
    return Interval(float(probability_of_improvement(x, y)), float(low), float(high))


def difference_ci(
    x: np.ndarray, y: np.ndarray, reps: int = 10_000, confidence: float = 0.95, seed: int = 0
) -> Interval:
    """mean(X) − mean(Y) of two independent groups of seeds (1-D), with a percentile bootstrap
    interval: each group resampled with replacement on its own, as `probability_of_improvement_ci`
    does (one task)."""
    x, y = np.asarray(x, float).reshape(-1, 1), np.asarray(y, float).reshape(-1, 1)
    rng = np.random.default_rng(seed)
    samples = np.concatenate(
        [
            mean(stratified_resample(x, n, rng)) - mean(stratified_resample(y, n, rng))
            for n in _chunks(reps)
        ]
    )
    low, high = _percentiles(samples, confidence)
    return Interval(float(x.mean() - y.mean()), float(low), float(high))


def performance_profile_ci(
    scores: np.ndarray,
    taus: np.ndarray,
    reps: int = 10_000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The performance profile at `taus` and its pointwise bootstrap band `(profile, low, high)`."""
    scores = np.asarray(scores, float)
    rng = np.random.default_rng(seed)
    samples = np.concatenate(
        [performance_profile(stratified_resample(scores, n, rng), taus) for n in _chunks(reps)]
    )
    low, high = _percentiles(samples, confidence)
    return performance_profile(scores, taus), low, high


# ----------------------------------------------------------------------------- helpers
def minmax_normalise(scores: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """(score − low) / (high − low) per task (last axis); a task with high = low maps to 0."""
    scores = np.asarray(scores, float)
    low, high = np.asarray(low, float), np.asarray(high, float)
    span = np.where(high > low, high - low, 1.0)
    return (scores - low) / span


def mean_std(values: np.ndarray) -> tuple[float, float]:
    """Mean and sample standard deviation (n − 1 in the denominator; NaN for one value)."""
    values = np.asarray(values, float)
    if values.size == 0:
        return float("nan"), float("nan")
    std = float(np.std(values, ddof=1)) if values.size > 1 else float("nan")
    return float(np.mean(values)), std


def t_interval(
    values: np.ndarray, confidence: float = 0.95
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean over axis 0 with a Student-t confidence band: mean ± t_{(1+c)/2, n−1} · s / √n.

    `values` is `(n_seeds, …)`; with one seed the band collapses onto the mean. Used for the
    bands of curves over seeds (training, rank, robustness).
    """
    values = np.asarray(values, float)
    n = np.sum(np.isfinite(values), axis=0)
    centre = np.nanmean(values, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        sd = np.nanstd(values, axis=0, ddof=1) if values.shape[0] > 1 else np.zeros_like(centre)
        q = scipy.stats.t.ppf((1.0 + confidence) / 2.0, np.maximum(n - 1, 1))
        half = np.where(n > 1, q * sd / np.sqrt(np.maximum(n, 1)), 0.0)
    return centre, centre - half, centre + half


def paired_difference_ci(x: np.ndarray, y: np.ndarray, confidence: float = 0.95) -> Interval:
    """mean(X − Y) of paired seeds (x[i] and y[i] share seed i) with the Student-t interval of
    the per-seed differences d = x − y: d̄ ± t_{(1+c)/2, n−1} · s_d/√n (`scipy.stats.ttest_rel`);
    NaN bounds for fewer than two pairs. Pairing removes what the two arms share (a forked
    control shares AdaRL's whole prefix), so it is far tighter than comparing two groups."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    if x.shape != y.shape:
        raise ValueError(f"paired samples need the same number of seeds, got {x.size} and {y.size}")
    d = x - y
    if d.size < 2:
        point = float(d.mean()) if d.size else float("nan")
        return Interval(point, float("nan"), float("nan"))
    centre, low, high = t_interval(d, confidence)
    return Interval(float(centre), float(low), float(high))
