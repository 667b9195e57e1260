"""Statistics against hand-computed values and against rliable's own estimators."""

import csv
import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.stats
from rliable import metrics

from adarl import stats


def test_iqm_trims_a_quarter_from_each_end():
    # 8 scores (4 runs × 2 tasks): drop 1, 2 and 7, 8 → mean(3, 4, 5, 6) = 4.5
    scores = np.array([[1, 5], [2, 6], [3, 7], [4, 8]], float)
    assert stats.iqm(scores) == pytest.approx(4.5)
    # 4 runs × 1 task: drop 1 and 4 → 2.5
    assert stats.iqm(np.array([[1.0], [2.0], [3.0], [40.0]])) == pytest.approx(2.5)


def test_mean_and_median_of_task_means():
    scores = np.array([[1.0, 10.0, 0.0], [3.0, 20.0, 2.0]])  # task means 2, 15, 1
    assert stats.mean(scores) == pytest.approx(6.0)
    assert stats.median(scores) == pytest.approx(2.0)


def test_point_estimates_equal_rliable_and_accept_batches():
    rng = np.random.default_rng(0)
    scores = rng.normal(size=(7, 3))
    assert stats.iqm(scores) == pytest.approx(metrics.aggregate_iqm(scores))
    assert stats.mean(scores) == pytest.approx(metrics.aggregate_mean(scores))
    assert stats.median(scores) == pytest.approx(metrics.aggregate_median(scores))
    batch = rng.normal(size=(4, 5, 2))
    assert np.allclose(stats.iqm(batch), [metrics.aggregate_iqm(b) for b in batch])


def test_probability_of_improvement_by_hand():
    # pairs (1,2) (1,2) (3,2) (3,2): X wins twice of four
    assert stats.probability_of_improvement([[1.0], [3.0]], [[2.0], [2.0]]) == pytest.approx(0.5)
    # (2,2) tie ½, (2,1) win, (3,2) win, (3,1) win → 3.5 / 4
    assert stats.probability_of_improvement([[2.0], [3.0]], [[2.0], [1.0]]) == pytest.approx(0.875)
    # averaged over tasks: task 1 → 1, task 2 → 0
    assert stats.probability_of_improvement([[5.0, 0.0]], [[1.0, 9.0]]) == pytest.approx(0.5)


def test_probability_of_improvement_equals_rliable():
    rng = np.random.default_rng(1)
    x, y = (
        rng.integers(0, 4, size=(5, 3)).astype(float),
        rng.integers(0, 4, size=(6, 3)).astype(float),
    )
    assert stats.probability_of_improvement(x, y) == pytest.approx(
        metrics.probability_of_improvement(x, y)
    )


def test_performance_profile_by_hand():
    scores = np.array([[0.1, 0.5], [0.9, 0.3]])
    taus = np.array([0.0, 0.2, 0.4, 0.6, 1.0])
    assert stats.performance_profile(scores, taus) == pytest.approx([1.0, 0.75, 0.5, 0.25, 0.0])


def test_stratified_resampling_stays_within_each_task():
    scores = np.array([[1.0, 10.0], [2.0, 20.0], [3.0, 30.0]])
    samples = stats.stratified_resample(scores, 50, np.random.default_rng(0))
    assert samples.shape == (50, 3, 2)
    assert set(np.unique(samples[..., 0])) <= {1.0, 2.0, 3.0}
    assert set(np.unique(samples[..., 1])) <= {10.0, 20.0, 30.0}


def test_bootstrap_interval_by_hand():
    # one run per task: every resample is the data itself
    one = stats.bootstrap_ci(np.array([[3.0, 5.0]]), stats.mean, reps=100)
    assert (one.point, one.low, one.high) == (4.0, 4.0, 4.0)
    # two runs a=0, b=1 on one task: resampled means are 0, ½, 1 with probability ¼, ½, ¼,
    # so the 2.5% and 97.5% percentiles are 0 and 1
    two = stats.bootstrap_ci(np.array([[0.0], [1.0]]), stats.mean, reps=4000, seed=3)
    assert (two.point, two.low, two.high) == (0.5, 0.0, 1.0)


