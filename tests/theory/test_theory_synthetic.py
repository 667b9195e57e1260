"""Synthetic check of Theorem 1: construction, ε = 0 optimum at r°, the bound, bad input."""

import numpy as np
import pytest

from adarl.errors import UsageError
from adarl.theory.linalg import picard_coefficients, picard_exponent, satisfies_picard
from adarl.theory.synthetic import (
    best_rank,
    check_params,
    draw_perturbation,
    make_ground_truth,
    run_synthetic,
)

CASES = [(16, 4, 2.0, 0), (8, 3, 1.5, 1), (10, 1, 3.0, 2), (6, 6, 2.0, 3)]


@pytest.mark.parametrize("d, r0, p, seed", CASES)
def test_ground_truth_has_rank_r0_and_satisfies_picard(d, r0, p, seed):
    t = make_ground_truth(d, r0, p, seed=seed)
    sigma, coef = picard_coefficients(t.a, t.b)
    assert np.linalg.matrix_rank(t.a) == r0
    np.testing.assert_allclose(sigma, t.sigma, atol=1e-12)
    assert satisfies_picard(sigma, coef, r0, p)
    assert picard_exponent(sigma, coef, r0) >= p
    # A° is a feature covariance of unit-norm features: symmetric PSD with trace 1
    np.testing.assert_allclose(t.a, t.a.T, atol=1e-14)
    assert np.linalg.eigvalsh(t.a).min() > -1e-12
    assert np.trace(t.a) == pytest.approx(1.0)
    # θ° is the minimum-norm (= rank-r° truncated) solution and b° lies in the range of A°
    np.testing.assert_allclose(t.theta, np.linalg.pinv(t.a, rcond=1e-10) @ t.b, atol=1e-10)
    np.testing.assert_allclose(t.a @ t.theta, t.b, atol=1e-12)


def test_ground_truth_is_seeded():
    a, b = make_ground_truth(8, 3, 2.0, seed=5), make_ground_truth(8, 3, 2.0, seed=5)
    np.testing.assert_array_equal(a.a, b.a)
    np.testing.assert_array_equal(a.theta, b.theta)
    assert not np.allclose(a.a, make_ground_truth(8, 3, 2.0, seed=6).a)


@pytest.mark.parametrize("d, r0, p, seed", CASES)
def test_without_uncertainty_the_error_is_minimised_at_r0(d, r0, p, seed):
    _, (sweep,) = run_synthetic(d, r0, p, eps=(0.0,), draws=2, seed=seed)
    err = sweep.error.mean(axis=0)
    assert best_rank(sweep) == r0
    assert err[r0 - 1] < 1e-12
    assert np.all(err[: r0 - 1] > 1e-6)  # bias below r°
    assert np.all(np.diff(err[:r0]) < 0)


def test_perturbation_radius_is_exact_with_lipschitz_constant_one():
    t = make_ground_truth(12, 3, 2.0, seed=0)
    for k, eps in enumerate([0.0, 0.01, 0.3, 1.0]):
        a_p, _ = draw_perturbation(t, eps, np.random.default_rng(k))
        assert np.linalg.norm(a_p - t.a, 2) <= eps + 1e-12  # ‖A_P − A°‖₂ ≤ L·ε with L = 1
        assert np.linalg.eigvalsh(a_p).min() > -1e-12  # still a covariance


@pytest.mark.parametrize("d, r0, p, seed", CASES)
def test_measured_error_never_exceeds_the_computable_bound(d, r0, p, seed):
    """Bound = ‖b_P − b°‖/σ_{P,r} + (d−r)σ°_r^{p−1} + (d−r)r°σ°_1^{p−1} + L·ε·‖θ°‖/σ_{P,r},
    L = 1 (the O(Lε) term with the constant ‖θ°‖₂/σ_{P,r}), checked draw by draw for every r."""
    _, sweeps = run_synthetic(d, r0, p, eps=(0.0, 0.001, 0.05, 0.3, 1.0), draws=20, seed=seed)
    for sw in sweeps:
        assert np.all(sw.error <= sw.bound * (1 + 1e-9) + 1e-12), sw.eps
        assert np.all(sw.var_part <= sw.var_term * (1 + 1e-9) + 1e-15)
        assert np.all(sw.bias_part <= sw.bias_term * (1 + 1e-9) + 1e-15)
        assert np.all(sw.pert_part <= sw.lipschitz_term * (1 + 1e-9) + 1e-15)


def test_small_uncertainty_gives_the_u_shape():
    _, sweeps = run_synthetic(16, 4, 2.0, eps=(0.01, 0.1), draws=30, seed=0)
    for sw in sweeps:
        err = sw.error.mean(axis=0)
        assert best_rank(sw) == 4
        assert np.all(np.diff(err[:4]) < 0)  # bias side
        assert np.all(np.diff(err[3:]) > 0)  # variance side
        # bias dominates below r°, variance above (the proof's exact parts)
        assert sw.bias_part.mean(0)[0] > sw.var_part.mean(0)[0]
        assert sw.var_part.mean(0)[-1] > sw.bias_part.mean(0)[-1]


@pytest.mark.parametrize(
    "kwargs, needle",
    [
        ({"d": 4, "r0": 5}, "r0 = 5"),
        ({"r0": 0}, "r0 = 0"),
        ({"p": 1.0}, "p = 1.0"),
        ({"p": 0.5}, "p = 0.5"),
        ({"p": float("nan")}, "p = nan"),
        ({"eps": [0.1, -0.01]}, "eps = -0.01"),
        ({"eps": [1.5]}, "eps = 1.5"),
        ({"eps": []}, "eps is empty"),
        ({"draws": 0}, "draws = 0"),
        ({"kappa": 0.5}, "kappa = 0.5"),
    ],
)
def test_bad_parameters_raise_one_line_usage_errors(kwargs, needle):
    params = {"d": 8, "r0": 2, "p": 2.0, "eps": [0.0], "draws": 1, "kappa": 10.0} | kwargs
    with pytest.raises(UsageError) as info:
        check_params(**params)
    assert needle in str(info.value) and "\n" not in str(info.value)
    with pytest.raises(UsageError):
        run_synthetic(**params)
