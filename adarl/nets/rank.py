"""Rank adaptation maths for AdaRL: the rank rules and the SVD truncation of a bottleneck (the
learning-rate schedule after each truncation is `adarl.algos.schedule`). Pure functions in
`jax.numpy` (usable inside `jit` and `vmap`) with the same semantics as the NumPy references in
the tests.

A bottleneck is stored padded to its full width `d`: factors `w1` (in × d) and `w2` (d × out) and
a 0/1 `mask` of length d whose first `rank` entries are 1. The layer computes
`((x @ w1) * mask) @ w2 + b`, so masked components contribute exactly nothing and receive exactly
zero gradient; shapes never change with the rank, so one compiled update serves every rank (and
several seeds with different ranks vmapped into one lane).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from adarl.nets.choices import RANK_RULES


def select_rank_cumulative(sigma: jnp.ndarray, beta: float) -> jnp.ndarray:
    """AdaRL's rule (paper Eq. 5): r̂ = max{ℓ : Σ_{i≤ℓ} σ_i / Σ_{i≤d} σ_i ≤ β}.

    `sigma` holds the singular values in descending order. When even ℓ = 1 exceeds β (one
    dominant value) the set is empty and 0 is returned; `next_rank` then floors it at 1.
    """
    total = jnp.sum(sigma)
    cumulative = jnp.cumsum(sigma) / jnp.where(total > 0, total, 1.0)
    # the cumulative ratio is non-decreasing, so the max ℓ satisfying it is the count satisfying it
    return jnp.sum(cumulative <= beta).astype(jnp.int32)


def select_rank_ratio(sigma: jnp.ndarray, beta: float) -> jnp.ndarray:
    """The ablation rule (paper Eq. 7): r̂ = min{ℓ : σ_ℓ / σ_1 ≤ β}; d when no ℓ qualifies."""
    ratio = sigma / jnp.where(sigma[0] > 0, sigma[0], 1.0)
    hits = ratio <= beta
    first = jnp.argmax(hits)  # index of the first True (0-based)
    return jnp.where(jnp.any(hits), first + 1, sigma.shape[0]).astype(jnp.int32)


def select_rank_energy(sigma: jnp.ndarray, beta: float) -> jnp.ndarray:
    """The energy ("srank") rule: r̂ = min{ℓ : Σ_{i≤ℓ} σ_i / Σ_i σ_i ≥ β} (Kumar et al., 2021).

    Unlike Eq. 5 it has a fixed point: a rank-r spectrum (σ_{r+1} = … = 0) is kept at r exactly
    when Σ_{i<r} σ_i / Σσ < β, i.e. when its smallest non-zero value holds more than 1 − β of
    the mass. Eq. 5 keeps the longest prefix holding at most β, this the shortest holding at least
    β, so the two differ by at most one component. An all-zero spectrum gives d.
    """
    total = jnp.sum(sigma)
    cumulative = jnp.cumsum(sigma) / jnp.where(total > 0, total, 1.0)
    below = jnp.sum(cumulative < beta)  # non-decreasing: the count is the first ℓ reaching β, − 1
    return jnp.minimum(below + 1, sigma.shape[0]).astype(jnp.int32)


def select_rank(sigma: jnp.ndarray, beta: float, rule: str = "cumulative") -> jnp.ndarray:
    """r̂ from a descending spectrum by the named rule: `cumulative` (Eq. 5), `ratio` (Eq. 7),
    `energy` (on σ_i) or `energy-squared` (on σ_i², the form of Trained Rank Pruning)."""
    if rule == "cumulative":
        return select_rank_cumulative(sigma, beta)
    if rule == "ratio":
        return select_rank_ratio(sigma, beta)
    if rule == "energy":
        return select_rank_energy(sigma, beta)
    if rule == "energy-squared":
        return select_rank_energy(sigma**2, beta)
    raise ValueError(f"unknown rank rule {rule!r}; allowed: {', '.join(RANK_RULES)}")


def next_rank(old_rank: jnp.ndarray, proposed: jnp.ndarray) -> jnp.ndarray:
    """The rank never grows and never drops below 1: r_new = max(1, min(r_old, r̂))."""
    return jnp.maximum(1, jnp.minimum(old_rank, proposed)).astype(jnp.int32)


def rank_mask(rank: jnp.ndarray, width: int, dtype=jnp.float32) -> jnp.ndarray:
    """0/1 vector of length `width` with ones in the first `rank` entries."""
    return (jnp.arange(width) < rank).astype(dtype)


def bottleneck_product(w1: jnp.ndarray, w2: jnp.ndarray, mask: jnp.ndarray) -> jnp.ndarray:
    """The effective weight W = W1 · diag(mask) · W2 of a padded bottleneck."""
    return (w1 * mask[None, :]) @ w2


@jax.custom_batching.custom_vmap
def svd(matrix: jnp.ndarray):
    """`jnp.linalg.svd(matrix, full_matrices=False)`, batched under `vmap` as a sequential
    `lax.map` of single-matrix LAPACK calls. jaxlib's batched CPU SVD splits its batch over the
    device's thread pool and waits on it from inside that pool; with one CPU device per core
    (`adarl.runtime`) two such SVDs running at once can deadlock (reproduced with jaxlib 0.10).
    The bottlenecks are small and truncations rare, so the sequential form costs nothing."""
    u, s, vt = jnp.linalg.svd(matrix, full_matrices=False)
    return u, s, vt


@svd.def_vmap
def _svd_vmap(axis_size, in_batched, matrix):
    del axis_size, in_batched
    return jax.lax.map(svd, matrix), (True, True, True)


def spectrum(w1, w2, mask):
    """SVD W1·diag(mask)·W2 = U Σ Vᵀ, cut (or zero-padded) to the bottleneck's width d: a
    bottleneck of width d has rank ≤ d, so only its first d singular values can be non-zero.
    Returns `(u, s, vt)` with `s` descending."""
    width = mask.shape[0]
    u, s, vt = svd(bottleneck_product(w1, w2, mask))
    k = s.shape[0]
    if k >= width:
        return u[:, :width], s[:width], vt[:width, :]
    # width exceeds min(in, out): pad with zero components
    return (
        jnp.pad(u, ((0, 0), (0, width - k))),
        jnp.pad(s, (0, width - k)),
        jnp.pad(vt, ((0, width - k), (0, 0))),
    )


def reparameterise(u, s, vt, new_rank, dtype=jnp.float32):
    """W1 = U_r √Σ_r, W2 = √Σ_r V_rᵀ (the best rank-r approximation, Eckart–Young), components
    past r exactly zero. Returns `(w1, w2, mask)`."""
    mask = rank_mask(new_rank, s.shape[0], dtype)
    root = jnp.sqrt(s) * mask
    return u * root[None, :], root[:, None] * vt, mask


def relative_error(approx: jnp.ndarray, reference: jnp.ndarray) -> jnp.ndarray:
    """‖approx − reference‖ / ‖reference‖ over all entries (0 when both are zero)."""
    num = jnp.linalg.norm((approx - reference).ravel())
    den = jnp.linalg.norm(reference.ravel())
    return jnp.where(den > 0, num / jnp.where(den > 0, den, 1.0), jnp.where(num > 0, jnp.inf, 0.0))


def retain_or_cut(old_rank, candidate, error, tolerance: float | None):
    """The paper's retain clause: "if no lower-rank model with sufficient approximation quality
    can be found, we simply retain the previous rank". The candidate rank is accepted when the
    truncated network's relative output error is at most `tolerance` (a NaN error fails);
    `tolerance=None` turns the test off (always accept)."""
    if tolerance is None:
        return candidate
    return jnp.where(error <= tolerance, candidate, old_rank).astype(jnp.int32)
