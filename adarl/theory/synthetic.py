"""Synthetic check of Theorem 1: a ground-truth system of rank r° that satisfies the discrete
Picard condition, perturbed systems at uncertainty radius ε, and the error of every rank-r
truncated-SVD solution against the theorem's bound.

Perturbation model (a documented simplification of the paper's Wasserstein ball). The paper's
proof uses the uncertainty only through ``‖A_P − A_{P°}‖ ≤ 2·O(Lε)`` and through ``b_P − b_{P°}``.
We perturb the *data distribution* by mixing, ``P = (1 − ε)·P° + ε·N``, so the moment matrices move
by exactly

    A_P = (1 − ε)·A_{P°} + ε·C,      b_P = (1 − ε)·b_{P°} + ε·c,

where ``C = E_N[φφᵀ]`` and ``c = E_N[φ y]`` are the moments under a random law N. ``P°`` and N are
laws over unit-norm features (``‖φ‖ ≤ 1``, Assumption 2.1), so both second moments are PSD with
trace 1 and ``‖A_P − A_{P°}‖₂ = ε‖C − A_{P°}‖₂ ≤ ε``: the O(Lε) constant is known exactly, with
L = 1. (Mixing is a total-variation ball of radius ε, i.e. the Wasserstein-1 ball for the discrete
metric.) Under N the targets follow another linear model, ``y = φᵀθ_N``, so ``c = C θ_N``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from adarl.errors import UsageError
from adarl.theory.linalg import RCOND, bias_term, split_error

#: Columns of the per-(ε, r) summary (see ``summarise``).
COLUMNS = [
    "eps",
    "r",
    "r_eff",
    "error_mean",
    "error_std",
    "error_max",
    "pred_error_mean",
    "var_part",
    "bias_part",
    "pert_part",
    "sigma_P_r",
    "var_term",
    "bias_term",
    "lipschitz_term",
    "bound",
    "max_error_over_bound",
]


def check_params(
    d: int,
    r0: int,
    p: float,
    eps: list[float] | tuple[float, ...],
    draws: int,
    kappa: float = 10.0,
) -> None:
    """Raise a one-line ``UsageError`` naming the first bad parameter and what is allowed."""
    if not isinstance(d, int | np.integer) or d < 1:
        raise UsageError(f"d = {d!r} is not allowed; d must be an integer >= 1")
    if not isinstance(r0, int | np.integer) or not 1 <= r0 <= d:
        raise UsageError(
            f"r0 = {r0!r} is not allowed; r0 must be an integer with 1 <= r0 <= d = {d}"
        )
    if not (isinstance(p, int | float) and math.isfinite(p) and p > 1):
        raise UsageError(f"p = {p!r} is not allowed; the Picard exponent must be a number > 1")
    if len(eps) == 0:
        raise UsageError("eps is empty; give at least one uncertainty radius in [0, 1]")
    for e in eps:
        if not (isinstance(e, int | float) and math.isfinite(e) and 0 <= e <= 1):
            raise UsageError(f"eps = {e!r} is not allowed; radii must lie in [0, 1]")
    if not isinstance(draws, int | np.integer) or draws < 1:
        raise UsageError(f"draws = {draws!r} is not allowed; draws must be an integer >= 1")
    if not (isinstance(kappa, int | float) and math.isfinite(kappa) and kappa >= 1):
        raise UsageError(f"kappa = {kappa!r} is not allowed; the condition number must be >= 1")


def random_orthogonal(d: int, rng: np.random.Generator) -> np.ndarray:
    """Haar-random d×d orthogonal matrix (QR of a Gaussian matrix with the sign fix)."""
    q, r = np.linalg.qr(rng.standard_normal((d, d)))
    return q * np.sign(np.diag(r))


@dataclass(frozen=True)
class GroundTruth:
    """``A_{P°} = Σ_{i≤r°} σ_i u_i u_iᵀ``, ``b_{P°} = Σ_{i≤r°} c_i u_i`` and ``θ° = A_{P°}^† b_{P°}``.

    ``basis`` holds u_1..u_d as columns (``u_i = v_i``: A° is symmetric PSD); ``sigma`` has the d
    singular values (zero beyond r°); ``coef`` the Picard coefficients ``u_iᵀ b_{P°}``.
    """

    a: np.ndarray
    b: np.ndarray
    theta: np.ndarray
    basis: np.ndarray
    sigma: np.ndarray
    coef: np.ndarray
    r0: int
    p: float


def make_ground_truth(
    d: int, r0: int, p: float, *, kappa: float = 10.0, seed: int = 0
) -> GroundTruth:
    """Ground-truth system of rank r° satisfying the discrete Picard condition (Assumption 1).

    - Spectrum: ``σ_i ∝ κ^{-(i-1)/(r°-1)}`` for i ≤ r° (condition number κ on the range), scaled to
      trace 1, so ``A_{P°}`` is the feature covariance of unit-norm features (φ = u_i with
      probability σ_i); ``σ_i = 0`` for i > r°.
    - Right-hand side: ``u_iᵀ b = ± η_i σ_i^p`` with ``η_i ~ U[1/2, 1]`` for i ≤ r° and 0 beyond, so
      ``|u_iᵀ b| ≤ σ_i^p`` (Picard, with a margin) and ``b`` lies in the range of ``A_{P°}``.
    - Solution: ``θ° = Σ_{i≤r°} v_i (u_iᵀ b)/σ_i`` (minimum-norm = rank-r° truncated solution).
    """
    check_params(d, r0, p, [0.0], 1, kappa)
    rng = np.random.default_rng([seed, 0])
    basis = random_orthogonal(d, rng)
    weights = kappa ** (-np.arange(r0) / max(r0 - 1, 1))
    sigma = np.zeros(d)
    sigma[:r0] = weights / weights.sum()
    coef = np.zeros(d)
    coef[:r0] = rng.choice([-1.0, 1.0], r0) * rng.uniform(0.5, 1.0, r0) * sigma[:r0] ** p
    a = (basis * sigma) @ basis.T
    b = basis @ coef
    theta = basis[:, :r0] @ (coef[:r0] / sigma[:r0])
    return GroundTruth(a=a, b=b, theta=theta, basis=basis, sigma=sigma, coef=coef, r0=r0, p=p)


def draw_perturbation(
    truth: GroundTruth, eps: float, rng: np.random.Generator, *, shift: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """One perturbed system ``(A_P, b_P)`` at radius ε (mixture model of the module docstring).

    N is uniform over ``m = 2d`` random unit-norm feature vectors, so ``C`` is full rank (trace 1),
    and its targets follow ``θ_N = θ° + δ`` with ``‖δ‖ = shift·‖θ°‖`` in a random direction.
    """
    d = truth.a.shape[0]
    feats = rng.standard_normal((2 * d, d))
    feats /= np.linalg.norm(feats, axis=1, keepdims=True)
    c_mat = feats.T @ feats / feats.shape[0]
    delta = rng.standard_normal(d)
    delta *= shift * np.linalg.norm(truth.theta) / np.linalg.norm(delta)
    c_vec = c_mat @ (truth.theta + delta)
    return (1 - eps) * truth.a + eps * c_mat, (1 - eps) * truth.b + eps * c_vec


@dataclass
class Sweep:
    """Per-draw results at one radius ε; every array is (draws, d), column r-1 for rank r."""

    eps: float
    error: np.ndarray
    pred_error: np.ndarray
    var_part: np.ndarray
    bias_part: np.ndarray
    pert_part: np.ndarray
    var_term: np.ndarray
    pert_term: np.ndarray
    lipschitz_term: np.ndarray
    bias_term: np.ndarray
    sigma_r: np.ndarray
    r_eff: np.ndarray
    extra: dict = field(default_factory=dict)

    @property
    def bound(self) -> np.ndarray:
        """Computable bound: variance term + bias term + the known O(Lε) term."""
        return self.var_term + self.bias_term + self.lipschitz_term


def collect(eps: float, splits: list, bias: np.ndarray, lipschitz: list[np.ndarray]) -> Sweep:
    """Stack the ``ErrorSplit`` of each draw into a ``Sweep`` (bias term evaluated at r_eff)."""

    def stack(name: str) -> np.ndarray:
        return np.stack([getattr(s, name) for s in splits])

    r_eff = stack("r_eff")
    return Sweep(
        eps=float(eps),
        error=stack("error"),
        pred_error=stack("pred_error"),
        var_part=stack("var_part"),
        bias_part=stack("bias_part"),
        pert_part=stack("pert_part"),
        var_term=stack("var_term"),
        pert_term=stack("pert_term"),
        lipschitz_term=np.stack(lipschitz),
        bias_term=np.asarray(bias)[r_eff - 1],
        sigma_r=stack("sigma_r"),
        r_eff=r_eff,
    )


def run_synthetic(
    d: int = 16,
    r0: int = 4,
    p: float = 2.0,
    eps: tuple[float, ...] = (0.0, 0.01, 0.1, 0.3, 0.5),
    draws: int = 200,
    *,
    kappa: float = 10.0,
    seed: int = 0,
    shift: float = 1.0,
    lipschitz: float = 1.0,
    rcond: float = RCOND,
) -> tuple[GroundTruth, list[Sweep]]:
    """Sweep r = 1..d for every ε: ``draws`` perturbed systems per ε (seeded by ``(seed, draw)``).

    The O(Lε) term of Theorem 1 is taken as ``L·ε·‖θ°‖₂ / σ_{P,r}`` with ``L = lipschitz`` (1 is
    exact for this construction): it bounds the proof's ``‖A_{P,r}^† ε_A θ°‖`` because
    ``‖ε_A‖₂ ≤ Lε``.
    """
    check_params(d, r0, p, list(eps), draws, kappa)
    truth = make_ground_truth(d, r0, p, kappa=kappa, seed=seed)
    bias = bias_term(truth.sigma, r0, p)
    norm_theta = np.linalg.norm(truth.theta)
    sweeps = []
    for e in eps:
        splits, lip = [], []
        for k in range(draws):
            rng = np.random.default_rng([seed, 1, k])  # same N across ε: only the radius changes
            a_p, b_p = draw_perturbation(truth, e, rng, shift=shift)
            sp = split_error(a_p, b_p, truth.a, truth.b, truth.theta, rcond)
            splits.append(sp)
            lip.append(lipschitz * e * norm_theta / sp.sigma_r)
        sweeps.append(collect(e, splits, bias, lip))
    return truth, sweeps


def summarise(sweeps: list[Sweep]) -> list[dict]:
    """One row per (ε, r): draw means (``error_std``/``error_max`` over draws) and the worst
    ``error / bound`` ratio over draws; columns are ``COLUMNS``."""
    rows = []
    for sw in sweeps:
        d = sw.error.shape[1]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(sw.bound > 0, sw.error / sw.bound, 0.0)
        for j in range(d):
            rows.append(
                {
                    "eps": sw.eps,
                    "r": j + 1,
                    "r_eff": int(sw.r_eff[:, j].max()),
                    "error_mean": sw.error[:, j].mean(),
                    "error_std": sw.error[:, j].std(),
                    "error_max": sw.error[:, j].max(),
                    "pred_error_mean": sw.pred_error[:, j].mean(),
                    "var_part": sw.var_part[:, j].mean(),
                    "bias_part": sw.bias_part[:, j].mean(),
                    "pert_part": sw.pert_part[:, j].mean(),
                    "sigma_P_r": sw.sigma_r[:, j].mean(),
                    "var_term": sw.var_term[:, j].mean(),
                    "bias_term": sw.bias_term[:, j].mean(),
                    "lipschitz_term": sw.lipschitz_term[:, j].mean(),
                    "bound": sw.bound[:, j].mean(),
                    "max_error_over_bound": ratio[:, j].max(),
                }
            )
    return rows


def best_rank(sweep: Sweep, rtol: float = 1e-9) -> int:
    """Smallest r whose mean error is within ``rtol`` (relative to the largest) of the minimum."""
    mean = sweep.error.mean(axis=0)
    tol = rtol * max(mean.max(), 1e-300)
    return int(np.flatnonzero(mean <= mean.min() + tol)[0]) + 1
