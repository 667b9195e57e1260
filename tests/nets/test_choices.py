"""The names the configs accept (`adarl.nets.choices`) are the ones the networks implement."""

import numpy as np

from adarl.nets import choices, mlp, rank


def test_every_activation_has_a_function():
    assert tuple(mlp.ACTIVATION_FUNCTIONS) == choices.ACTIVATIONS


def test_every_rank_rule_selects_a_rank():
    sigma = np.array([3.0, 2.0, 1.0, 0.5], np.float32)
    for rule in choices.RANK_RULES:
        assert 0 <= int(rank.select_rank(sigma, 0.9, rule)) <= len(sigma)
