"""Linear algebra behind Theorem 1 (``theorem:tradeoff`` in the paper): the rank-r truncated-SVD
solution, the discrete Picard condition, and the exact three-way split of the error that the proof
of the theorem (appendix "Proof of Theorem 1") bounds term by term.

Notation follows the paper: ``A_P = U Σ_P Vᵀ`` is the SVD of the (perturbed) system matrix with
singular values in decreasing order, ``A_{P,r}^† = V_r Σ_{P,r}^{-1} U_rᵀ`` its rank-r truncated
pseudo-inverse, ``θ_r = A_{P,r}^† b_P`` and ``θ° = A_{P°}^† b_{P°}``. Every function here is pure
NumPy and deterministic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Singular values at or below ``RCOND · σ_1`` count as zero (same convention as ``np.linalg.pinv``).
RCOND = 1e-10


def numerical_rank(sigma: np.ndarray, rcond: float = RCOND) -> int:
    """Number of singular values strictly above ``rcond · σ_1`` (``np.linalg.pinv``'s cut-off)."""
    sigma = np.asarray(sigma, dtype=float)
    if sigma.size == 0 or sigma[0] <= 0:
        return 0
    return int(np.count_nonzero(sigma > rcond * sigma[0]))


def svd(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``A = U diag(σ) Vᵀ`` with σ decreasing; returns ``(U, σ, V)`` (V, not Vᵀ)."""
    u, s, vt = np.linalg.svd(np.asarray(a, dtype=float))
    return u, s, vt.T


def truncated_pinv(a: np.ndarray, r: int, rcond: float = RCOND) -> np.ndarray:
    """Rank-r truncated pseudo-inverse ``A_r^† = V_r Σ_r^{-1} U_rᵀ`` (proof of Theorem 1).

    Only the ``min(r, rank A)`` leading singular triplets are used, so for ``r ≥ rank A`` this is
    ``np.linalg.pinv(A, rcond)``.
    """
    if r < 0:
        raise ValueError(f"r must be >= 0, got {r}")
    u, s, v = svd(a)
    k = min(int(r), numerical_rank(s, rcond))
    return (v[:, :k] / s[:k]) @ u[:, :k].T


def truncated_solutions(a: np.ndarray, b: np.ndarray, rcond: float = RCOND) -> np.ndarray:
    """All truncated-SVD solutions at once: row ``r-1`` is ``θ_r = A_{r}^† b`` for r = 1..d.

    ``θ_r = Σ_{i ≤ r} v_i (u_iᵀ b) / σ_i`` is a cumulative sum over the singular triplets; beyond
    the numerical rank the solution stays at ``θ_{rank}`` (the theorem assumes ``r ≤ rank A_P``).
    """
    u, s, v = svd(a)
    k = numerical_rank(s, rcond)
    coef = np.zeros(s.shape)
    coef[:k] = (u[:, :k].T @ np.asarray(b, dtype=float)) / s[:k]
    return np.cumsum(v * coef, axis=1).T


@dataclass(frozen=True)
class ErrorSplit:
    """``‖θ_r − θ°‖`` for r = 1..d and the pieces of the proof of Theorem 1, each of shape (d,).

    Exact parts (the proof's identity ``θ_r − θ° = A_{P,r}^†(b_P − b_{P°}) − Σ_{i>r} v_i v_iᵀ θ°
    + A_{P,r}^† ε_A θ°`` with ``ε_A = A_{P°} − A_P``):

    - ``var_part``  = ``‖A_{P,r}^†(b_P − b_{P°})‖``
    - ``bias_part`` = ``‖Σ_{i>r} v_i v_iᵀ θ°‖``
    - ``pert_part`` = ``‖A_{P,r}^† ε_A θ°‖`` (the term the paper writes as ``2·O(Lε)``)

    Computable upper bounds of the variance and perturbation parts:

    - ``var_term``  = ``‖b_P − b_{P°}‖ / σ_{P,r}`` (the theorem's variance term)
    - ``pert_term`` = ``‖ε_A‖₂ ‖θ°‖ / σ_{P,r}``

    ``pred_error`` is ``‖θ_r − θ°‖_{A_{P°}}`` = the RMS error of the fitted Q-values under the
    ground-truth data distribution. ``r_eff = min(r, rank A_P)``: beyond the rank θ_r is constant,
    and every r-dependent quantity is evaluated at ``r_eff``.
    """

    error: np.ndarray
    pred_error: np.ndarray
    var_part: np.ndarray
    bias_part: np.ndarray
    pert_part: np.ndarray
    var_term: np.ndarray
    pert_term: np.ndarray
    sigma_r: np.ndarray
    r_eff: np.ndarray
    rank: int
    thetas: np.ndarray


def split_error(
    a_p: np.ndarray,
    b_p: np.ndarray,
    a0: np.ndarray,
    b0: np.ndarray,
    theta0: np.ndarray,
    rcond: float = RCOND,
) -> ErrorSplit:
    """Error of every truncated solution of ``A_P θ = b_P`` against θ°, split as in the proof.

    The identity behind the split (first display of the appendix proof) needs ``A_{P°} θ° =
    b_{P°}``, i.e. ``b_{P°}`` in the range of ``A_{P°}``; callers construct it that way.
    """
    a_p, b_p, a0, b0, theta0 = (np.asarray(x, dtype=float) for x in (a_p, b_p, a0, b0, theta0))
    d = a_p.shape[0]
    u, s, v = svd(a_p)
    k = numerical_rank(s, rcond)
    r_eff = np.minimum(np.arange(1, d + 1), max(k, 1))
    inv_s = np.zeros(d)
    inv_s[:k] = 1.0 / s[:k]

    thetas = np.cumsum(v * ((u.T @ b_p) * inv_s), axis=1).T  # row r-1 = θ_r
    thetas = thetas[r_eff - 1]
    delta = thetas - theta0
    error = np.linalg.norm(delta, axis=1)
    pred_error = np.sqrt(np.maximum(np.einsum("ri,ij,rj->r", delta, a0, delta), 0.0))

    def cum_norm(coef: np.ndarray) -> np.ndarray:
        # ‖Σ_{i≤r} v_i coef_i‖ = sqrt(Σ_{i≤r} coef_i²) because the v_i are orthonormal.
        return np.sqrt(np.cumsum(coef**2))[r_eff - 1]

    db = b_p - b0
    eps_a = a0 - a_p
    var_part = cum_norm((u.T @ db) * inv_s)
    pert_part = cum_norm((u.T @ (eps_a @ theta0)) * inv_s)
    tail = (v.T @ theta0) ** 2  # bias_part[r] = sqrt(Σ_{i>r} (v_iᵀθ°)²), summed from the end
    tail_sum = np.append(np.cumsum(tail[::-1])[::-1][1:], 0.0)
    bias_part = np.sqrt(tail_sum)[r_eff - 1]

    sigma_r = s[r_eff - 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        var_term = np.where(sigma_r > 0, np.linalg.norm(db) / sigma_r, np.inf)
        pert_term = np.where(
            sigma_r > 0, np.linalg.norm(eps_a, 2) * np.linalg.norm(theta0) / sigma_r, np.inf
        )
    if not np.any(db):
        var_term = np.zeros(d)
    if not np.any(eps_a):
        pert_term = np.zeros(d)
    return ErrorSplit(
        error=error,
        pred_error=pred_error,
        var_part=var_part,
        bias_part=bias_part,
        pert_part=pert_part,
        var_term=var_term,
        pert_term=pert_term,
        sigma_r=sigma_r,
        r_eff=r_eff,
        rank=k,
        thetas=thetas,
    )


def bias_term(sigma0: np.ndarray, r0: int, p: float, scale: float = 1.0) -> np.ndarray:
    """The theorem's bias term ``(d − r)·σ_{P°,r}^{p−1} + (d − r)·r°·σ_{P°,1}^{p−1}`` for r = 1..d.

    ``sigma0`` are the d singular values of ``A_{P°}`` (zero beyond r°, and ``0^{p−1} = 0`` for
    p > 1). ``scale`` is the constant C of a Picard condition ``|u_iᵀb| ≤ C·σ_i^p``: the proof goes
    through unchanged with every bias term multiplied by C (the paper has C = 1).
    """
    sigma0 = np.asarray(sigma0, dtype=float)
    d = sigma0.size
    r = np.arange(1, d + 1)
    return scale * ((d - r) * sigma0 ** (p - 1) + (d - r) * r0 * sigma0[0] ** (p - 1))


def picard_coefficients(a0: np.ndarray, b0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(σ_i, |u_iᵀ b|)`` for i = 1..d: the two sides of the discrete Picard condition."""
    u, s, _ = svd(a0)
    return s, np.abs(u.T @ np.asarray(b0, dtype=float))


def picard_limits(sigma: np.ndarray, r0: int, p: float) -> np.ndarray:
    """Right-hand sides of Assumption 1: ``σ_i^p`` for i ≤ r°, ``σ_{r°}^p`` for i > r°."""
    sigma = np.asarray(sigma, dtype=float)
    return np.concatenate([sigma[:r0] ** p, np.full(sigma.size - r0, sigma[r0 - 1] ** p)])


def picard_constant(sigma: np.ndarray, coef: np.ndarray, r0: int, p: float) -> float:
    """Smallest C with ``|u_iᵀb| ≤ C·(Picard limit)_i`` for all i (C ≤ 1 ⇔ Assumption 1 holds)."""
    limit = picard_limits(sigma, r0, p)
    coef = np.asarray(coef, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(coef > 0, coef / limit, 0.0)
    return float(np.max(ratio))


def satisfies_picard(
    sigma: np.ndarray, coef: np.ndarray, r0: int, p: float, rtol: float = 1e-9
) -> bool:
    """Assumption 1 (discrete Picard condition) with exponent p.

    ``|u_iᵀ b| ≤ σ_i^p`` for i ≤ r° and ``|u_iᵀ b| ≤ σ_{r°}^p`` for i > r°.
    """
    limit = picard_limits(sigma, r0, p)
    return bool(np.all(np.asarray(coef, dtype=float) <= limit * (1 + rtol) + 1e-300))


def picard_exponent(sigma: np.ndarray, coef: np.ndarray, r0: int) -> float:
    """Largest p for which the Picard condition holds (``inf`` if unbounded, ``nan`` if none).

    Each constraint ``c ≤ s^p`` with ``0 < s < 1`` gives ``p ≤ log c / log s``; with ``s > 1`` it
    gives ``p ≥ log c / log s``; ``s = 1`` needs ``c ≤ 1``; ``s = 0`` needs ``c = 0``.
    """
    sigma, coef = np.asarray(sigma, dtype=float), np.asarray(coef, dtype=float)
    s = np.concatenate([sigma[:r0], np.full(sigma.size - r0, sigma[r0 - 1])])
    lo, hi = -np.inf, np.inf
    for si, ci in zip(s, coef):
        if ci == 0:
            continue
        if si <= 0:
            return float("nan")
        if si == 1:
            if ci > 1:
                return float("nan")
            continue
        bound = np.log(ci) / np.log(si)
        if si < 1:
            hi = min(hi, bound)
        else:
            lo = max(lo, bound)
    return float(hi) if hi >= lo else float("nan")
