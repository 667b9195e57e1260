"""Coverage of the report's intervals at the seed counts we run (3, 5, 10), simulated on Gaussian
data: a 95% interval must contain the true mean (or difference) in at least 92% of 4000 simulated
datasets. For a correct 95% interval the simulated coverage has standard error
√(0.95 · 0.05 / 4000) ≈ 0.34%, so 92% is nine standard errors below the nominal level: a failure
is an interval that under-covers, not bad luck. The percentile bootstrap that the report used
before fails it; the test shows that too, so the comparison is measured, not assumed.

The second half (issue 34) measures coverage on the shapes our returns have: arms whose seeds hop
or fall, right-skewed returns, and paired differences that are symmetric-bimodal or mostly small
with the odd large loss; there the exact permutation intervals (`two_sample_permutation_interval`,
`paired_permutation_interval`) are compared with the t intervals.

Run `python tests/test_stats_coverage.py` to print the coverage tables."""

import numpy as np
import pytest

from adarl import stats

DATASETS = 4000
BOOTSTRAP = 2000
LEVEL = 0.95
THRESHOLD = 0.92
MU_X, MU_Y, SD_X, SD_Y = 1000.0, 700.0, 400.0, 250.0  # Hopper-like returns, unequal spreads


def _draw(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(MU_X, SD_X, (n, DATASETS)), rng.normal(MU_Y, SD_Y, (n, DATASETS))


def _covered(low: np.ndarray, high: np.ndarray, truth: float) -> float:
    return float(np.mean((low <= truth) & (truth <= high)))


def t_coverage(n: int, seed: int = 0) -> tuple[float, float]:
    """Coverage of `stats.t_interval` (one mean) and `stats.welch_interval` (difference)."""
    x, y = _draw(n, seed)
    _, low, high = stats.t_interval(x, LEVEL)
    _, dlow, dhigh = stats.welch_interval(x, y, LEVEL)
    return _covered(low, high, MU_X), _covered(dlow, dhigh, MU_X - MU_Y)


def bootstrap_resample_means(data: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """`BOOTSTRAP` resampled means of every dataset (column) of `data` (n, datasets): each
    resample draws n seeds with replacement, i.e. multinomial counts over the n seeds."""
    n = data.shape[0]
    counts = rng.multinomial(n, np.full(n, 1.0 / n), size=BOOTSTRAP)  # (BOOTSTRAP, n)
    return counts @ data / n


def percentile_bootstrap_coverage(n: int, seed: int = 0) -> tuple[float, float]:
    """Coverage of the percentile bootstrap (`stats.bootstrap_ci`, `stats.difference_ci`)."""
    x, y = _draw(n, seed)
    rng = np.random.default_rng(seed + 1)
    mx, my = bootstrap_resample_means(x, rng), bootstrap_resample_means(y, rng)
    q = [100 * (1 - LEVEL) / 2, 100 * (1 + LEVEL) / 2]
    low, high = np.percentile(mx, q, axis=0)
    dlow, dhigh = np.percentile(mx - my, q, axis=0)
    return _covered(low, high, MU_X), _covered(dlow, dhigh, MU_X - MU_Y)


@pytest.mark.parametrize("n", [3, 5, 10])
def test_t_intervals_cover_at_their_level(n):
    mean_coverage, difference_coverage = t_coverage(n)
    assert mean_coverage >= THRESHOLD, mean_coverage
    assert difference_coverage >= THRESHOLD, difference_coverage


@pytest.mark.parametrize("n", [3, 5])
def test_the_percentile_bootstrap_under_covers_at_few_seeds(n):
    mean_coverage, difference_coverage = percentile_bootstrap_coverage(n)
    assert mean_coverage < THRESHOLD and difference_coverage < THRESHOLD


def test_the_scalar_intervals_are_the_vectorised_ones():
    x, y = _draw(5, 3)
    _, low, high = stats.t_interval(x, LEVEL)
    _, dlow, dhigh = stats.welch_interval(x, y, LEVEL)
    for j in (0, 17):
        one = stats.mean_ci(x[:, j], LEVEL)
        diff = stats.welch_difference_ci(x[:, j], y[:, j], LEVEL)
        assert (one.low, one.high) == pytest.approx((low[j], high[j]))
        assert (diff.low, diff.high) == pytest.approx((dlow[j], dhigh[j]))


# ----------------------------------------------------------------------------- other shapes
# Our outcomes are not Gaussian: at the paper's schedule a seed hops (~2,700) or falls (~450), and
# paired differences are mostly small with the odd large one. Coverage of each interval on such
# populations, at our seed counts (issue 34). SHAPE_DATASETS per case: SE of a 95% coverage ≈ 0.5%.
SHAPE_DATASETS = 2000


def hop_or_fall(rng, size):
    """60% of seeds hop (2,700 ± 200), 40% fall (450 ± 50): the 3M Hopper arms' shape."""
    hops = rng.random(size) < 0.6
    return np.where(hops, rng.normal(2700, 200, size), rng.normal(450, 50, size))


def lognormal(rng, size):
    """Right-skewed returns, mean exp(7 + 0.8²/2) ≈ 1,515."""
    return rng.lognormal(7.0, 0.8, size)


def two_sample_coverage(shape, n: int, seed: int = 0) -> tuple[float, float]:
    """Coverage of the true shift (both arms of one `shape`, Y shifted by −300) by the Welch
    interval and by the inverted exact permutation interval, n vs n seeds."""
    rng = np.random.default_rng(seed)
    x, y = shape(rng, (SHAPE_DATASETS, n)), shape(rng, (SHAPE_DATASETS, n)) - 300.0
    welch = [stats.welch_difference_ci(a, b) for a, b in zip(x, y)]
    perm = [stats.two_sample_permutation_interval(a, b) for a, b in zip(x, y)]
    return (
        float(np.mean([i.low <= 300.0 <= i.high for i in welch])),
        float(np.mean([i.low <= 300.0 <= i.high for i in perm])),
    )


def paired_coverage(draw, truth: float, n: int, seed: int = 0) -> tuple[float, float]:
    """Coverage of the mean difference `truth` by the paired t interval and by the inverted
    sign-flip interval, n pairs drawn by `draw(rng, size)`."""
    rng = np.random.default_rng(seed)
    d = draw(rng, (SHAPE_DATASETS, n))
    t_int = [stats.mean_ci(row) for row in d]
    perm = [stats.paired_permutation_interval(row) for row in d]
    return (
        float(np.mean([i.low <= truth <= i.high for i in t_int])),
        float(np.mean([i.low <= truth <= i.high for i in perm])),
    )


def symmetric_bimodal(rng, size):
    """Differences of +600 or −600 (± 100) with equal chance around +100: a seed that hops in
    one arm and falls in the other, either way; symmetric about its mean 100."""
    signs = np.where(rng.random(size) < 0.5, 1.0, -1.0)
    return 100.0 + signs * rng.normal(600, 100, size)


def mostly_small_gains(rng, size):
    """Issue 34's population: 90% of pairs at +40, 10% at −360; mean 0, skewed."""
    return np.where(rng.random(size) < 0.9, 40.0, -360.0)


@pytest.mark.parametrize("shape", [hop_or_fall, lognormal], ids=["hop-or-fall", "lognormal"])
def test_the_permutation_interval_covers_a_shift_on_any_shape(shape):
    """Under the shift model the two arms are exchangeable at the true shift, so the inverted
    exact test covers at least at its level whatever the shape (5 vs 5 seeds)."""
    _, perm = two_sample_coverage(shape, 5)
    assert perm >= 0.93, perm


def test_welch_is_conservative_when_both_arms_hop_or_fall_alike():
    """Same shape in both arms (a shift): Welch's interval over-covers (0.971 measured on
    2026-12-04), so its power is lower than its nominal figure, and it is still valid."""
    welch, _ = two_sample_coverage(hop_or_fall, 5)
    assert welch >= 0.95, welch


def test_no_interval_covers_arms_that_hop_in_different_proportions():
    """80% of one arm's seeds hop against 20% of the other's: not a shift, so neither interval
    keeps its level (measured 0.885 Welch, 0.880 permutation at 5 vs 5). For outcomes of two
    kinds, report the counts with an exact test (`stats.counts_exact_test`)."""
    rng = np.random.default_rng(0)

    def arm(share, size):
        hops = rng.random(size) < share
        return np.where(hops, rng.normal(2700, 200, size), rng.normal(450, 50, size))

    x, y = arm(0.8, (SHAPE_DATASETS, 5)), arm(0.2, (SHAPE_DATASETS, 5))
    truth = 0.6 * (2700 - 450)
    welch = np.mean([_contains(stats.welch_difference_ci(a, b), truth) for a, b in zip(x, y)])
    perm = np.mean(
        [_contains(stats.two_sample_permutation_interval(a, b), truth) for a, b in zip(x, y)]
    )
    assert welch < 0.92 and perm < 0.92, (welch, perm)


def _contains(interval, truth: float) -> bool:
    return interval.low <= truth <= interval.high


def test_the_sign_flip_interval_covers_symmetric_differences():
    t_cov, perm = paired_coverage(symmetric_bimodal, 100.0, 10)
    assert perm >= 0.93, perm
    assert t_cov >= 0.9, t_cov


def test_neither_paired_interval_covers_mostly_small_gains():
    """With 10 pairs from issue 34's mean-zero population, all ten differences are +40 in
    0.9¹⁰ = 35% of samples; then both intervals collapse onto +40 and miss 0. A sign-flip
    rejection says "not symmetric about 0", not "positive mean"."""
    t_cov, perm = paired_coverage(mostly_small_gains, 0.0, 10)
    assert t_cov < 0.7 and perm < 0.7, (t_cov, perm)
    assert abs(1 - t_cov - 0.9**10) < 0.05  # misses are the all-positive samples, and few others


if __name__ == "__main__":
    print("n   t mean  Welch diff  bootstrap mean  bootstrap diff")
    for n in (3, 5, 10):
        t = t_coverage(n)
        b = percentile_bootstrap_coverage(n)
        print(f"{n:<3} {t[0]:.3f}   {t[1]:.3f}       {b[0]:.3f}           {b[1]:.3f}")
    print("\nshape          seeds  Welch  permutation (two-sample shift)")
    for shape in (hop_or_fall, lognormal):
        for n in (5, 10) if shape is hop_or_fall else (5,):
            if n == 10:
                continue  # 184,756 splits per dataset: too slow for 2,000 datasets here
            w, p = two_sample_coverage(shape, n)
            print(f"{shape.__name__:14s} {n:<5}  {w:.3f}  {p:.3f}")
    print("\npaired differences   pairs  t      sign-flip")
    for draw, truth in ((symmetric_bimodal, 100.0), (mostly_small_gains, 0.0)):
        for n in (5, 10):
            c, p = paired_coverage(draw, truth, n)
            print(f"{draw.__name__:20s} {n:<5}  {c:.3f}  {p:.3f}")
