"""`FactorisedDense`: the factorised layer W = W1·W2 (+ b) as a Flax linen module, for agents
whose networks are Flax modules (Stable-Baselines-JAX, Brax, PureJaxRL). Needs `flax`, which
`adarl.lowrank` itself does not.

Its parameters are named as `adarl.lowrank` expects (`w1`, `w2`, `mask`, `b`), so
`adarl.lowrank.truncate` finds and cuts the layer in a Flax parameter tree as in any pytree.
The layer is stored masked by default (`width` ≥ `rank`, the rank in `mask`): a cut keeps every
shape, so a jitted train step and its optimiser keep working. Flax checks a parameter's shape
against the module's, so a compact layer (`width=None`) must be rebuilt with the applied rank
after a cut (`module.clone(rank=r)`).
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

from adarl.lowrank import _count, apply_factorised, rank_mask


class FactorisedDense(nn.Module):
    """x ↦ x·W1·diag(mask)·W2 + b with W1 (n_in × d), W2 (d × features), d = `width` (masked)
    or `rank` (compact), initialised as PyTorch's nn.Linear(n_in, r, bias=False) followed by
    nn.Linear(r, features) (the bottleneck of the paper's appendix). `features` and `rank` are
    integers ≥ 1, `width` -1, None or an integer ≥ `rank`; else a ValueError at the first call
    (as `adarl.lowrank.init_factorised`)."""

    features: int
    rank: int
    width: int | None = -1  # -1: masked at width = rank; None: compact; else masked at width
    use_bias: bool = True
    dtype: jnp.dtype = jnp.float32

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        _count(self.features, "features", 1)
        r = _count(self.rank, "rank", 1)
        d = r if self.width is None or self.width == -1 else _count(self.width, "width", 1)
        if d < r:
            raise ValueError(f"rank {r} exceeds width {d}; allowed: 1 <= rank <= width")
        n_in = x.shape[-1]

        def uniform(bound):
            def init(key, shape, dtype=self.dtype):
                return jax.random.uniform(key, shape, dtype, -bound, bound)

            return init

        keep = rank_mask(r, d, self.dtype)
        w1 = self.param("w1", lambda k, s: uniform(n_in**-0.5)(k, s) * keep[None, :], (n_in, d))
        w2 = self.param(
            "w2", lambda k, s: uniform(r**-0.5)(k, s) * keep[:, None], (d, self.features)
        )
        layer = {"w1": w1, "w2": w2}
        if self.width is not None:
            layer["mask"] = self.param("mask", lambda k, s: keep, (d,))
        if self.use_bias:
            layer["b"] = self.param("b", uniform(r**-0.5), (self.features,))
        return apply_factorised(layer, x)