def test_bootstrap_is_seeded_and_brackets_the_estimate():
    scores = np.random.default_rng(2).normal(size=(10, 4))
    a = stats.bootstrap_ci(scores, stats.iqm, reps=2000, seed=7)
    assert a == stats.bootstrap_ci(scores, stats.iqm, reps=2000, seed=7)
    assert a != stats.bootstrap_ci(scores, stats.iqm, reps=2000, seed=8)
    assert a.low < a.point < a.high
    poi = stats.probability_of_improvement_ci(scores + 1, scores, reps=500, seed=0)
    assert poi.point == pytest.approx(stats.probability_of_improvement(scores + 1, scores))
    assert poi.low <= poi.point <= poi.high
    profile, low, high = stats.performance_profile_ci(scores, np.linspace(-1, 1, 5), reps=300)
    assert np.all(low <= profile + 1e-12) and np.all(profile <= high + 1e-12)


def test_t_interval_by_hand():
    centre, low, high = stats.t_interval(np.array([[1.0], [2.0], [3.0]]))
    half = scipy.stats.t.ppf(0.975, 2) * 1.0 / np.sqrt(3)  # s = 1
    assert centre == pytest.approx([2.0])
    assert high - centre == pytest.approx([half]) and centre - low == pytest.approx([half])
    centre, low, high = stats.t_interval(np.array([[4.0, 5.0]]))  # one seed: no band
    assert np.array_equal(low, centre) and np.array_equal(high, centre)


def test_normalise_and_mean_std():
    scores = np.array([[0.0, 10.0], [5.0, 30.0]])
    assert stats.minmax_normalise(scores, [0.0, 10.0], [10.0, 30.0]) == pytest.approx(
        np.array([[0.0, 0.0], [0.5, 1.0]])
    )
    assert stats.mean_std([1.0, 2.0, 3.0]) == pytest.approx((2.0, 1.0))
    m, s = stats.mean_std([4.0])
    assert m == 4.0 and np.isnan(s)


def test_difference_ci_against_a_numpy_loop():
    x, y = np.array([3.0, 5.0, 10.0]), np.array([1.0, 2.0, 2.5, 4.0])
    got = stats.difference_ci(x, y, reps=400, confidence=0.9, seed=3)
    rng = np.random.default_rng(3)  # the same draws, one resample at a time
    ix = rng.integers(0, 3, size=(400, 3, 1))[:, :, 0]
    iy = rng.integers(0, 4, size=(400, 4, 1))[:, :, 0]
    diffs = x[ix].mean(axis=1) - y[iy].mean(axis=1)
    assert got.point == pytest.approx(x.mean() - y.mean())
    assert got.low == pytest.approx(np.percentile(diffs, 5.0))
    assert got.high == pytest.approx(np.percentile(diffs, 95.0))
    assert got.low < got.point < got.high
    same = stats.difference_ci(np.full(3, 2.0), np.full(5, 2.0), reps=100)
    assert (same.point, same.low, same.high) == (0.0, 0.0, 0.0)


# ----------------------------------------------------------------------------- few seeds
X = np.array([812.0, 1430.0, 265.0, 990.0, 1211.0])
Y = np.array([402.0, 655.0, 310.0, 1020.0])


def test_t_intervals_equal_scipy():
    one = stats.mean_ci(X, 0.9)
    expected = scipy.stats.ttest_1samp(X, 0.0).confidence_interval(0.9)
    assert one.point == pytest.approx(X.mean())
    assert (one.low, one.high) == pytest.approx((expected.low, expected.high))
    welch = stats.welch_difference_ci(X, Y)
    expected = scipy.stats.ttest_ind(X, Y, equal_var=False).confidence_interval(0.95)
    assert welch.point == pytest.approx(X.mean() - Y.mean())
    assert (welch.low, welch.high) == pytest.approx((expected.low, expected.high))
    paired = stats.paired_difference_ci(X[:4], Y)
    expected = scipy.stats.ttest_rel(X[:4], Y).confidence_interval(0.95)
    assert paired.point == pytest.approx((X[:4] - Y).mean())
    assert (paired.low, paired.high) == pytest.approx((expected.low, expected.high))


def test_no_interval_from_one_seed():
    assert np.isnan(stats.mean_ci([5.0]).low) and stats.mean_ci([5.0]).point == 5.0
    assert np.isnan(stats.welch_difference_ci([5.0], Y).high)
    same = stats.welch_difference_ci(np.full(3, 2.0), np.full(4, 1.0))
    assert (same.point, same.low, same.high) == (1.0, 1.0, 1.0)
    with pytest.raises(ValueError):
        stats.paired_difference_ci(X, Y)


def _mean_difference(a, b, axis=-1):
    return np.mean(a, axis=axis) - np.mean(b, axis=axis)


