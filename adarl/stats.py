"""Statistics for comparing methods across tasks and seeds (Agarwal et al., 2021, "Deep RL at
the edge of the statistical precipice"; the `rliable` library).

Scores are arrays of shape `(n_runs, n_tasks)`: one entry per seed ("run") and task, usually a
normalised final return. Every estimator also accepts leading batch dimensions
`(..., n_runs, n_tasks)`, which is how the bootstrap evaluates thousands of resamples at once.
The point estimators equal `rliable.metrics` (the tests check it); confidence intervals use the
stratified bootstrap of `rliable.library.StratifiedBootstrap` (runs resampled with replacement
within each task, percentile intervals). That part of rliable needs the `arch` package, which
does not import with pandas ≥ 3, so it is reimplemented here in NumPy, vectorised and seeded.

Per-task means and differences over a handful of seeds use Student-t intervals instead
(`mean_ci`, `welch_difference_ci`, `paired_difference_ci`), exact permutation tests
(`permutation_p_value`, `paired_permutation_p_value`) and the intervals from inverting them
(`paired_permutation_interval`, `two_sample_permutation_interval`), exact tests of counts for
outcomes of two kinds (`counts_exact_test`), the power of Welch's test (`welch_power`,
`welch_minimum_detectable_difference`, `detectable_difference_range` over the SD's own interval)
and of the t-test (`minimum_detectable_difference`, `seeds_per_arm` and their paired versions): at 3–10 seeds a
percentile bootstrap interval covers far less often than its nominal level (73% instead of 95%
for one mean of 3 Gaussian seeds), a t interval covers at its level for Gaussian data
(tests/test_stats_coverage.py checks both).

All functions are pure: same input and seed, same output.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.optimize
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


def bootstrap_ci_bytes(reps: int, values: int) -> int:
    """Peak bytes of a bootstrap interval of `reps` resamples of a statistic of `values` numbers
    (float64: the chunks' results, then their concatenation): 16 per resample and value, as
    tracemalloc measures `performance_profile_ci` at 20,000 and 100,000 resamples."""
    return 16 * reps * values


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
    does (one task). At 3–5 seeds a side it covers 81–88% for a nominal 95%: the report uses
    `welch_difference_ci` instead."""
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


# ----------------------------------------------------------------------------- few seeds
# Intervals and tests for per-task means and differences at 3–10 seeds. A percentile bootstrap
# over so few seeds under-covers (nominal 95% intervals cover 73% of the time for one mean of 3
# Gaussian seeds; tests/test_stats_coverage.py), so these use Student-t intervals, exact
# permutation tests and the power of the two-sample t-test.
MAX_EXACT = 2**18  # permutation tests enumerate up to this many rearrangements, else sample


def mean_ci(values: np.ndarray, confidence: float = 0.95) -> Interval:
    """Mean of 1-D `values` with its Student-t interval x̄ ± t_{(1+c)/2, n−1} · s/√n (`t_interval`);
    NaN bounds for fewer than two values (no interval from one seed)."""
    values = np.asarray(values, float).ravel()
    if values.size < 2:
        point = float(values.mean()) if values.size else float("nan")
        return Interval(point, float("nan"), float("nan"))
    centre, low, high = t_interval(values, confidence)
    return Interval(float(centre), float(low), float(high))


def welch_interval(
    x: np.ndarray, y: np.ndarray, confidence: float = 0.95
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """mean(x) − mean(y) over axis 0 with Welch's t interval, vectorised over trailing axes:

        d ± t_{(1+c)/2, ν} · √(s_x²/n_x + s_y²/n_y),
        ν = (s_x²/n_x + s_y²/n_y)² / ((s_x²/n_x)²/(n_x − 1) + (s_y²/n_y)²/(n_y − 1))

    (Welch–Satterthwaite degrees of freedom; `scipy.stats.ttest_ind(equal_var=False)`). Needs
    two values on each side; where both variances are 0 the interval is the point.
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    n_x, n_y = x.shape[0], y.shape[0]
    diff = x.mean(axis=0) - y.mean(axis=0)
    if n_x < 2 or n_y < 2:
        nan = np.full_like(diff, np.nan)
        return diff, nan, nan
    a, b = x.var(axis=0, ddof=1) / n_x, y.var(axis=0, ddof=1) / n_y
    se = np.sqrt(a + b)
    with np.errstate(invalid="ignore", divide="ignore"):
        df = (a + b) ** 2 / (a**2 / (n_x - 1) + b**2 / (n_y - 1))
    q = scipy.stats.t.ppf((1.0 + confidence) / 2.0, np.where(se > 0, df, 1.0))
    half = np.where(se > 0, q * se, 0.0)
    return diff, diff - half, diff + half


def welch_difference_ci(x: np.ndarray, y: np.ndarray, confidence: float = 0.95) -> Interval:
    """mean(X) − mean(Y) of two independent groups of seeds (1-D) with Welch's t interval
    (`welch_interval`); NaN bounds when a group has fewer than two seeds."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    diff, low, high = welch_interval(x, y, confidence)
    return Interval(float(diff), float(low), float(high))


def paired_difference_ci(x: np.ndarray, y: np.ndarray, confidence: float = 0.95) -> Interval:
    """mean(X − Y) of paired seeds (x[i] and y[i] share seed i) with the Student-t interval of
    the per-seed differences d = x − y: d̄ ± t_{(1+c)/2, n−1} · s_d/√n (`scipy.stats.ttest_rel`)."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    if x.shape != y.shape:
        raise ValueError(f"paired samples need the same number of seeds, got {x.size} and {y.size}")
    return mean_ci(x - y, confidence)


def _two_sided(null: np.ndarray, observed: float) -> float:
    """Two-sided p-value of `observed` against an enumerated (or sampled) null distribution:
    min(1, 2 · min(P(T ≤ t), P(T ≥ t))), as `scipy.stats.permutation_test`, with a relative
    tolerance so that rearrangements equal to the observed one up to rounding count as ties."""
    tol = 1e-12 * max(abs(observed), float(np.max(np.abs(null))), 1e-300)
    less = np.mean(null <= observed + tol)
    greater = np.mean(null >= observed - tol)
    return float(min(1.0, 2.0 * min(less, greater)))


def permutation_p_value(
    x: np.ndarray, y: np.ndarray, resamples: int = 100_000, seed: int = 0
) -> float:
    """Two-sided permutation test of mean(X) = mean(Y) for two independent groups (1-D): the
    statistic mean(X) − mean(Y) over every split of the pooled seeds into groups of n_x and n_y
    (exact when there are at most `MAX_EXACT` splits, else `resamples` random splits with the
    observed one counted, p = (k + 1)/(resamples + 1)); `_two_sided` turns the null distribution
    into p. With 3 seeds a side there are 20 splits, so p ≥ 0.1: no difference can reach 0.05.
    """
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    pooled = np.concatenate([x, y])
    n, n_x = pooled.size, x.size
    if n_x == 0 or y.size == 0:
        return float("nan")
    observed = x.mean() - y.mean()
    total = pooled.sum()
    if math.comb(n, n_x) <= MAX_EXACT:
        groups = np.array(list(itertools.combinations(range(n), n_x)), dtype=np.intp)
        sums = pooled[groups].sum(axis=1)
        return _two_sided(sums / n_x - (total - sums) / y.size, observed)
    rng = np.random.default_rng(seed)
    order = np.argsort(rng.random((resamples, n)), axis=1)[:, :n_x]
    sums = pooled[order].sum(axis=1)
    null = np.concatenate([[observed], sums / n_x - (total - sums) / y.size])
    return _two_sided(null, observed)


def paired_permutation_p_value(
    x: np.ndarray, y: np.ndarray, resamples: int = 100_000, seed: int = 0
) -> float:
    """Two-sided sign-flip permutation test of mean(X − Y) = 0 for paired seeds: under the null
    each difference d_i = x_i − y_i is as likely to be −d_i, so the statistic mean(ε · d) over
    every sign vector ε ∈ {±1}ⁿ (exact for 2ⁿ ≤ `MAX_EXACT`, else `resamples` random sign
    vectors plus the observed one) is the null distribution; `_two_sided` gives p. With n pairs
    the smallest p is 2/2ⁿ: 0.25 for 3 seeds, 0.0625 for 5."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    if x.shape != y.shape:
        raise ValueError(f"paired samples need the same number of seeds, got {x.size} and {y.size}")
    d = x - y
    n = d.size
    if n == 0:
        return float("nan")
    if 2**n <= MAX_EXACT:
        bits = (np.arange(2**n)[:, None] >> np.arange(n)) & 1
        null = (1 - 2 * bits) @ d / n
    else:
        signs = np.random.default_rng(seed).choice([-1.0, 1.0], size=(resamples, n))
        null = np.concatenate([[d.mean()], signs @ d / n])
    return _two_sided(null, float(d.mean()))


# ----------------------------------------------------------------------------- permutation intervals
# Intervals from inverting the exact permutation tests: the shifts δ the test does not reject.
# Both tests' one-sided tail counts are monotone in δ (below), so the accepted shifts form an
# interval whose ends are order statistics of a finite set of "breakpoints"; nothing is searched.


def _inverted_interval(
    breakpoints: np.ndarray, total: int, confidence: float
) -> tuple[float, float]:
    """Accepted shifts of a permutation test whose tail counts at a shift δ are

        greater(δ) = (1 + #{v ≤ δ}) / total,   less(δ) = (1 + #{v ≥ δ}) / total

    over the `breakpoints` v (the rearrangements other than the observed one; the observed one
    is the 1, a tie at every δ). The test accepts δ when p = min(1, 2·min(greater, less)) > α,
    α = 1 − confidence, i.e. when both counts exceed c = total·α/2 − 1: δ ∈ [v₍ₖ₎, v₍ₘ₋ₖ₊₁₎]
    with k the smallest integer above c (order statistics of the m breakpoints); the whole line
    when k ≤ 0 (the test can never reject at this level). A c within rounding of an integer is
    that integer (1 − 0.9 is not 0.1 in binary: 3 vs 3 seeds at 90% have c = 0 exactly)."""
    v = np.sort(np.asarray(breakpoints, float))
    alpha = 1.0 - confidence
    c = total * alpha / 2.0 - 1.0
    k = math.floor(c + 1e-9 * max(1.0, abs(c))) + 1  # smallest integer > c
    if k <= 0:
        return float("-inf"), float("inf")
    return float(v[k - 1]), float(v[v.size - k])


def paired_permutation_interval(
    differences: np.ndarray, confidence: float = 0.95, resamples: int = 100_000, seed: int = 0
) -> Interval:
    """Mean of the paired differences d with the interval of shifts δ that the two-sided exact
    sign-flip test (`paired_permutation_p_value`) of d − δ does not reject at 1 − confidence.

    Flipping the signs of a set F of the d_i − δ changes the mean by −2·Σ_F (d_i − δ)/n, so the
    flipped statistic is ≥ the observed one exactly when δ ≥ mean_F(d): the breakpoints are the
    means of the 2ⁿ − 1 non-empty subsets of d (exact for 2ⁿ ≤ `MAX_EXACT`, else `resamples`
    random sign vectors). The smallest two-sided p is 2/2ⁿ, so for n ≤ 5 pairs no 95% interval
    exists: the result is (−∞, +∞), honestly, not the observed range. Valid (covers at its level)
    when the differences are symmetric about their mean; skewed differences can under-cover
    (tests/test_stats_coverage.py measures both)."""
    d = np.asarray(differences, float).ravel()
    n = d.size
    if n == 0:
        return Interval(float("nan"), float("nan"), float("nan"))
    if 2**n <= MAX_EXACT:
        subsets = ((np.arange(1, 2**n)[:, None] >> np.arange(n)) & 1).astype(float)
    else:
        subsets = np.random.default_rng(seed).integers(0, 2, size=(resamples, n)).astype(float)
        subsets = subsets[subsets.sum(axis=1) > 0]  # an empty flip is the observed arrangement
    sizes = subsets.sum(axis=1)
    low, high = _inverted_interval(subsets @ d / sizes, subsets.shape[0] + 1, confidence)
    return Interval(float(d.mean()), low, high)


def two_sample_permutation_interval(
    x: np.ndarray, y: np.ndarray, confidence: float = 0.95, resamples: int = 100_000, seed: int = 0
) -> Interval:
    """mean(X) − mean(Y) with the interval of shifts δ that the two-sided exact permutation test
    (`permutation_p_value`) of X against Y + δ does not reject at 1 − confidence (the shift
    model: Y + δ has X's distribution).

    A split that moves k ≥ 1 values A ⊂ X to Y's side and k values B ⊂ Y to X's side gives a
    statistic ≥ the observed one exactly when δ ≥ mean(A) − mean(B): those are the breakpoints,
    one per split other than the observed (C(n_x + n_y, n_x) − 1; exact up to `MAX_EXACT`
    splits, else `resamples` random splits). With 5 vs 5 seeds there are 252 splits (smallest p
    2/252), so a 95% interval exists; with 3 vs 3 (20 splits) it is (−∞, +∞)."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    n_x, n = x.size, x.size + y.size
    if n_x == 0 or y.size == 0:
        return Interval(float("nan"), float("nan"), float("nan"))
    if math.comb(n, n_x) <= MAX_EXACT:
        groups = np.array(list(itertools.combinations(range(n), n_x)), dtype=np.intp)
    else:
        rng = np.random.default_rng(seed)
        groups = np.argsort(rng.random((resamples, n)), axis=1)[:, :n_x]
    member = np.zeros((groups.shape[0], n), bool)
    np.put_along_axis(member, groups, True, axis=1)
    moved_in = member[:, n_x:]  # values of Y placed on X's side
    k = moved_in.sum(axis=1)
    keep = k > 0  # k = 0 is the observed split
    moved_out_sum = (~member[keep, :n_x]) @ x  # values of X placed on Y's side
    moved_in_sum = moved_in[keep] @ y
    breakpoints = (moved_out_sum - moved_in_sum) / k[keep]
    low, high = _inverted_interval(breakpoints, int(keep.sum()) + 1, confidence)
    return Interval(float(x.mean() - y.mean()), low, high)


@dataclass(frozen=True)
class CountsTest:
    """Outcomes that are one of two kinds (a policy that hops or falls) counted per arm, with
    exact tests of equal proportions."""

    successes_x: int
    n_x: int
    successes_y: int
    n_y: int
    fisher_p: float  # two-sided Fisher exact test (conditional on both margins)
    boschloo_p: float  # two-sided Boschloo exact test (unconditional; never above Fisher's)


def counts_exact_test(successes_x: int, n_x: int, successes_y: int, n_y: int) -> CountsTest:
    """Exact tests of p_x = p_y for successes_x of n_x against successes_y of n_y: Fisher's
    (hypergeometric; `scipy.stats.fisher_exact`) and Boschloo's (`scipy.stats.boschloo_exact`),
    both two-sided. With 5 vs 5 seeds, Fisher's p < 0.05 needs 5 of 5 against 0 of 5."""
    for name, value, total in (("x", successes_x, n_x), ("y", successes_y, n_y)):
        if not 0 <= value <= total:
            raise ValueError(f"successes_{name} = {value} is not between 0 and n_{name} = {total}")
    table = [[successes_x, n_x - successes_x], [successes_y, n_y - successes_y]]
    fisher = float(scipy.stats.fisher_exact(table, alternative="two-sided").pvalue)
    boschloo = float(scipy.stats.boschloo_exact(table, alternative="two-sided").pvalue)
    return CountsTest(successes_x, n_x, successes_y, n_y, fisher, min(boschloo, 1.0))


def count_above(scores: np.ndarray, threshold: float) -> int:
    """How many per-seed scores exceed `threshold` (the caller's line between the two kinds of
    outcome, e.g. a return that only a hopping policy reaches)."""
    return int(np.sum(np.asarray(scores, float) > threshold))


def holm(p_values: list[float]) -> list[float]:
    """Holm's step-down adjusted p-values, in the input order: with p_(1) ≤ … ≤ p_(m),
    p̃_(j) = max_{i ≤ j} min(1, (m − i + 1)·p_(i)) (Holm 1979). Rejecting where p̃ < α keeps
    the family-wise error rate at α. Two tests at 0.01 and 0.04: 0.02 and 0.04."""
    p = np.asarray(p_values, float)
    if np.any(~np.isfinite(p)) or np.any((p < 0) | (p > 1)):
        raise ValueError(f"p-values must lie in [0, 1]: {p.tolist()}")
    adjusted, running = np.empty(p.size), 0.0
    for rank, i in enumerate(np.argsort(p, kind="stable")):
        running = max(running, min(1.0, (p.size - rank) * p[i]))
        adjusted[i] = running
    return adjusted.tolist()


# ----------------------------------------------------------------------------- power
def pooled_sd(x: np.ndarray, y: np.ndarray) -> float:
    """√(((n_x − 1)s_x² + (n_y − 1)s_y²) / (n_x + n_y − 2)), the SD the two-sample t-test assumes
    both groups share; NaN without a degree of freedom (one seed on each side)."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    df = x.size + y.size - 2
    if df < 1:
        return float("nan")
    ss = ((x - x.mean()) ** 2).sum() + ((y - y.mean()) ** 2).sum() if x.size and y.size else np.nan
    return float(np.sqrt(ss / df))


def _t_power(noncentrality: float, df: float, alpha: float) -> float:
    """P(|T| > t_{1−α/2, df}) for T ~ noncentral t(df, λ): the power of a two-sided t-test."""
    crit = scipy.stats.t.ppf(1.0 - alpha / 2.0, df)
    return float(
        scipy.stats.nct.sf(crit, df, noncentrality) + scipy.stats.nct.cdf(-crit, df, noncentrality)
    )


def t_test_power(difference: float, sd: float, n_x: int, n_y: int, alpha: float = 0.05) -> float:
    """Power of the two-sided two-sample t-test (equal variances) to detect a true difference of
    means `difference` when both groups have SD `sd`: P(|T| > t_{1−α/2, ν}), T ~ noncentral
    t(ν = n_x + n_y − 2, λ = difference / (sd · √(1/n_x + 1/n_y)))."""
    if n_x + n_y - 2 < 1 or min(n_x, n_y) < 1:
        return float("nan")
    if sd == 0:
        return 1.0 if difference != 0 else alpha
    lam = difference / (sd * math.sqrt(1.0 / n_x + 1.0 / n_y))
    return _t_power(lam, n_x + n_y - 2, alpha)


def paired_t_test_power(difference: float, sd_diff: float, n: int, alpha: float = 0.05) -> float:
    """Power of the two-sided paired t-test (one-sample t on the n per-seed differences, SD
    `sd_diff`): P(|T| > t_{1−α/2, n−1}), T ~ noncentral t(n − 1, λ = difference · √n / sd_diff)."""
    if n < 2:
        return float("nan")
    if sd_diff == 0:
        return 1.0 if difference != 0 else alpha
    return _t_power(difference * math.sqrt(n) / sd_diff, n - 1, alpha)


_WELCH_NODES = 200  # quadrature nodes per sample variance in `welch_power`


def welch_power(
    difference: float, sd_x: float, sd_y: float, n_x: int, n_y: int, alpha: float = 0.05
) -> float:
    """Power of the two-sided Welch t-test (`scipy.stats.ttest_ind(equal_var=False)`) on normal
    data with true difference `difference` and SDs sd_x, sd_y, computed, not approximated.

    Given the sample variances S_x², S_y², the difference of means D ~ N(δ, σ²),
    σ² = σ_x²/n_x + σ_y²/n_y, is independent of them, and the test rejects when
    |D| > t_{1−α/2, ν̂} · √(S_x²/n_x + S_y²/n_y) with ν̂ the Welch–Satterthwaite df of the sample
    variances. So power = E[Φ((δ − c)/σ) + Φ((−δ − c)/σ)], c = t_{1−α/2, ν̂}·ŝe, an expectation
    over (n − 1)S²/σ² ~ χ²(n − 1), taken by midpoint quadrature on `_WELCH_NODES` quantiles of
    each χ² (error below 1e-3, tested against simulation). The noncentral t with the population
    ν instead (what `t_test_power` gives for equal SDs) overstates it: at 5 vs 5 seeds it puts
    80% power at 2.02·SD, where Welch's test has 77.6%."""
    if min(n_x, n_y) < 2:
        return float("nan")
    if sd_x == 0 and sd_y == 0:
        return 1.0 if difference != 0 else alpha
    u = (np.arange(_WELCH_NODES) + 0.5) / _WELCH_NODES
    var_x = sd_x**2 * scipy.stats.chi2.ppf(u, n_x - 1) / (n_x - 1)
    var_y = sd_y**2 * scipy.stats.chi2.ppf(u, n_y - 1) / (n_y - 1)
    a, b = var_x[:, None] / n_x, var_y[None, :] / n_y
    se = np.sqrt(a + b)
    with np.errstate(invalid="ignore", divide="ignore"):
        df = (a + b) ** 2 / (a**2 / (n_x - 1) + b**2 / (n_y - 1))
    df = np.where(np.isfinite(df), df, min(n_x, n_y) - 1.0)  # one SD 0: the other's df
    c = scipy.stats.t.ppf(1.0 - alpha / 2.0, df) * se
    sigma = math.sqrt(sd_x**2 / n_x + sd_y**2 / n_y)
    reject = scipy.stats.norm.cdf((difference - c) / sigma) + scipy.stats.norm.cdf(
        (-difference - c) / sigma
    )
    return float(reject.mean())


def welch_minimum_detectable_difference(
    sd_x: float, sd_y: float, n_x: int, n_y: int, power: float = 0.8, alpha: float = 0.05
) -> float:
    """The smallest true difference Welch's test (the test the reports run) detects with
    probability `power`: the δ with `welch_power(δ, sd_x, sd_y, n_x, n_y, α)` = power. At 5 vs 5
    seeds of equal SD: 2.08·SD (the pooled-t `minimum_detectable_difference` gives 2.02·SD)."""
    if not (np.isfinite(sd_x) and np.isfinite(sd_y)) or min(n_x, n_y) < 2:
        return float("nan")
    scale = max(sd_x, sd_y)
    if scale == 0:
        return 0.0
    return scale * _solve_difference(
        lambda d: welch_power(d, sd_x / scale, sd_y / scale, n_x, n_y, alpha), power
    )


def sd_confidence_interval(sd: float, df: int, confidence: float = 0.95) -> tuple[float, float]:
    """Interval for a normal population's SD from a sample SD with `df` degrees of freedom
    (n − 1 for one sample or n paired differences, n_x + n_y − 2 pooled):
    [s·√(df/χ²_{(1+c)/2, df}), s·√(df/χ²_{(1−c)/2, df})]. An SD of 987 from 5 values (df 4):
    [592, 2,837]."""
    if df < 1 or not np.isfinite(sd):
        return float("nan"), float("nan")
    high_q, low_q = scipy.stats.chi2.ppf([(1 + confidence) / 2, (1 - confidence) / 2], df)
    return float(sd * math.sqrt(df / high_q)), float(sd * math.sqrt(df / low_q))


def detectable_difference_range(
    sd: float,
    n_x: int,
    n_y: int | None = None,
    power: float = 0.8,
    alpha: float = 0.05,
    confidence: float = 0.95,
) -> tuple[float, float]:
    """The detectable difference at the ends of the SD's own confidence interval
    (`sd_confidence_interval`): the paired t-test on n_x differences of SD `sd` when n_y is
    None (df n_x − 1), else Welch's test of n_x against n_y seeds sharing SD `sd` (the pooled
    SD, df n_x + n_y − 2). A paired SD of 987 from 5 pairs: 995–4,772."""
    if n_y is None:
        low, high = sd_confidence_interval(sd, n_x - 1, confidence)
        return (
            paired_minimum_detectable_difference(low, n_x, power, alpha),
            paired_minimum_detectable_difference(high, n_x, power, alpha),
        )
    low, high = sd_confidence_interval(sd, n_x + n_y - 2, confidence)
    return (
        welch_minimum_detectable_difference(low, low, n_x, n_y, power, alpha),
        welch_minimum_detectable_difference(high, high, n_x, n_y, power, alpha),
    )


def _solve_difference(power_of, target: float) -> float:
    """The difference δ ≥ 0 at which the increasing function `power_of(δ)` reaches `target`."""
    if power_of(0.0) >= target:
        return 0.0
    high = 1.0
    while (reached := power_of(high)) < target:
        high *= 2.0
    if not np.isfinite(reached):  # scipy's noncentral t gives NaN at large λ for 1 df
        return float("nan")
    return float(scipy.optimize.brentq(lambda d: power_of(d) - target, 0.0, high, xtol=1e-10))


def minimum_detectable_difference(
    sd: float, n_x: int, n_y: int, power: float = 0.8, alpha: float = 0.05
) -> float:
    """The smallest true difference of means the two-sided two-sample t-test detects with
    probability `power` at level α with n_x and n_y seeds and SD `sd`: the δ with
    `t_test_power(δ, sd, n_x, n_y, α)` = power (a root of the noncentral-t power; NaN without a
    degree of freedom or an SD)."""
    if not np.isfinite(sd) or n_x + n_y - 2 < 1 or min(n_x, n_y) < 1:
        return float("nan")
    if sd == 0:
        return 0.0
    return sd * _solve_difference(lambda d: t_test_power(d, 1.0, n_x, n_y, alpha), power)


def paired_minimum_detectable_difference(
    sd_diff: float, n: int, power: float = 0.8, alpha: float = 0.05
) -> float:
    """As `minimum_detectable_difference` for the paired t-test on n per-seed differences of SD
    `sd_diff` (`paired_t_test_power`)."""
    if not np.isfinite(sd_diff) or n < 2:
        return float("nan")
    if sd_diff == 0:
        return 0.0
    return sd_diff * _solve_difference(lambda d: paired_t_test_power(d, 1.0, n, alpha), power)


def _smallest_n(power_at, target: float, start: int) -> int:
    """The smallest n ≥ `start` with `power_at(n)` ≥ `target` (power increases with n)."""
    if power_at(start) >= target:
        return start
    low, high = start, start * 2
    while power_at(high) < target:
        low, high = high, high * 2
    while high - low > 1:  # power_at(low) < target <= power_at(high)
        mid = (low + high) // 2
        low, high = (mid, high) if power_at(mid) < target else (low, mid)
    return high


def seeds_per_arm(difference: float, sd: float, power: float = 0.8, alpha: float = 0.05) -> float:
    """Seeds per group (equal groups, at least 2) for the two-sided two-sample t-test to detect
    a true difference `difference` with probability `power` when the SD is `sd`: the smallest n
    with `t_test_power(difference, sd, n, n, α)` ≥ power. NaN without an SD."""
    if not np.isfinite(sd) or difference == 0:
        return float("nan")
    return _smallest_n(lambda n: t_test_power(abs(difference), sd, n, n, alpha), power, 2)


def paired_seeds_needed(
    difference: float, sd_diff: float, power: float = 0.8, alpha: float = 0.05
) -> float:
    """Pairs of seeds (at least 2) for the two-sided paired t-test to detect `difference` with
    probability `power` when the per-seed differences have SD `sd_diff`
    (`paired_t_test_power`). NaN without an SD."""
    if not np.isfinite(sd_diff) or difference == 0:
        return float("nan")
    return _smallest_n(lambda n: paired_t_test_power(abs(difference), sd_diff, n, alpha), power, 2)


@dataclass(frozen=True)
class Comparison:
    """Two independent groups of seeds compared: the difference of means with its Welch
    interval, the exact permutation p-value, and the power of the comparison at these seeds."""

    difference: Interval  # mean(X) − mean(Y), Welch t interval
    p_value: float  # two-sided exact permutation test (`permutation_p_value`)
    n_x: int
    n_y: int
    sd: float  # pooled SD of the two groups
    detectable: float  # smallest difference detectable at `power` with n_x, n_y seeds
    target: float  # a difference worth detecting
    seeds_for_target: float  # seeds per group to detect `target` at `power`


def compare_groups(
    x: np.ndarray,
    y: np.ndarray,
    target: float = 300.0,
    confidence: float = 0.95,
    power: float = 0.8,
    alpha: float = 0.05,
) -> Comparison:
    """`Comparison` of X − Y (`welch_difference_ci`, `permutation_p_value`, `pooled_sd`,
    `minimum_detectable_difference`, `seeds_per_arm`)."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    sd = pooled_sd(x, y)
    return Comparison(
        difference=welch_difference_ci(x, y, confidence),
        p_value=permutation_p_value(x, y),
        n_x=x.size,
        n_y=y.size,
        sd=sd,
        detectable=minimum_detectable_difference(sd, x.size, y.size, power, alpha),
        target=target,
        seeds_for_target=seeds_per_arm(target, sd, power, alpha),
    )
