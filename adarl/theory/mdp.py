"""Tabular version of the Theorem 1 experiment: a random MDP with low-rank transitions, linear
features, and transition kernels resampled from an uncertainty ball of radius ε.

Construction
- Low-rank kernel: ``P°(s'|s,a) = Σ_{k≤K} F_k(s,a) M_k(s')`` with K latent factors; every ``M_k``
  is supported on the first ``n_core`` ("core") states, so rank(P°) ≤ K and, from any (s, a), the
  next state is a core state.
- Behaviour policy uniform; the data distribution is the steady state of (s, a, s') (Assumption 0).
  Under P° it lives on the ``n_core · n_actions`` core pairs, so with generic unit-norm features
  ``φ(s, a) ∈ R^d`` the system ``A_{P°} = E_{P°}[φφᵀ]`` has rank ``r° = n_core · n_actions``.
- Soft-Q fixed point: ``Q° = R + γ P° V°``, ``V°(s) = log Σ_a exp Q°(s, a)`` (the soft Bellman
  operator of the paper, temperature 1). The value head is tabular (``ψ(s)ᵀω° = V°(s)``), so
  ``b_{P,ω°} = E_P[φ(s,a)(R(s,a) + γ V°(s'))]`` with ω° fixed at the ground truth, as in Theorem 1.
- Uncertainty: ``P = (1 − ε) P° + ε N`` with N a fresh Dirichlet(1) kernel for every draw. For every
  (s, a), ``TV(P_{s,a}, P°_{s,a}) ≤ ε`` = the Wasserstein-1 distance for the discrete metric on
  states, so the radius is controlled exactly. The moment matrices move through the stationary
  distribution, so ``‖A_P − A_{P°}‖₂`` is *not* bounded by ε itself; we report the measured ratio.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from adarl.errors import UsageError
from adarl.theory.linalg import (
    RCOND,
    bias_term,
    numerical_rank,
    picard_coefficients,
    picard_constant,
    picard_exponent,
    split_error,
)
from adarl.theory.synthetic import Sweep, collect
from adarl.theory.synthetic import check_params as check_sweep_params


def check_params(n_states: int, n_actions: int, n_core: int, d: int, gamma: float = 0.9) -> None:
    """Raise a one-line ``UsageError`` naming the first bad MDP parameter and what is allowed."""
    for name, value, low in (("n_states", n_states, 2), ("n_actions", n_actions, 1)):
        if not isinstance(value, int | np.integer) or value < low:
            raise UsageError(f"{name} = {value!r} is not allowed; it must be an integer >= {low}")
    if not isinstance(n_core, int | np.integer) or not 1 <= n_core < n_states:
        raise UsageError(
            f"n_core = {n_core!r} is not allowed; need 1 <= n_core < n_states = {n_states}"
        )
    r0, full = n_core * n_actions, n_states * n_actions
    if not isinstance(d, int | np.integer) or not r0 <= d <= full:
        raise UsageError(
            f"feature dimension d = {d!r} is not allowed; need n_core*n_actions = {r0} <= d <= "
            f"n_states*n_actions = {full}"
        )
    if not (isinstance(gamma, int | float) and math.isfinite(gamma) and 0 <= gamma < 1):
        raise UsageError(f"gamma = {gamma!r} is not allowed; the discount must lie in [0, 1)")


@dataclass(frozen=True)
class LowRankMDP:
    """Kernel (S, A, S), reward (S, A), unit-norm features (S, A, d), discount, core size."""

    kernel: np.ndarray
    reward: np.ndarray
    features: np.ndarray
    gamma: float
    n_core: int
    n_latent: int


def make_low_rank_mdp(
    n_states: int = 8,
    n_actions: int = 2,
    n_core: int = 2,
    d: int = 10,
    *,
    n_latent: int | None = None,
    gamma: float = 0.9,
    seed: int = 0,
) -> LowRankMDP:
    """Random MDP with ``P° = F M`` (K = ``n_latent`` factors, default ``n_core``), rewards
    ``U[0, 1]`` and Gaussian features scaled to ``‖φ(s, a)‖ = 1`` (Assumption 2.1)."""
    check_params(n_states, n_actions, n_core, d, gamma)
    k = n_core if n_latent is None else int(n_latent)
    rng = np.random.default_rng([seed, 2])
    mix = rng.dirichlet(np.ones(k), size=(n_states, n_actions))  # F: (S, A, K)
    factors = np.zeros((k, n_states))
    factors[:, :n_core] = rng.dirichlet(np.ones(n_core), size=k)  # M: (K, S), core support
    kernel = mix @ factors
    reward = rng.uniform(0.0, 1.0, (n_states, n_actions))
    feats = rng.standard_normal((n_states, n_actions, d))
    feats /= np.linalg.norm(feats, axis=-1, keepdims=True)
    return LowRankMDP(kernel, reward, feats, float(gamma), int(n_core), k)


def logsumexp(q: np.ndarray) -> np.ndarray:
    """``V(s) = log Σ_a exp Q(s, a)`` over the last axis, computed stably."""
    m = q.max(axis=-1)
    return m + np.log(np.exp(q - m[..., None]).sum(axis=-1))


def soft_q_fixed_point(
    kernel: np.ndarray, reward: np.ndarray, gamma: float, tol: float = 1e-12
) -> tuple[np.ndarray, np.ndarray]:
    """Fixed point of the soft Bellman operator ``BQ = R + γ E_{s'~P}[log Σ_{a'} exp Q(s', a')]``
    (Section 3 of the paper), by value iteration (a γ-contraction); returns ``(Q, V)``."""
    q = np.zeros_like(reward)
    for _ in range(100_000):
        q_new = reward + gamma * kernel @ logsumexp(q)
        if np.max(np.abs(q_new - q)) <= tol * max(1.0, np.max(np.abs(q_new))):
            q = q_new
            break
        q = q_new
    return q, logsumexp(q)


def stationary_distribution(kernel: np.ndarray, policy: np.ndarray) -> np.ndarray:
    """Steady-state distribution ρ of the state chain ``T(s'|s) = Σ_a π(a|s) P(s'|s, a)``:
    ``ρᵀT = ρᵀ``, ``Σρ = 1`` (least squares; tiny negatives from rounding are clipped)."""
    chain = np.einsum("sa,sat->st", policy, kernel)
    n = chain.shape[0]
    lhs = np.vstack([chain.T - np.eye(n), np.ones((1, n))])
    rhs = np.append(np.zeros(n), 1.0)
    rho = np.clip(np.linalg.lstsq(lhs, rhs, rcond=None)[0], 0.0, None)
    rho[rho < 1e-14] = 0.0
    return rho / rho.sum()


def moment_system(
    mdp: LowRankMDP, kernel: np.ndarray, value: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``A_P = E_P[φφᵀ]`` and ``b_{P,ω} = E_P[φ (R + γ ψ(s')ᵀω)]`` (Section 3) under the steady
    state of ``kernel`` with the uniform behaviour policy; ``ψ(s')ᵀω = value[s']``."""
    n_s, n_a, d = mdp.features.shape
    policy = np.full((n_s, n_a), 1.0 / n_a)
    mu = (stationary_distribution(kernel, policy)[:, None] * policy).reshape(-1)
    phi = mdp.features.reshape(-1, d)
    target = (mdp.reward + mdp.gamma * kernel @ value).reshape(-1)
    return (phi.T * mu) @ phi, phi.T @ (mu * target)


