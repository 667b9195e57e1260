"""The permutation intervals of adarl.stats against brute force in exact rational arithmetic: a
shift δ is in the interval when the two-sided permutation test of X against Y + δ (every split,
or every sign vector, enumerated here) does not reject at α = 1 − confidence, rejecting when
p ≤ α, p = min(1, 2·min(P(T ≤ t), P(T ≥ t))). Integer data put every breakpoint on a grid of
1/lcm, so scanning the grid finds the interval's ends exactly. The cases where total·α/2 is an
integer (3 vs 3 at 90%: 20·0.05 = 1) are where an off-by-one in the order statistic shows."""

import itertools
import math
from fractions import Fraction

import numpy as np
import pytest

from adarl import stats


def _accepts(null_stats, observed, alpha: Fraction) -> bool:
    total = len(null_stats)
    less = sum(s <= observed for s in null_stats)
    greater = sum(s >= observed for s in null_stats)
    return min(Fraction(1), Fraction(2 * min(less, greater), total)) > alpha


def two_sample_accepts(x, y, delta: Fraction, alpha: Fraction) -> bool:
    pooled = [Fraction(v) for v in x] + [Fraction(v) + delta for v in y]
    n, n_x = len(pooled), len(x)

    def statistic(group):
        inside = [pooled[i] for i in group]
        outside = [pooled[i] for i in range(n) if i not in group]
        return sum(inside) / n_x - sum(outside) / (n - n_x)

    null = [statistic(set(g)) for g in itertools.combinations(range(n), n_x)]
    return _accepts(null, statistic(set(range(n_x))), alpha)


def paired_accepts(d, delta: Fraction, alpha: Fraction) -> bool:
    shifted = [Fraction(v) - delta for v in d]
    null = [
        sum(s * v for s, v in zip(signs, shifted)) / len(d)
        for signs in itertools.product((1, -1), repeat=len(d))
    ]
    return _accepts(null, sum(shifted) / len(d), alpha)


def brute_interval(accepts, centre: float, spread: int, denominator: int):
    """(low, high) of the accepted grid points j/denominator around `centre`; infinite ends
    where the scan's edge is still accepted."""
    grid = [
        Fraction(round(centre * denominator) + j, denominator)
        for j in range(-spread * denominator, spread * denominator + 1)
    ]
    accepted = [g for g in grid if accepts(g)]
    assert accepted, "no shift accepted"
    low = -math.inf if accepted[0] == grid[0] else float(accepted[0])
    high = math.inf if accepted[-1] == grid[-1] else float(accepted[-1])
    # the accepted set is one closed interval: every grid point between its ends is accepted
    assert len(accepted) == grid.index(accepted[-1]) - grid.index(accepted[0]) + 1
    return low, high


@pytest.mark.parametrize(
    "x, y, confidence",
    [
        ([10, 12, 15], [7, 8, 11], "0.9"),  # 20 splits: 20·0.05 = 1, an integer
        ([10, 12, 15], [7, 8, 11], "0.8"),  # 20·0.1 = 2
        ([10, 12, 15], [7, 8, 11], "0.7"),  # 20·0.15 = 3
        ([10, 12, 15], [7, 8, 11], "0.95"),  # 20·0.025 = 0.5: never rejects, the whole line
        ([3, 9, 14, 20], [1, 2, 8, 10], "0.8"),  # 70 splits: 70·0.1 = 7
        ([3, 9, 14, 20], [1, 2, 8, 10], "0.9"),  # 70·0.05 = 3.5, not an integer
    ],
)
def test_the_two_sample_permutation_interval_is_the_brute_force_one(x, y, confidence):
    alpha = 1 - Fraction(confidence)
    k = len(x)
    denominator = math.lcm(*range(1, k + 1))  # breakpoints: differences of means of j-subsets
    spread = max(x + y) - min(x + y) + 1
    expected = brute_interval(
        lambda d: two_sample_accepts(x, y, d, alpha), np.mean(x) - np.mean(y), spread, denominator
    )
    got = stats.two_sample_permutation_interval(
        np.array(x, float), np.array(y, float), confidence=float(confidence)
    )
    assert (got.low, got.high) == pytest.approx(expected, rel=1e-12, abs=1e-12)
    assert got.point == pytest.approx(np.mean(x) - np.mean(y))


@pytest.mark.parametrize(
    "d, confidence",
    [
        ([1, 4, 6, 9], "0.75"),  # 16 sign vectors: 16·0.125 = 2, an integer
        ([1, 2, 4, 5, 8], "0.875"),  # 32·0.0625 = 2
        ([1, 2, 4, 5, 8], "0.9"),  # 32·0.05 = 1.6
        ([1, 2, 4, 5, 8], "0.8"),  # 32·0.1 = 3.2
    ],
)
def test_the_paired_permutation_interval_is_the_brute_force_one(d, confidence):
    alpha = 1 - Fraction(confidence)
    denominator = math.lcm(*range(1, len(d) + 1))  # breakpoints: means of subsets
    spread = max(d) - min(d) + 1
    expected = brute_interval(
        lambda s: paired_accepts(d, s, alpha), float(np.mean(d)), spread, denominator
    )
    got = stats.paired_permutation_interval(np.array(d, float), confidence=float(confidence))
    assert (got.low, got.high) == pytest.approx(expected, rel=1e-12, abs=1e-12)
