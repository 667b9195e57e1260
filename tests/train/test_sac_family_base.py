"""`adarl.train.sac_family`: the one base of the SAC family's host and device learners. What the
loop reads of a learner (train.csv rows, policies, the divergence watch) is built once, from the
per-seed values each backend gives; neither learner builds its own."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

from adarl.algos import registry, sac
from adarl.policy import NumpyPolicy
from adarl.runs import layout
from adarl.train import device_learner, sac_learner
from adarl.train.sac_family import SACFamily

SHARED = ("train_rows", "policies", "parameters_finite", "nonfinite", "check_memory")


@pytest.mark.parametrize("cls", [sac_learner.SACLearner, device_learner.DeviceSACLearner])
def test_both_backends_use_the_one_base(cls):
    assert issubclass(cls, SACFamily)
    for name in SHARED:
        assert getattr(cls, name) is getattr(SACFamily, name), f"{cls.__name__}.{name}"


class FixedValues(SACFamily):
    """A SAC-family learner of two seeds whose per-seed values are given."""

    def __init__(self, means, ranks, finite, returns, **flags):
        config = registry.resolve_config("adarl", None, {"seeds": [4, 9], **flags})
        self.setup(config, 11, 3, -np.ones(3), np.ones(3))
        self.means, self.ranks, self.finite, self.returns = means, ranks, finite, returns

    def take_metric_means(self):
        means, self.means = self.means, None
        return means

    def seed_ranks(self):
        return self.ranks

    def seed_diagnostics(self):
        return {"active_fraction": np.array([0.25, 0.5])}

    def seed_finite(self):
        return self.finite

    def seed_actors(self):
        actors = []
        for seed in self.seeds:
            state = jax.device_get(sac.init_state(self.spec, seed, with_buffer=False))
            actors.append((self.spec, state["actor"], state["masks"]["actor"]))
        return actors

    def episode_returns(self):
        return self.returns


METRICS = {
    "loss_q": np.array([1.0, 2.0]),
    "loss_pi": np.array([-3.0, -4.0]),
    "alpha": np.array([0.1, 0.2]),
    "entropy": np.array([0.5, 0.6]),
    "q_mean": np.array([7.0, 8.0]),
    "lr": np.array([1e-3, 2e-3]),
    "penalty_actor": np.array([0.01, 0.02]),
    "penalty_critic": np.array([0.03, 0.05]),
}
RANKS = {"actor_1": np.array([40, 38]), "q1_1": np.array([50, 52]), "q2_1": np.array([51, 49])}
FINITE = {"actor parameters": np.array([True, True]), "critic parameters": np.array([True, False])}


def test_train_rows_are_each_seeds_metrics_and_ranks():
    learner = FixedValues(dict(METRICS), RANKS, FINITE, np.zeros(2))
    rows = learner.train_rows(500, 123.0)
    assert rows == [
        {"step": 500, "seed": 4, "steps_per_s": 123.0, "loss_q": 1.0, "loss_pi": -3.0,
         "alpha": 0.1, "entropy": 0.5, "q_mean": 7.0, "lr": 1e-3,
         "rank_actor_1": 40, "rank_q1_1": 50, "rank_q2_1": 51},
        {"step": 500, "seed": 9, "steps_per_s": 123.0, "loss_q": 2.0, "loss_pi": -4.0,
         "alpha": 0.2, "entropy": 0.6, "q_mean": 8.0, "lr": 2e-3,
         "rank_actor_1": 38, "rank_q1_1": 52, "rank_q2_1": 49},
    ]  # fmt: skip
    assert set(rows[0]) == set(learner.train_columns)
    assert learner.train_rows(600, 1.0) == []  # no update since: no rows


def test_regulariser_columns_follow_the_config():
    parseval = FixedValues(dict(METRICS), RANKS, FINITE, np.zeros(2), parseval_coef=1e-3)
    rows = parseval.train_rows(500, 1.0)
    assert [r["parseval_penalty"] for r in rows] == pytest.approx([0.04, 0.07])
    assert "parseval_penalty" in parseval.train_columns


def test_nonfinite_names_each_quantity_and_its_seeds():
    means = dict(METRICS) | {"loss_q": np.array([math.nan, 1.0])}
    learner = FixedValues(means, RANKS, FINITE, np.array([0.0, math.inf]))
    assert learner.nonfinite(0) == {"critic parameters": [9], "episode return": [9]}
    learner.train_rows(500, 1.0)  # the watch reads the metrics of the latest rows
    assert learner.nonfinite(500) == {
        "loss_q": [4],
        "critic parameters": [9],
        "episode return": [9],
    }
    assert not learner.parameters_finite()


def test_policies_are_each_seeds_actor_in_seed_order():
    learner = FixedValues(dict(METRICS), RANKS, FINITE, np.zeros(2))
    obs = np.random.default_rng(0).normal(size=(5, 11)).astype(np.float32)
    acts = [NumpyPolicy(p)(obs) for p in learner.policies()]
    for seed, act in zip(learner.seeds, acts):
        state = jax.device_get(sac.init_state(learner.spec, seed, with_buffer=False))
        alone = sac.export_policy(learner.spec, state["actor"], state["masks"]["actor"])
        np.testing.assert_array_equal(act, NumpyPolicy(alone)(obs))
    assert not np.allclose(acts[0], acts[1])  # seed 4's actor, then seed 9's


def test_the_column_names_are_made_and_read_in_one_place():
    assert layout.param_column("torso_length") == "p_torso_length"
    assert layout.rank_column("actor_1") == "rank_actor_1"
    columns = ["step", "p_torso_length", "p_value_x", "rank_actor_1", "return", "rank_q1_1"]
    assert layout.param_columns(columns) == ["p_torso_length", "p_value_x"]
    assert layout.rank_columns(columns) == ["rank_actor_1", "rank_q1_1"]
    assert layout.param_name("p_torso_length") == "torso_length"
    assert layout.rank_layer("rank_q1_1") == "q1_1"