def perturb_kernel(kernel: np.ndarray, eps: float, rng: np.random.Generator) -> np.ndarray:
    """``P = (1 − ε) P° + ε N``, N with Dirichlet(1) rows: ``TV(P_{s,a}, P°_{s,a}) ≤ ε``."""
    noise = rng.dirichlet(np.ones(kernel.shape[-1]), size=kernel.shape[:-1])
    return (1 - eps) * kernel + eps * noise


@dataclass(frozen=True)
class MdpTruth:
    """Ground truth of the MDP experiment: Q°, V°, the system (A°, b°), θ° = A°^† b°, its rank r°,
    singular values, Picard coefficients ``|u_iᵀb°|``, the largest exponent ``picard_p`` with which
    Assumption 1 holds as stated (C = 1), and the constant ``picard_c`` = smallest C with
    ``|u_iᵀb°| ≤ C·σ_i^p`` at the chosen exponent ``p``."""

    mdp: LowRankMDP
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    b: np.ndarray
    theta: np.ndarray
    r0: int
    sigma: np.ndarray
    coef: np.ndarray
    picard_p: float
    p: float
    picard_c: float


def mdp_truth(mdp: LowRankMDP, p: float = 2.0, rcond: float = RCOND) -> MdpTruth:
    """Solve the ground-truth MDP: soft-Q fixed point, its linear system and θ° (minimum norm)."""
    q, v = soft_q_fixed_point(mdp.kernel, mdp.reward, mdp.gamma)
    a, b = moment_system(mdp, mdp.kernel, v)
    sigma, coef = picard_coefficients(a, b)
    r0 = numerical_rank(sigma, rcond)
    sigma = np.where(np.arange(sigma.size) < r0, sigma, 0.0)
    theta = np.linalg.pinv(a, rcond=rcond) @ b
    p_hat = picard_exponent(sigma, coef, r0)
    c = picard_constant(sigma, coef, r0, p)
    return MdpTruth(mdp, q, v, a, b, theta, r0, sigma, coef, p_hat, float(p), c)


