"""Rank adaptation maths for AdaRL: the rank rules, the SVD truncation of a bottleneck and the
learning-rate schedule after each truncation. Pure functions in `jax.numpy` (usable inside `jit`
and `vmap`) with the same semantics as the NumPy references in the tests.

A bottleneck is stored padded to its full width `d`: factors `w1` (in × d) and `w2` (d × out) and
a 0/1 `mask` of length d whose first `rank` entries are 1. The layer computes
`((x @ w1) * mask) @ w2 + b`, so masked components contribute exactly nothing and receive exactly
zero gradient; shapes never change, so several seeds with different ranks share one compiled
update under `vmap`.
"""

from __future__ import annotations

import jax.numpy as jnp

RANK_RULES = ("cumulative", "ratio")


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


def select_rank(sigma: jnp.ndarray, beta: float, rule: str = "cumulative") -> jnp.ndarray:
    """r̂ from a descending spectrum by the named rule (`cumulative` or `ratio`)."""
    if rule == "cumulative":
        return select_rank_cumulative(sigma, beta)
    if rule == "ratio":
        return select_rank_ratio(sigma, beta)
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


def truncate_bottleneck(w1, w2, mask, beta: float, rule: str = "cumulative"):
    """One rank-adaptation step on a padded bottleneck (paper appendix, "Basic Settings").

    Takes the SVD W1·W2 = U Σ Vᵀ, picks r_new = max(1, min(r_old, r̂)) and re-parameterises
    W1 = U[:, :r] √Σ_r, W2 = √Σ_r V[:r, :]ᵀ, so W1·W2 becomes the best rank-r approximation of
    the old product (Eckart–Young). Components past r are set to exactly zero.

    Returns `(w1_new, w2_new, mask_new, sigma, proposed_rank)`; `sigma` is the full spectrum
    (length min(in, out) ≥ width is not required; it is padded/cut to the bottleneck width).
    """
    width = mask.shape[0]
    product = bottleneck_product(w1, w2, mask)
    u, s, vt = jnp.linalg.svd(product, full_matrices=False)
    k = s.shape[0]
    # a bottleneck of width d has rank ≤ d, so only its first d singular values can be non-zero
    if k >= width:
        u, s, vt = u[:, :width], s[:width], vt[:width, :]
    else:  # width exceeds min(in, out): pad with zero components
        u = jnp.pad(u, ((0, 0), (0, width - k)))
        s = jnp.pad(s, (0, width - k))
        vt = jnp.pad(vt, ((0, width - k), (0, 0)))
    old_rank = jnp.sum(mask).astype(jnp.int32)
    proposed = select_rank(s, beta, rule)
    new_rank = next_rank(old_rank, proposed)
    new_mask = rank_mask(new_rank, width, w1.dtype)
    root = jnp.sqrt(s) * new_mask
    w1_new = u * root[None, :]
    w2_new = root[:, None] * vt
    return w1_new, w2_new, new_mask, s, proposed


def restart_learning_rate(
    step_in_iteration,
    base_lr: float,
    warmup_steps: int,
    iteration_steps: int,
    min_ratio: float,
):
    """Learning rate after an optimiser reset (ReLoRA-style restart, paper appendix).

    Linear warm-up from 0 to `base_lr` over `warmup_steps`, then cosine decay from `base_lr` to
    `min_ratio · base_lr` over the rest of the iteration (`iteration_steps` in all):
        t < w:  lr = base · t / w
        t ≥ w:  lr = base · (m + (1 − m) · ½ (1 + cos(π · min(1, (t − w) / (T − w)))))
    """
    t = jnp.asarray(step_in_iteration, jnp.float32)
    warm = t / max(warmup_steps, 1)
    decay_len = max(iteration_steps - warmup_steps, 1)
    progress = jnp.clip((t - warmup_steps) / decay_len, 0.0, 1.0)
    cosine = min_ratio + (1.0 - min_ratio) * 0.5 * (1.0 + jnp.cos(jnp.pi * progress))
    return base_lr * jnp.where(t < warmup_steps, warm, cosine)
