"""Loss terms added to the SAC losses by the baselines. Pure functions of the parameters."""

from __future__ import annotations

import jax.numpy as jnp

from adarl.nets.mlp import hidden_weights


def parseval_term(w: jnp.ndarray, scale: float) -> jnp.ndarray:
    """‖W Wᵀ − s·I‖²_F for a weight W of shape out×in (Parseval regularisation, Chung et al.).

    We store weights as (in, out) = Wᵀ, so W Wᵀ is `w.T @ w` here.
    """
    gram = w.T @ w
    return jnp.sum((gram - scale * jnp.eye(gram.shape[0], dtype=w.dtype)) ** 2)


def parseval_penalty(
    layers: list[dict], layout: tuple, config, has_output_layer: bool
) -> jnp.ndarray:
    """c · (64/width)² · Σ over hidden (non-output) weights of ‖W Wᵀ − s·I‖²_F; biases and the
    output layer are not regularised (wechu/parseval_reg). `width` is each layer's output size."""
    total = jnp.zeros(())
    for w in hidden_weights(layers, layout, has_output_layer):
        width = w.shape[1]
        total = total + (64.0 / width) ** 2 * parseval_term(w, config.parseval_scale)
    return config.parseval_coef * total
