"""The newest checkpoint is always a good one (docs/reliability.md): state that went non-finite
between two logging points (parameters, or the optimisers' moments) stops the run at the next
checkpoint, before it is written. Both trainers; values are poisoned by hand at a known step and
the checkpoints are read back with NumPy."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import rnac_config, sac_config
from adarl.algos.sac_config import SAC_FAMILY
from adarl.errors import Diverged
from adarl.runs import checkpoints
from adarl.train import rnac_learner, sac_learner, trainers


def poison_one(tree, value, seed_position: int = 0):
    """`tree` with one entry of its first floating leaf (seed `seed_position`) set to `value`."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    i = next(k for k, x in enumerate(leaves) if jnp.issubdtype(x.dtype, jnp.floating))
    x = jnp.asarray(leaves[i])
    leaves[i] = x.at[(seed_position,) + (0,) * (x.ndim - 1)].set(value)
    return jax.tree_util.tree_unflatten(treedef, leaves)


def assert_all_finite(checkpoint):
    arrays, _ = checkpoints.load_checkpoint(checkpoint)
    bad = [k for k, a in arrays.items() if a.dtype.kind == "f" and not np.isfinite(a).all()]
    assert not bad, f"{checkpoint.name} holds non-finite {bad[:3]}"


def step_names(run_dir):
    return [p.name for p in checkpoints.checkpoint_dirs(run_dir)]


# ----------------------------------------------------------------------------- SAC family
SAC_POISON = {  # what goes non-finite -> (how, the watch's words)
    "critic": (lambda s: dict(s, critic=poison_one(s["critic"], np.nan)), "critic parameters"),
    "critic_target": (  # the target alone: the critic itself still finite
        lambda s: dict(s, critic_target=poison_one(s["critic_target"], np.nan)),
        "critic target parameters",
    ),
    "actor_mu": (
        lambda s: dict(s, opt_actor=s["opt_actor"]._replace(mu=poison_one(s["opt_actor"].mu, np.inf))),
        "actor optimiser state",
    ),
    "critic_nu": (
        lambda s: dict(s, opt_critic=s["opt_critic"]._replace(nu=poison_one(s["opt_critic"].nu, np.inf))),
        "critic optimiser state",
    ),
    "alpha_mu": (
        lambda s: dict(s, opt_alpha=s["opt_alpha"]._replace(mu=poison_one(s["opt_alpha"].mu, np.inf))),
        "temperature optimiser state",
    ),
}  # fmt: skip


@pytest.mark.parametrize("what", SAC_POISON)
def test_sac_state_gone_non_finite_between_log_points_is_never_checkpointed(
    what, tmp_path, monkeypatch
):
    values = {**SAC_FAMILY["sac"], **sac_config.PRESETS["smoke"], "algo": "sac", "task": "hopper"}
    values.update(seeds=(0, 1), total_steps=400, start_steps=100, update_after=100)
    values.update(log_every=400, eval_every=400, checkpoint_every=100)  # one log point: the end
    config = sac_config.SACConfig(**values)
    poison, words = SAC_POISON[what]
    original = sac_learner.SACLearner.advance

    def then_poison(self, step):
        advance = original(self, step)
        if advance.step == 300:  # after the update of the chunk ending at 300, before its save
            lane = self.lanes[-1]  # seed 1 (one lane per seed)
            assert self.seeds[lane.index] == 1
            lane.state = poison(lane.state)
        return advance

    monkeypatch.setattr(sac_learner.SACLearner, "advance", then_poison)
    run_dir = tmp_path / "run"
    with pytest.raises(Diverged) as err:
        trainers.train(config, run_dir, progress=False)
    message = str(err.value)
    assert "diverged at step 300" in message and f"{words} (seed 1)" in message, message
    assert "last good checkpoint step_000000000200" in message, message
    assert step_names(run_dir) == ["step_000000000100", "step_000000000200"]
    assert_all_finite(checkpoints.checkpoint_dirs(run_dir)[-1])
    assert not (run_dir / "DONE").exists()


# ----------------------------------------------------------------------------- RNAC
# each poisons the first (only) seed of one call of the update: RNAC updates one seed a call
RNAC_POISON = {
    "actor_mu": (
        lambda s: s._replace(actor_opt=(s.actor_opt[0], s.actor_opt[1]._replace(mu=poison_one(s.actor_opt[1].mu, np.inf, 0)))),
        "actor optimiser state",
    ),
    "critic_nu": (
        lambda s: s._replace(critic_opt=(s.critic_opt[0], s.critic_opt[1]._replace(nu=poison_one(s.critic_opt[1].nu, np.inf, 0)))),
        "critic optimiser state",
    ),
    "actor": (lambda s: s._replace(actor=poison_one(s.actor, np.nan, 0)), "actor parameters"),
}  # fmt: skip


@pytest.mark.parametrize("what", RNAC_POISON)
def test_rnac_state_gone_non_finite_between_log_points_is_never_checkpointed(
    what, tmp_path, monkeypatch
):
    config = rnac_config.RNACConfig(
        **{**rnac_config.PRESETS["smoke"], "seeds": (0, 1), "total_steps": 1024, "log_every": 1024}
        | {"checkpoint_every": 256, "eval_every": 1024}
    )
    poison, words = RNAC_POISON[what]
    original = rnac_learner.make_update

    def make_update(*args, **kwargs):
        update, calls = original(*args, **kwargs), []

        def poisoned(state, *rest):
            state, *out = update(state, *rest)
            calls.append(1)
            # the update at step 768 (the third), its call for seed 1 (two calls an update)
            return (poison(state) if len(calls) == 6 else state, *out)

        return poisoned

    monkeypatch.setattr(rnac_learner, "make_update", make_update)
    run_dir = tmp_path / "run"
    with pytest.raises(Diverged) as err:
        trainers.train(config, run_dir, progress=False)
    message = str(err.value)
    assert "diverged at step 768" in message and f"{words} (seed 1)" in message, message
    assert "last good checkpoint step_000000000512" in message, message
    assert step_names(run_dir) == ["step_000000000256", "step_000000000512"]
    assert_all_finite(checkpoints.checkpoint_dirs(run_dir)[-1])
