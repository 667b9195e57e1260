"""The paired sign-flip test where it samples (2ⁿ above `MAX_EXACT`): the observed sign vector
counts among the resamples, so p is never 0, at least 1/(resamples + 1), and close to the exact
p computed by enumerating every sign vector here (issue 38)."""

import itertools

import numpy as np
import pytest

from adarl import stats


def exact_sign_flip_p(d: np.ndarray) -> float:
    """Every sign vector, by itertools: 2 · min(P(T ≤ t), P(T ≥ t)), capped at 1."""
    t = d.mean()
    null = np.array([np.dot(s, d) / d.size for s in itertools.product((-1.0, 1.0), repeat=d.size)])
    tol = 1e-9 * max(abs(t), 1.0)
    return min(1.0, 2 * min(np.mean(null <= t + tol), np.mean(null >= t - tol)))


@pytest.mark.parametrize("resamples", [10, 1000])
def test_a_sampled_p_is_never_zero(resamples):
    x = np.arange(30, dtype=float) + 100.0  # 2³⁰ sign vectors: sampled; every d_i > 0
    y = np.zeros(30)
    p = stats.paired_permutation_p_value(x, y, resamples=resamples)
    assert p > 0 and p >= 1.0 / (resamples + 1)
    assert p <= 2.0 / (resamples + 1) + 1e-12  # no resample reaches the observed sum


def test_a_sampled_p_is_close_to_the_exact_one(monkeypatch):
    rng = np.random.default_rng(3)
    x, y = rng.normal(1.0, 2.0, 12), rng.normal(0.0, 2.0, 12)
    exact = exact_sign_flip_p(x - y)
    assert stats.paired_permutation_p_value(x, y) == pytest.approx(exact, abs=1e-12)
    monkeypatch.setattr(stats, "MAX_EXACT", 16)  # 2¹² > 16: sampled
    sampled = stats.paired_permutation_p_value(x, y, resamples=200_000, seed=1)
    assert sampled == pytest.approx(exact, abs=0.005)  # 4 SE of a p near 0.1 at 200k
    assert 0.01 < exact < 0.9  # a p where the comparison means something
