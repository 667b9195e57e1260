"""Tabular-MDP version of the Theorem 1 experiment."""

import numpy as np
import pytest

from adarl.errors import UsageError
from adarl.theory.mdp import (
    check_params,
    logsumexp,
    make_low_rank_mdp,
    mdp_truth,
    moment_system,
    perturb_kernel,
    run_mdp,
    soft_q_fixed_point,
    stationary_distribution,
)
from adarl.theory.synthetic import best_rank


@pytest.fixture(scope="module")
def truth():
    return mdp_truth(make_low_rank_mdp(8, 2, 2, 10, seed=0))


def test_kernel_is_low_rank_and_lives_on_the_core(truth):
    mdp = truth.mdp
    kernel = mdp.kernel
    np.testing.assert_allclose(kernel.sum(axis=-1), 1.0)
    assert np.linalg.matrix_rank(kernel.reshape(-1, kernel.shape[-1])) <= mdp.n_latent
    assert np.all(kernel[..., mdp.n_core :] == 0)
    np.testing.assert_allclose(np.linalg.norm(mdp.features, axis=-1), 1.0)


def test_soft_q_fixed_point_and_theta0(truth):
    mdp = truth.mdp
    bellman = mdp.reward + mdp.gamma * mdp.kernel @ logsumexp(truth.q)
    np.testing.assert_allclose(truth.q, bellman, atol=1e-9)
    assert truth.r0 == mdp.n_core * mdp.kernel.shape[1]
    assert np.linalg.matrix_rank(truth.a, tol=1e-10) == truth.r0
    # θ° reproduces Q° on the state-action pairs the true dynamics visit
    core_phi = mdp.features[: mdp.n_core].reshape(-1, mdp.features.shape[-1])
    np.testing.assert_allclose(core_phi @ truth.theta, truth.q[: mdp.n_core].ravel(), atol=1e-8)
    np.testing.assert_allclose(truth.a @ truth.theta, truth.b, atol=1e-9)


def test_stationary_distribution_and_perturbation(truth):
    kernel = truth.mdp.kernel
    policy = np.full(kernel.shape[:2], 0.5)
    rho = stationary_distribution(kernel, policy)
    chain = np.einsum("sa,sat->st", policy, kernel)
    np.testing.assert_allclose(rho @ chain, rho, atol=1e-12)
    assert np.all(rho[truth.mdp.n_core :] == 0)
    for eps in (0.0, 0.1, 0.5):
        p = perturb_kernel(kernel, eps, np.random.default_rng(0))
        np.testing.assert_allclose(p.sum(axis=-1), 1.0)
        tv = 0.5 * np.abs(p - kernel).sum(axis=-1)  # = W1 under the discrete metric
        assert np.all(tv <= eps + 1e-12)
    a0, b0 = moment_system(truth.mdp, kernel, truth.v)
    np.testing.assert_allclose(a0, truth.a)
    np.testing.assert_allclose(b0, truth.b)


def test_soft_q_is_the_entropy_regularised_value():
    # one state, one action, self-loop: Q = R + γ Q  ⇒  Q = R / (1 − γ)
    q, v = soft_q_fixed_point(np.ones((1, 1, 1)), np.array([[1.0]]), 0.5)
    assert q[0, 0] == pytest.approx(2.0)
    # two actions with equal reward: V = Q + log 2, Q = R + γ V  ⇒  Q = (R + γ log 2) / (1 − γ)
    q, v = soft_q_fixed_point(np.ones((1, 2, 1)), np.array([[1.0, 1.0]]), 0.5)
    assert q[0, 0] == pytest.approx((1 + 0.5 * np.log(2)) / 0.5)


def test_mdp_tradeoff_and_bound():
    truth, sweeps = run_mdp(eps=(0.0, 0.01, 0.1), draws=20, seed=0)
    zero, small, mid = sweeps
    assert best_rank(zero) == truth.r0
    assert zero.error.mean(0)[truth.r0 - 1] < 1e-9
    for sw in (small, mid):
        err = sw.error.mean(axis=0)
        assert best_rank(sw) == truth.r0
        assert err[truth.r0] > err[truth.r0 - 1] and err[-1] > err[truth.r0 - 1]
    for sw in sweeps:
        # bias term with the measured Picard constant C, realised ‖ε_A‖ in the O(Lε) term
        assert np.all(sw.error <= sw.bound * (1 + 1e-9) + 1e-12)
    assert truth.picard_c > 1  # rewards of order one: Picard holds only with a constant


def test_mdp_bad_parameters():
    with pytest.raises(UsageError, match="n_core"):
        check_params(4, 2, 4, 8)
    with pytest.raises(UsageError, match="feature dimension"):
        check_params(4, 2, 2, 3)
    with pytest.raises(UsageError, match="gamma"):
        check_params(4, 2, 2, 4, gamma=1.0)
    with pytest.raises(UsageError, match="eps"):
        run_mdp(eps=(-0.1,), draws=1)