@pytest.mark.parametrize(
    "x, y",
    [(X, Y), (X[:3], Y[:3]), (np.array([1.0, 2.0, 2.0]), np.array([2.0, 2.0, 3.0, 3.0]))],
)
def test_permutation_p_value_equals_scipy_exact(x, y):
    expected = scipy.stats.permutation_test(
        (x, y), _mean_difference, permutation_type="independent", n_resamples=np.inf
    ).pvalue
    assert stats.permutation_p_value(x, y) == pytest.approx(expected)


def test_three_seeds_a_side_cannot_reach_five_percent():
    # 20 splits of 6 seeds into 3 + 3: the most extreme split has p = 2/20
    assert stats.permutation_p_value([10.0, 11.0, 12.0], [0.0, 1.0, 2.0]) == pytest.approx(0.1)


def test_permutation_p_value_samples_when_there_are_too_many_splits(monkeypatch):
    rng = np.random.default_rng(5)
    x, y = rng.normal(1.0, 1.0, 12), rng.normal(0.0, 1.0, 12)  # C(24, 12) = 2.7 million splits
    exact = scipy.stats.permutation_test(
        (x, y), _mean_difference, permutation_type="independent", n_resamples=20_000, rng=1
    ).pvalue
    got = stats.permutation_p_value(x, y, resamples=20_000, seed=2)
    assert got == pytest.approx(exact, abs=0.01)


@pytest.mark.parametrize("n", [3, 6, 19])
def test_sign_flip_p_value_equals_scipy(n):
    rng = np.random.default_rng(n)
    x, y = rng.normal(0.5, 1.0, n), rng.normal(0.0, 1.0, n)
    exact = n <= 17
    expected = scipy.stats.permutation_test(
        (x, y), _mean_difference, permutation_type="samples",
        n_resamples=np.inf if exact else 50_000, rng=3,
    ).pvalue  # fmt: skip
    got = stats.paired_permutation_p_value(x, y, resamples=50_000, seed=4)
    assert got == pytest.approx(expected, abs=0 if exact else 0.01)
    assert stats.paired_permutation_p_value([3.0, 4.0, 5.0], [0.0, 0.0, 0.0]) == 0.25  # 2 / 2³


def test_pooled_sd_by_hand():
    x, y = np.array([1.0, 3.0]), np.array([2.0, 4.0, 6.0])  # squares 2 + 8, df 3
    assert stats.pooled_sd(x, y) == pytest.approx(np.sqrt(10.0 / 3.0))
    assert np.isnan(stats.pooled_sd([1.0], [2.0]))


# ----------------------------------------------------------------------------- power
def power_by_integral(lam: float, df: int, alpha: float = 0.05) -> float:
    """P(|Z + λ| / √(V/df) > t_crit), Z ~ N(0, 1), V ~ χ²_df, integrated over V: the power of a
    two-sided t-test from its definition, without the noncentral t distribution."""
    import scipy.integrate

    crit = scipy.stats.t.ppf(1 - alpha / 2, df)

    def integrand(v):
        bound = crit * np.sqrt(v / df)
        tails = scipy.stats.norm.sf(bound - lam) + scipy.stats.norm.cdf(-bound - lam)
        return tails * scipy.stats.chi2.pdf(v, df)

    return scipy.integrate.quad(integrand, 0, np.inf, limit=200)[0]


@pytest.mark.parametrize("n_x, n_y, delta", [(3, 3, 500.0), (5, 4, 300.0), (10, 10, 250.0)])
def test_two_sample_power_equals_the_integral(n_x, n_y, delta):
    sd = 400.0
    lam = delta / (sd * np.sqrt(1 / n_x + 1 / n_y))
    expected = power_by_integral(lam, n_x + n_y - 2)
    assert stats.t_test_power(delta, sd, n_x, n_y) == pytest.approx(expected, abs=1e-6)


def test_two_sample_power_by_simulation():
    rng = np.random.default_rng(0)
    n, sd, delta, sims = 5, 400.0, 600.0, 20_000
    x, y = rng.normal(delta, sd, (sims, n)), rng.normal(0.0, sd, (sims, n))
    rejected = np.mean(scipy.stats.ttest_ind(x, y, axis=1).pvalue < 0.05)
    assert stats.t_test_power(delta, sd, n, n) == pytest.approx(rejected, abs=0.015)  # 4.5 SE


