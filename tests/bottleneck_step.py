"""Test helper shared by tests/algos and tests/nets: AdaRL's rank-adaptation step on one
bottleneck, composed of `adarl.nets.rank`'s pieces as `sac.truncate` composes them."""

import jax.numpy as jnp

from adarl.nets import rank


def truncate_bottleneck(w1, w2, mask, beta: float, rule: str = "cumulative"):
    """One rank-adaptation step on a padded bottleneck (paper appendix, "Basic Settings"): the
    SVD W1·W2 = U Σ Vᵀ, r_new = max(1, min(r_old, r̂)), W1 = U_r √Σ_r, W2 = √Σ_r V_rᵀ. Returns
    `(w1, w2, mask, sigma, proposed_rank)`."""
    u, s, vt = rank.spectrum(w1, w2, mask)
    old_rank = jnp.sum(mask).astype(jnp.int32)
    proposed = rank.select_rank(s, beta, rule)
    new_w1, new_w2, new_mask = rank.reparameterise(
        u, s, vt, rank.next_rank(old_rank, proposed), w1.dtype
    )
    return new_w1, new_w2, new_mask, s, proposed
