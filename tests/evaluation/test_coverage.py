"""Coverage of the report's intervals at the seed counts we run (3, 5, 10), simulated on Gaussian
data: a 95% interval must contain the true mean (or difference) in at least 92% of 4000 simulated
datasets. For a correct 95% interval the simulated coverage has standard error
√(0.95 · 0.05 / 4000) ≈ 0.34%, so 92% is nine standard errors below the nominal level: a failure
is an interval that under-covers, not bad luck. The percentile bootstrap that the report used
before fails it; the test shows that too, so the comparison is measured, not assumed.

Run `python tests/evaluation/test_coverage.py` to print the coverage table."""

import numpy as np
import pytest

from adarl.evaluation import stats

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


if __name__ == "__main__":
    print("n   t mean  Welch diff  bootstrap mean  bootstrap diff")
    for n in (3, 5, 10):
        t = t_coverage(n)
        b = percentile_bootstrap_coverage(n)
        print(f"{n:<3} {t[0]:.3f}   {t[1]:.3f}       {b[0]:.3f}           {b[1]:.3f}")
