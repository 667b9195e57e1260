"""One word for what a policy does, from its episode length and forward distance."""

import math

import pytest

from adarl.report import behaviour


@pytest.mark.parametrize(
    "length, distance, word",
    [
        (136.0, 0.4, "falls"),  # ends early, little distance
        (300.0, 4.9, "falls"),  # lunges 4.9 m but in under half the limit
        (949.0, 0.5, "falls"),  # just under 95% of the limit
        (950.0, 0.5, "stands"),  # 95% of the limit counts as full length
        (1000.0, 2.99, "stands"),
        (1000.0, 3.0, "moves"),
        (500.0, 6.5, "moves"),  # half the limit, far: hops then falls late
        (499.0, 6.5, "falls"),
        (1000.0, math.nan, "stands or moves"),  # distance not recorded
        (136.0, math.nan, "falls"),
    ],
)
def test_describe_by_the_documented_thresholds(length, distance, word):
    assert behaviour.describe(length, 1000, distance) == word


def test_the_limit_is_the_runs_own():
    assert behaviour.describe(190.0, 200, 0.1) == "stands"  # a 200-step time limit (smoke)
    assert set(behaviour.MEANING) == set(behaviour.WORDS)
