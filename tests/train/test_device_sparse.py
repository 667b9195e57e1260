"""`--algo sac-sparse --backend device` (the sparsification-layer network on the device learner)
on CPU, tiny (2 seeds, a 16-wide sparse layer, 3 chunks of 10 steps, 2 of them updating): it
updates, logs the actor code's `active_fraction` as the host learner does, and each seed's
policy file computes what its network on the device computes."""

import jax
import numpy as np
import pytest

from adarl.algos import registry, replay, sac
from adarl.device import missing_reason
from adarl.policy import NumpyPolicy

pytestmark = [
    pytest.mark.skipif(missing_reason() is not None, reason=str(missing_reason())),
    pytest.mark.slow,
]

BUDGET = {
    "backend": "device",
    "task": "hopper",
    "dynamics": "default",
    "seeds": (0, 1),
    "sparse_width": 16,
    "total_steps": 30,
    "update_every": 10,
    "start_steps": 10,
    "update_after": 20,
    "log_every": 30,
    "eval_every": 30,
    "checkpoint_every": 30,
    "buffer_size": 100,
    "batch_size": 8,
    "max_episode_steps": 8,
}


def test_sac_sparse_trains_on_the_device_and_its_policy_files_compute_its_network():
    from adarl.train.device_learner import DeviceSACLearner

    config = registry.resolve_config("sac-sparse", "smoke", BUDGET)
    learner = DeviceSACLearner(config)
    assert "active_fraction" in learner.train_columns
    learner.fresh()
    before = jax.device_get(learner.state["actor"])
    assert learner.advance(0).step == 30
    rows = learner.train_rows(30, 1.0)
    assert [r["seed"] for r in rows] == [0, 1]
    after = jax.device_get(learner.state["actor"])
    for i, row in enumerate(rows):
        assert np.isfinite(row["loss_q"]) and 0.0 <= row["active_fraction"] <= 1.0
        # the host learner's diagnostic: the code's non-zero share on a batch drawn with key 0
        state = jax.tree_util.tree_map(lambda a, i=i: a[i], jax.device_get(learner.state))
        obs = replay.sample(state["buffer"], jax.random.PRNGKey(0), config.batch_size)["obs"]
        code = sac.actor_features(learner.spec, state["actor"], state["masks"]["actor"], obs)
        assert row["active_fraction"] == pytest.approx(float(np.mean(np.asarray(code) > 0)))
        d = after["trunk"][1]["d"][i]
        assert d.shape == (16, 16) and not np.array_equal(d, before["trunk"][1]["d"][i])
    obs = np.random.default_rng(0).normal(size=(32, 11)).astype(np.float32)
    for i, policy in enumerate(learner.policies()):
        actor = jax.tree_util.tree_map(lambda a, i=i: a[i], after)
        masks = [
            None if m is None else m[i] for m in jax.device_get(learner.state["masks"]["actor"])
        ]
        mean, _ = sac.actor_forward(learner.spec, actor, masks, obs)
        np.testing.assert_allclose(
            NumpyPolicy(policy)(obs), np.asarray(sac.squash(learner.spec, mean)), atol=1e-5
        )