def test_paired_power_equals_the_integral_and_simulation():
    sd, n, delta = 200.0, 6, 250.0
    expected = power_by_integral(delta * np.sqrt(n) / sd, n - 1)
    assert stats.paired_t_test_power(delta, sd, n) == pytest.approx(expected, abs=1e-6)
    d = np.random.default_rng(1).normal(delta, sd, (20_000, n))
    rejected = np.mean(scipy.stats.ttest_1samp(d, 0.0, axis=1).pvalue < 0.05)
    assert stats.paired_t_test_power(delta, sd, n) == pytest.approx(rejected, abs=0.015)


@pytest.mark.parametrize("n_x, n_y", [(3, 3), (5, 5), (5, 3), (10, 10)])
def test_minimum_detectable_difference_has_80_percent_power(n_x, n_y):
    sd = 400.0
    mdd = stats.minimum_detectable_difference(sd, n_x, n_y)
    lam = mdd / (sd * np.sqrt(1 / n_x + 1 / n_y))
    assert power_by_integral(lam, n_x + n_y - 2) == pytest.approx(0.8, abs=1e-6)
    paired = stats.paired_minimum_detectable_difference(sd, n_x)
    assert power_by_integral(paired * np.sqrt(n_x) / sd, n_x - 1) == pytest.approx(0.8, abs=1e-6)


def test_seeds_per_arm_is_the_smallest_with_80_percent_power():
    # Cohen (1988), Table 2.4.1: d = 1 needs 17 per group, d = 0.5 needs 64 (α = 0.05, two-sided)
    assert stats.seeds_per_arm(1.0, 1.0) == 17 and stats.seeds_per_arm(0.5, 1.0) == 64
    sd = 538.0  # AdaRL's seeds on Hopper at 100k steps (README)
    n = stats.seeds_per_arm(300.0, sd)
    lam = lambda k: 300.0 / (sd * np.sqrt(2 / k))  # noqa: E731
    assert power_by_integral(lam(n), 2 * n - 2) >= 0.8 > power_by_integral(lam(n - 1), 2 * n - 4)
    m = stats.paired_seeds_needed(300.0, sd)
    plam = lambda k: 300.0 * np.sqrt(k) / sd  # noqa: E731
    assert power_by_integral(plam(m), m - 1) >= 0.8 > power_by_integral(plam(m - 1), m - 2)
    assert np.isnan(stats.seeds_per_arm(300.0, float("nan")))
    assert stats.minimum_detectable_difference(0.0, 3, 3) == 0.0


def test_compare_groups_bundles_the_pieces():
    c = stats.compare_groups(X, Y, target=300.0)
    assert c.difference == stats.welch_difference_ci(X, Y)
    assert c.p_value == stats.permutation_p_value(X, Y) and (c.n_x, c.n_y) == (5, 4)
    assert c.detectable == stats.minimum_detectable_difference(stats.pooled_sd(X, Y), 5, 4)
    assert c.seeds_for_target == stats.seeds_per_arm(300.0, stats.pooled_sd(X, Y))


# ----------------------------------------------------------------------------- permutation intervals
def _sign_flip_p(d, delta):
    """Two-sided sign-flip p of mean(d − δ) = 0, by a plain loop over every sign vector."""
    shifted = [v - delta for v in d]
    observed = sum(shifted)
    count_ge = count_le = 0
    for signs in itertools.product((1, -1), repeat=len(d)):
        s = sum(e * v for e, v in zip(signs, shifted))
        count_ge += s >= observed - 1e-9
        count_le += s <= observed + 1e-9
    total = 2 ** len(d)
    return min(1.0, 2 * min(count_ge, count_le) / total)


def _two_sample_p(x, y, delta):
    """Two-sided permutation p of X against Y + δ by a plain loop over every split."""
    pooled = list(x) + [v + delta for v in y]
    n, n_x = len(pooled), len(x)
    observed = sum(x) / n_x - sum(pooled[n_x:]) / (n - n_x)
    count_ge = count_le = total = 0
    for group in itertools.combinations(range(n), n_x):
        inside = sum(pooled[i] for i in group)
        s = inside / n_x - (sum(pooled) - inside) / (n - n_x)
        count_ge += s >= observed - 1e-9
        count_le += s <= observed + 1e-9
        total += 1
    return min(1.0, 2 * min(count_ge, count_le) / total)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_paired_permutation_interval_is_the_set_the_test_accepts(seed):
    d = np.round(np.random.default_rng(seed).normal(100, 300, 7), 1)
    interval = stats.paired_permutation_interval(d, confidence=0.9)  # 7 pairs: p ≥ 1/64
    eps = 1e-6
    for delta in (interval.low, interval.high, interval.low + eps, interval.high - eps):
        assert _sign_flip_p(d, delta) > 0.1
    for delta in (interval.low - eps, interval.high + eps, interval.low - 50, interval.high + 50):
        assert _sign_flip_p(d, delta) <= 0.1
    assert interval.point == pytest.approx(d.mean())


