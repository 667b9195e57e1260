"""Truncated-SVD algebra of Theorem 1 against NumPy, and the proof's error identity."""

import numpy as np
import pytest

from adarl.theory.linalg import (
    RCOND,
    bias_term,
    numerical_rank,
    picard_constant,
    picard_exponent,
    satisfies_picard,
    split_error,
    svd,
    truncated_pinv,
    truncated_solutions,
)


def low_rank(d: int, rank: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.standard_normal((d, rank)) @ rng.standard_normal((rank, d))


@pytest.mark.parametrize("d, rank", [(6, 6), (7, 3), (5, 1)])
def test_truncated_pinv_matches_numpy_pinv_at_or_above_rank(d, rank):
    a = low_rank(d, rank, seed=d + rank)
    expected = np.linalg.pinv(a, rcond=RCOND)
    for r in range(rank, d + 2):
        np.testing.assert_allclose(truncated_pinv(a, r), expected, atol=1e-10)


def test_truncated_pinv_matches_explicit_svd_below_rank():
    a = np.random.default_rng(1).standard_normal((6, 6))
    u, s, vt = np.linalg.svd(a)
    for r in range(0, 7):
        expected = vt[:r].T @ np.diag(1 / s[:r]) @ u[:, :r].T
        np.testing.assert_allclose(truncated_pinv(a, r), expected, atol=1e-12)
        # A_r^† is also NumPy's pinv of the rank-r truncation A_r = U_r Σ_r V_rᵀ
        a_r = u[:, :r] @ np.diag(s[:r]) @ vt[:r]
        np.testing.assert_allclose(
            truncated_pinv(a, r), np.linalg.pinv(a_r, rcond=1e-12), atol=1e-9
        )


def test_truncated_solutions_are_pinv_times_b():
    a = low_rank(7, 4, seed=2)
    b = np.random.default_rng(3).standard_normal(7)
    thetas = truncated_solutions(a, b)
    assert thetas.shape == (7, 7)
    for r in range(1, 8):
        np.testing.assert_allclose(thetas[r - 1], truncated_pinv(a, r) @ b, atol=1e-10)
    assert numerical_rank(np.linalg.svd(a, compute_uv=False)) == 4


def test_split_error_matches_the_proof_identity():
    """θ_r − θ° = A_r^†(b_P − b°) − Σ_{i>r} v_i v_iᵀ θ° + A_r^† (A° − A_P) θ° (appendix proof)."""
    rng = np.random.default_rng(4)
    d = 6
    a0 = low_rank(d, 3, seed=5)
    a0 = a0 @ a0.T
    theta0 = np.linalg.pinv(a0) @ rng.standard_normal(d)
    b0 = a0 @ theta0
    a_p = a0 + 0.05 * rng.standard_normal((d, d))
    b_p = b0 + 0.05 * rng.standard_normal(d)
    sp = split_error(a_p, b_p, a0, b0, theta0)
    _, _, v = svd(a_p)
    for r in range(1, d + 1):
        pinv_r = truncated_pinv(a_p, r)
        var_vec = pinv_r @ (b_p - b0)
        bias_vec = v[:, r:] @ (v[:, r:].T @ theta0)
        pert_vec = pinv_r @ ((a0 - a_p) @ theta0)
        np.testing.assert_allclose(pinv_r @ b_p - theta0, var_vec - bias_vec + pert_vec, atol=1e-10)
        assert sp.error[r - 1] == pytest.approx(np.linalg.norm(pinv_r @ b_p - theta0))
        assert sp.var_part[r - 1] == pytest.approx(np.linalg.norm(var_vec))
        assert sp.bias_part[r - 1] == pytest.approx(np.linalg.norm(bias_vec), abs=1e-12)
        assert sp.pert_part[r - 1] == pytest.approx(np.linalg.norm(pert_vec))
    assert np.all(sp.var_part <= sp.var_term * (1 + 1e-12))
    assert np.all(sp.pert_part <= sp.pert_term * (1 + 1e-12))


def test_bias_term_formula():
    sigma = np.array([0.5, 0.25, 0.0, 0.0])
    # (d − r)·σ_r^{p−1} + (d − r)·r°·σ_1^{p−1} with d = 4, r° = 2, p = 2
    expected = [3 * 0.5 + 3 * 2 * 0.5, 2 * 0.25 + 2 * 2 * 0.5, 1 * 0 + 1 * 2 * 0.5, 0.0]
    np.testing.assert_allclose(bias_term(sigma, 2, 2.0), expected)
    np.testing.assert_allclose(bias_term(sigma, 2, 2.0, scale=3.0), 3 * np.array(expected))


def test_picard_condition_helpers():
    sigma = np.array([0.5, 0.1, 0.0])
    coef = np.array([0.5**3, 0.1**3, 0.0])  # exactly σ_i^3, nothing past r° = 2
    assert satisfies_picard(sigma, coef, 2, 3.0)
    assert satisfies_picard(sigma, coef, 2, 2.0)
    assert not satisfies_picard(sigma, coef, 2, 3.5)
    assert picard_exponent(sigma, coef, 2) == pytest.approx(3.0)
    assert picard_constant(sigma, coef, 2, 3.0) == pytest.approx(1.0)
    assert picard_constant(sigma, 2 * coef, 2, 3.0) == pytest.approx(2.0)
    # a component past r° must stay below σ_{r°}^p
    assert not satisfies_picard(sigma, np.array([0.5**3, 0.1**3, 0.1**2]), 2, 3.0)
