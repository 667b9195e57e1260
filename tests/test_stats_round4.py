"""Issue 55 §4: behaviour tests of adarl.stats that planted bugs got past, each checked against
a planted bug (docs/reliability.md): the sampled paired interval is the seed's, the paired test
at exactly MAX_EXACT sign vectors enumerates them, the two-sample inverted interval at 90%, and
Holm refuses a p above 1."""

from __future__ import annotations

import numpy as np
import pytest

from adarl import stats


def test_the_same_seed_gives_the_same_sampled_paired_interval():
    d = np.random.default_rng(0).normal(1.0, 2.0, size=19)  # 2^19 > MAX_EXACT: sampled
    assert 2**d.size > stats.MAX_EXACT
    one = stats.paired_permutation_interval(d, resamples=2000, seed=5)
    two = stats.paired_permutation_interval(d, resamples=2000, seed=5)
    other = stats.paired_permutation_interval(d, resamples=2000, seed=6)
    assert one == two
    assert (other.low, other.high) != (one.low, one.high)
    p = stats.paired_permutation_p_value(d, np.zeros_like(d), resamples=2000, seed=5)
    assert p == stats.paired_permutation_p_value(d, np.zeros_like(d), resamples=2000, seed=5)


def test_at_exactly_max_exact_sign_vectors_the_paired_p_is_enumerated():
    """n = 18 pairs, 2^18 = MAX_EXACT sign vectors, all differences +1: the observed mean is the
    largest of the enumerated null, reached by 1 sign vector in 2^18, so p = 2 / 2^18 exactly;
    sampling 100,000 vectors could not give that value."""
    n = int(np.log2(stats.MAX_EXACT))
    assert 2**n == stats.MAX_EXACT
    p = stats.paired_permutation_p_value(np.ones(n), np.zeros(n))
    assert p == 2 / 2**n


def test_the_two_sample_inverted_interval_at_90_percent():
    """Its ends are where the two-sided permutation test of X against Y + δ turns from
    rejecting (p ≤ 0.10) to accepting (p > 0.10), with 5 vs 5 seeds (252 splits)."""
    rng = np.random.default_rng(3)
    x, y = rng.normal(10.0, 2.0, 5), rng.normal(7.0, 2.0, 5)
    interval = stats.two_sample_permutation_interval(x, y, confidence=0.90)
    wide = stats.two_sample_permutation_interval(x, y, confidence=0.95)
    assert wide.low < interval.low < interval.high < wide.high
    for end, inside in ((interval.low, +1), (interval.high, -1)):
        step = 1e-6 * max(1.0, abs(end))
        accept = stats.permutation_p_value(x, y + end + inside * step)
        reject = stats.permutation_p_value(x, y + end - inside * step)
        assert accept > 0.10 >= reject, (end, accept, reject)


@pytest.mark.parametrize("bad", [1.2, 1.0000001, -0.1])
def test_holm_refuses_a_p_above_1_or_below_0(bad):
    with pytest.raises(ValueError, match=r"p-values must lie in \[0, 1\]"):
        stats.holm([0.01, bad])
    assert stats.holm([0.01, 1.0]) == pytest.approx([0.02, 1.0])