def test_paired_permutation_interval_of_the_hopper_mechanism_experiment():
    """The committed per-seed differences of docs/experiments/mechanism-hopper.md (AdaRL −
    control, 10 pairs): the referee of issue 34 inverted the sign-flip test to [−748, +4]."""
    table = Path(__file__).parents[1] / "docs/experiments/mechanism-hopper/tables/control_pairs.csv"
    with table.open() as f:
        d = [float(row["difference"]) for row in csv.DictReader(f)]
    interval = stats.paired_permutation_interval(d)
    assert len(d) == 10
    assert interval.low == pytest.approx(-748.5, abs=0.5)
    assert 4.0 < interval.high < 5.0


def test_five_pairs_have_no_95_percent_permutation_interval():
    interval = stats.paired_permutation_interval([1.0, 2.0, 3.0, 4.0, 5.0])
    assert (interval.low, interval.high) == (-np.inf, np.inf)  # smallest p is 2/32 = 0.0625
    narrower = stats.paired_permutation_interval([1.0, 2.0, 3.0, 4.0, 5.0], confidence=0.9)
    assert np.isfinite(narrower.low) and np.isfinite(narrower.high)


@pytest.mark.parametrize("seed", [0, 1])
def test_two_sample_permutation_interval_is_the_set_the_test_accepts(seed):
    rng = np.random.default_rng(seed)
    x, y = np.round(rng.normal(900, 400, 5), 1), np.round(rng.normal(500, 400, 5), 1)
    interval = stats.two_sample_permutation_interval(x, y)
    eps = 1e-6
    for delta in (interval.low, interval.high, interval.low + eps, interval.high - eps):
        assert _two_sample_p(x, y, delta) > 0.05
    for delta in (interval.low - eps, interval.high + eps):
        assert _two_sample_p(x, y, delta) <= 0.05
    assert interval.point == pytest.approx(x.mean() - y.mean())


def test_two_sample_permutation_interval_samples_when_there_are_too_many_splits(monkeypatch):
    rng = np.random.default_rng(3)
    x, y = rng.normal(1, 1, 6), rng.normal(0, 1, 6)
    exact = stats.two_sample_permutation_interval(x, y)
    monkeypatch.setattr(stats, "MAX_EXACT", 100)  # C(12, 6) = 924 splits: sampled now
    sampled = stats.two_sample_permutation_interval(x, y, resamples=20_000)
    assert sampled.low == pytest.approx(exact.low, abs=0.15)
    assert sampled.high == pytest.approx(exact.high, abs=0.15)


def test_three_seeds_a_side_have_no_95_percent_permutation_interval():
    interval = stats.two_sample_permutation_interval([5.0, 6.0, 7.0], [1.0, 2.0, 3.0])
    assert (interval.low, interval.high) == (-np.inf, np.inf)  # 20 splits: p ≥ 0.1


# ----------------------------------------------------------------------------- counts
def test_counts_exact_test_by_hand():
    """Fisher's p for 4 of 5 against 1 of 5: the hypergeometric table probabilities with 5 of
    10 successes, summed over the tables at most as likely as the observed one."""
    prob = [math.comb(5, k) * math.comb(5, 5 - k) / math.comb(10, 5) for k in range(6)]
    observed = prob[4]
    expected = sum(p for p in prob if p <= observed * (1 + 1e-9))
    result = stats.counts_exact_test(4, 5, 1, 5)
    assert result.fisher_p == pytest.approx(expected)  # 0.2063
    assert result.boschloo_p <= result.fisher_p + 1e-12
    assert stats.counts_exact_test(5, 5, 0, 5).fisher_p == pytest.approx(2 / 252)
    assert stats.count_above([450, 2700, 2900, 430, 1200], 1000) == 3
    with pytest.raises(ValueError, match="successes_x = 6"):
        stats.counts_exact_test(6, 5, 0, 5)


