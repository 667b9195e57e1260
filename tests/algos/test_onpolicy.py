"""The on-policy parts every such algorithm shares (adarl.algos.onpolicy) against NumPy
references: GAE, PPO's clipped objective, the running normalisers, the host state and the
policy file with the normaliser folded in."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import onpolicy
from adarl.errors import UsageError
from adarl.policy import NumpyPolicy

# jitted once: eager JAX compiles every primitive separately, which is slow on 2 shared cores
gae = jax.jit(onpolicy.gae)


def gae_reference(r, v, v_next, dw, done, gamma, lam, penalty=0.0):
    """The original's loop (ppo_continuous.py, PPO_continuous.update)."""
    deltas = r + gamma * (1.0 - dw) * v_next - v - penalty
    adv, g = [], 0.0
    for delta, d in zip(deltas[::-1], done[::-1]):
        g = delta + gamma * lam * g * (1.0 - d)
        adv.insert(0, g)
    adv = np.array(adv)
    return adv, adv + v


@pytest.mark.parametrize("penalty", [0.0, 0.3])
def test_gae_matches_numpy_reference(penalty):
    rng = np.random.default_rng(0)
    n = 257
    r, v, v_next = (rng.standard_normal(n) for _ in range(3))
    done = (rng.random(n) < 0.05).astype(float)
    dw = done * (rng.random(n) < 0.5)  # some ends are truncations: bootstrap through them
    adv, targets = gae(
        *(jnp.asarray(x, jnp.float32) for x in (r, v, v_next, dw, done)), 0.99, 0.95, penalty
    )
    ref_adv, ref_targets = gae_reference(r, v, v_next, dw, done, 0.99, 0.95, penalty)
    np.testing.assert_allclose(adv, ref_adv, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(targets, ref_targets, rtol=1e-5, atol=1e-5)


def test_clipped_objective_matches_numpy_reference():
    rng = np.random.default_rng(1)
    logp_old = rng.standard_normal(500)
    logp_new = logp_old + 0.3 * rng.standard_normal(500)
    adv = rng.standard_normal(500)
    ratio = np.exp(logp_new - logp_old)
    ref = np.minimum(ratio * adv, np.clip(ratio, 0.8, 1.2) * adv)
    got = onpolicy.ppo_clip_objective(
        jnp.asarray(logp_new), jnp.asarray(logp_old), jnp.asarray(adv), 0.2
    )
    np.testing.assert_allclose(got, ref, rtol=1e-5)
    # where the ratio has left [1-ε, 1+ε] in the direction the advantage favours, no gradient
    grad = jax.grad(lambda lp: jnp.sum(onpolicy.ppo_clip_objective(lp, logp_old, adv, 0.2)))(
        logp_new
    )
    frozen = ((adv > 0) & (ratio > 1.2)) | ((adv < 0) & (ratio < 0.8))
    assert frozen.any() and np.all(np.asarray(grad)[frozen] == 0)
    np.testing.assert_allclose(np.asarray(grad)[~frozen], (ratio * adv)[~frozen], rtol=1e-5)


# ----------------------------------------------------------------------------- normalisers
def test_welford_gives_numpy_mean_and_population_variance():
    x = np.random.default_rng(2).normal(3.0, 2.0, size=(200, 5))
    count, mean, m2 = 0, np.zeros(5), np.zeros(5)
    for row in x:
        count, mean, m2 = onpolicy.welford(count, mean, m2, row)
    assert count == 200
    np.testing.assert_allclose(mean, x.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(m2 / count, x.var(axis=0), rtol=1e-10)


class Settings:
    obs_norm, obs_clip, reward_scaling, gamma = True, 2.0, True, 0.9


def test_host_normalises_observations_and_scales_rewards():
    """Observations by the running mean and variance of every one seen so far, clipped; rewards
    by the running standard deviation of the discounted return R ← γR + r (reset at an
    episode's end), the first reward unscaled."""
    rng = np.random.default_rng(3)
    obs = rng.normal(1.0, 3.0, size=(12, 4))
    rewards = rng.normal(size=12)
    ends = {4, 9}  # the episode ends after these steps
    host = onpolicy.Host.zeros(2, 4, 1, 12, 3)
    host.obs_norm[1] = host.observe(1, obs[0], Settings)
    returns, r_acc = [], 0.0
    for k in range(1, 12):
        done = k in ends
        host.record(1, k, [0.5], -1.0, obs[k], rewards[k], done, False, Settings)
        seen = obs[: k + 1]
        expected = np.clip((obs[k] - seen.mean(0)) / np.sqrt(seen.var(0) + 1e-8), -2.0, 2.0)
        np.testing.assert_allclose(host.buf_next_obs[1, k], expected, rtol=1e-5, atol=1e-6)
        r_acc = 0.9 * r_acc + rewards[k]
        returns.append(r_acc)
        scale = 1.0 if k == 1 else np.std(returns) + 1e-8
        assert host.buf_rewards[1, k] == pytest.approx(rewards[k] / scale, rel=1e-6)
        assert host.buf_terminated[1, k] == host.buf_done[1, k] == float(done)
        if done:
            assert host.ep_length[1] == (4 if k == 4 else 5)
            host.end_episode(1)
            r_acc = 0.0
    assert host.ep_return[1] == pytest.approx(rewards[10:].sum())
    assert host.ep_length[1] == 2
    assert not host.buf_rewards[0].any() and host.obs_count[0] == 0  # the other seed untouched
    np.testing.assert_array_equal(host.buf_obs[1, 2:], host.buf_next_obs[1, 1:-1])


def test_host_checkpoint_arrays_round_trip_and_refuse_another_shape():
    host = onpolicy.Host.zeros(2, 3, 1, 4, 2)
    host.buf_obs[1, 2] = [1.0, 2.0, 3.0]
    host.metrics[:] = 7.0
    again = onpolicy.Host.zeros(2, 3, 1, 4, 2)
    again.load(host.arrays())
    for key, value in host.arrays().items():
        np.testing.assert_array_equal(again.arrays()[key], value)
    with pytest.raises(UsageError, match="host/buf_obs does not match"):
        onpolicy.Host.zeros(2, 3, 1, 8, 2).load(host.arrays())


def test_policy_file_folds_the_normaliser_into_the_actor():
    rng = np.random.default_rng(4)
    actor = onpolicy.init_actor(rng, 4, 2, (8, 8), 0.0)
    actor["mean"]["w"] = rng.standard_normal((8, 2)).astype(np.float32)
    host = onpolicy.Host.zeros(1, 4, 2, 3, 1)
    for o in rng.normal(2.0, 3.0, size=(50, 4)):
        host.observe(0, o, Settings)
    low, high = np.array([-1.0, 0.0]), np.array([1.0, 4.0])
    policy = NumpyPolicy(host.policy(0, actor, Settings, low, high))
    obs = rng.normal(2.0, 3.0, size=(6, 4))
    x = np.clip((obs - host.obs_mean[0]) / np.sqrt(host.obs_m2[0] / 50 + 1e-8), -2.0, 2.0)
    for layer in actor["trunk"]:
        x = np.tanh(x @ layer["w"] + layer["b"])
    z = x @ actor["mean"]["w"] + actor["mean"]["b"]
    np.testing.assert_allclose(policy(obs), (low + high) / 2 + (high - low) / 2 * np.tanh(z),
                               rtol=1e-5, atol=1e-6)  # fmt: skip
    plain = NumpyPolicy(onpolicy.policy_arrays(actor, low, high))
    assert "obs_mean" not in plain.arrays
