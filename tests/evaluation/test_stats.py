"""Statistics against hand-computed values and against rliable's own estimators."""

import numpy as np
import pytest
import scipy.stats
from rliable import metrics

from adarl.evaluation import stats


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