# ----------------------------------------------------------------------------- Welch power
@pytest.mark.parametrize(
    "delta, sd_x, sd_y, n_x, n_y",
    [
        (2.024, 1.0, 1.0, 5, 5),
        (1.0, 1.0, 1.0, 10, 10),
        (1.5, 1.5, 0.5, 5, 10),
        (0.0, 1.0, 2.0, 5, 5),
    ],
)
def test_welch_power_by_simulation(delta, sd_x, sd_y, n_x, n_y):
    rng = np.random.default_rng(11)
    draws = 40_000
    x = rng.normal(delta, sd_x, (draws, n_x))
    y = rng.normal(0.0, sd_y, (draws, n_y))
    simulated = np.mean(scipy.stats.ttest_ind(x, y, axis=1, equal_var=False).pvalue < 0.05)
    se = math.sqrt(simulated * (1 - simulated) / draws)
    assert stats.welch_power(delta, sd_x, sd_y, n_x, n_y) == pytest.approx(simulated, abs=4 * se)


def test_welch_detectable_difference_is_above_the_pooled_t_figure():
    """Issue 34: the pooled-t detectable difference (2.02·SD at 5 vs 5) has 77.6% power under
    Welch's test; Welch's own is 2.08·SD."""
    assert stats.welch_power(2.0244, 1.0, 1.0, 5, 5) == pytest.approx(0.776, abs=0.002)
    mdd = stats.welch_minimum_detectable_difference(1042.0, 1042.0, 5, 5)
    assert stats.welch_power(mdd, 1042.0, 1042.0, 5, 5) == pytest.approx(0.8, abs=1e-6)
    assert mdd > stats.minimum_detectable_difference(1042.0, 5, 5)
    assert mdd / 1042.0 == pytest.approx(2.08, abs=0.01)


def test_sd_interval_and_detectable_range_of_issue_34():
    """An SD of 987 from 5 values has the 95% interval [592, 2,837] (χ² with 4 df, here
    computed from the quantiles 0.4844 and 11.143), and the paired test on 5 pairs then detects
    995–4,772."""
    low, high = stats.sd_confidence_interval(987.0, 4)
    assert low == pytest.approx(987.0 * math.sqrt(4 / 11.1433), rel=1e-4)
    assert high == pytest.approx(987.0 * math.sqrt(4 / 0.484419), rel=1e-4)
    dlow, dhigh = stats.detectable_difference_range(987.0, 5)
    assert dlow == pytest.approx(stats.paired_minimum_detectable_difference(low, 5))
    assert dhigh == pytest.approx(stats.paired_minimum_detectable_difference(high, 5))
    assert (round(dlow, -1), round(dhigh, -1)) == (990.0, 4770.0)
    two = stats.detectable_difference_range(1000.0, 5, 5)
    low8, high8 = stats.sd_confidence_interval(1000.0, 8)
    assert two[0] == pytest.approx(stats.welch_minimum_detectable_difference(low8, low8, 5, 5))
    assert two[1] == pytest.approx(stats.welch_minimum_detectable_difference(high8, high8, 5, 5))


def _holm_by_procedure(p_values: list[float]) -> list[float]:
    """Holm's adjusted p of each test as the smallest level α at which the step-down procedure
    (reject p_(1), p_(2), … while p_(j) ≤ α / (m − j + 1)) rejects it, found by running the
    procedure at every level where a decision can change."""
    m = len(p_values)
    order = sorted(range(m), key=lambda i: p_values[i])
    levels = sorted({min(1.0, (m - j) * p_values[i]) for j, i in enumerate(order)} | {1.0})
    adjusted = [1.0] * m
    for alpha in reversed(levels):  # the smallest level that rejects is found last
        for j, i in enumerate(order):
            if p_values[i] > alpha / (m - j):
                break
            adjusted[i] = alpha
    return adjusted


@pytest.mark.parametrize(
    "p_values",
    [[0.01, 0.04], [0.03, 0.02], [0.5, 0.9], [0.001, 0.04, 0.03, 0.2], [0.02, 0.02, 0.5]],
)
def test_holm_equals_the_step_down_procedure(p_values):
    assert stats.holm(p_values) == pytest.approx(_holm_by_procedure(p_values))


def test_holm_by_hand_and_refuses_what_is_no_p_value():
    assert stats.holm([0.01, 0.04]) == pytest.approx([0.02, 0.04])
    assert stats.holm([0.03, 0.02]) == pytest.approx([0.04, 0.04])  # monotone: 2 × 0.02, then 0.03
    assert stats.holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])  # capped at 1
    with pytest.raises(ValueError, match="in \\[0, 1\\]"):
        stats.holm([0.2, float("nan")])
