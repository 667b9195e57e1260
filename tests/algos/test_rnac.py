"""RNAC's maths (adarl.algos.rnac) against NumPy references, and bad configs (the shared
on-policy parts: tests/algos/test_onpolicy.py; the learner: tests/train/test_rnac_learner.py)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import onpolicy, rnac, rnac_config
from adarl.errors import UsageError

# jitted once: eager JAX compiles every primitive separately, which is slow on 2 shared cores
gae = jax.jit(onpolicy.gae)
ipm_norm = jax.jit(rnac.ipm_norm)


# ----------------------------------------------------------------------------- the maths
def test_ipm_penalty_value():
    critic = onpolicy.init_critic(np.random.default_rng(0), 11, (64, 64))
    critic["out"]["b"] = np.asarray([5.0], np.float32)  # the output bias is not in the norm
    critic["trunk"][0]["b"] = np.full(64, 0.1, np.float32)  # hidden biases are
    squares = sum(
        float(np.sum(np.asarray(x) ** 2)) for layer in critic["trunk"] for x in layer.values()
    )
    squares += float(np.sum(np.asarray(critic["out"]["w"]) ** 2))
    assert float(ipm_norm(critic)) == pytest.approx(np.sqrt(squares), rel=1e-6)
    # the penalty lowers every TD residual by weight_reg·‖θ‖: with no episode end the advantage
    # drops by weight_reg·‖θ‖·Σ_k (γλ)^k, counted to the end of the rollout
    n, gamma, lam, penalty = 50, 0.99, 0.95, 1e-5 * float(ipm_norm(critic))
    zeros = jnp.zeros(n)
    adv, _ = gae(zeros, zeros, zeros, zeros, zeros, gamma, lam, penalty)
    expected = -penalty * np.array(
        [sum((gamma * lam) ** k for k in range(n - t)) for t in range(n)]
    )
    np.testing.assert_allclose(adv, expected, rtol=1e-5)


def test_worst_case_selection_picks_the_lowest_valued_candidate():
    critic = onpolicy.init_critic(np.random.default_rng(1), 11, (64, 64))
    candidates = np.random.default_rng(3).standard_normal((5, 11)).astype(np.float32)
    values = onpolicy.critic_value(critic, candidates, np)
    assert rnac.select_candidate(values, worst=True, random_index=4) == int(np.argmin(values))
    assert values[rnac.select_candidate(values, True, 0)] == values.min()
    assert rnac.select_candidate(values, worst=False, random_index=4) == 4
    np.testing.assert_allclose(
        values, onpolicy.critic_value(critic, jnp.asarray(candidates)), rtol=1e-5
    )
    # the draws: noise within ±noise, the worst case with probability δ, random index uniform
    rng = np.random.default_rng(4)
    draws = [rnac.draw_double_sampling(rng, 3, 2, 5e-3, 0.25) for _ in range(4000)]
    assert all(np.abs(d[0]).max() <= 5e-3 and d[0].shape == (3, 2) for d in draws)
    assert np.mean([d[1] for d in draws]) == pytest.approx(0.25, abs=0.03)
    assert np.bincount([d[2] for d in draws], minlength=3) / 4000 == pytest.approx(
        [1 / 3] * 3, abs=0.04
    )


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "change, words",
    [
        ({"uncertainty_set": "kl"}, "uncertainty set 'kl'"),
        ({"delta": 1.5}, "delta"),
        ({"delta": -0.1}, "delta"),
        ({"n_candidates": 0}, "n-candidates"),
        ({"total_steps": 0}, "total-steps"),
        ({"rollout_steps": 100}, "multiple of minibatch-size"),
        ({"seeds": ()}, "seeds"),
        ({"eval_every": -5}, "eval-every"),
    ],
)
def test_bad_config_raises_one_line_usage_error(change, words):
    config = dataclasses.replace(rnac_config.RNACConfig(), **change)
    with pytest.raises(UsageError, match=words) as err:
        config.validate()
    assert "\n" not in str(err.value)


def test_presets_are_valid_configs():
    from adarl.algos import registry

    assert registry.get("rnac").config_class is rnac_config.RNACConfig
    for name, overrides in rnac_config.PRESETS.items():
        rnac_config.RNACConfig(**overrides).validate(), name