def run_mdp(
    n_states: int = 8,
    n_actions: int = 2,
    n_core: int = 2,
    d: int = 10,
    eps: tuple[float, ...] = (0.0, 0.01, 0.1, 0.3, 0.5),
    draws: int = 200,
    *,
    p: float = 2.0,
    gamma: float = 0.9,
    seed: int = 0,
    rcond: float = RCOND,
) -> tuple[MdpTruth, list[Sweep]]:
    """Sweep r = 1..d for every ε over ``draws`` resampled kernels (seeded by ``(seed, draw)``).

    The O(Lε) part uses the realised ``‖A_{P°} − A_P‖₂ ‖θ°‖ / σ_{P,r}`` (no a-priori constant is
    known here). Rewards of order 1 make ``|u_iᵀb°|`` of order 1/(1 − γ), so Assumption 1 fails
    with C = 1 for every p > 1; the bias term is the theorem's at exponent ``p`` multiplied by the
    measured Picard constant C (``truth.picard_c``), for which the proof holds verbatim.
    ``Sweep.extra['lipschitz_ratio']`` holds ``‖A_P − A_{P°}‖₂ / ε`` per draw.
    """
    check_params(n_states, n_actions, n_core, d, gamma)
    check_sweep_params(d, 1, p, list(eps), draws)  # p > 1, radii in [0, 1], draws >= 1
    mdp = make_low_rank_mdp(n_states, n_actions, n_core, d, gamma=gamma, seed=seed)
    truth = mdp_truth(mdp, p, rcond)
    bias = bias_term(truth.sigma, truth.r0, p, truth.picard_c)
    sweeps = []
    for e in eps:
        splits, lip, ratio = [], [], []
        for k in range(draws):
            rng = np.random.default_rng([seed, 3, k])
            a_p, b_p = moment_system(truth.mdp, perturb_kernel(truth.mdp.kernel, e, rng), truth.v)
            sp = split_error(a_p, b_p, truth.a, truth.b, truth.theta, rcond)
            splits.append(sp)
            lip.append(sp.pert_term)
            ratio.append(np.linalg.norm(a_p - truth.a, 2) / e if e > 0 else 0.0)
        sw = collect(e, splits, bias, lip)
        sw.extra["lipschitz_ratio"] = np.asarray(ratio)
        sweeps.append(sw)
    return truth, sweeps
