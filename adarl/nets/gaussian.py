"""The diagonal Gaussian of both policy families: SAC's pre-squash distribution and RNAC's
action distribution."""

import math

import jax.numpy as jnp


def gaussian_log_prob(x, mean, log_std, xp=jnp):
    """Σ_i log N(x_i; μ_i, σ_i²) over the last axis, σ = exp(log_std); `xp` is jax.numpy or
    NumPy (rollouts)."""
    z = (x - mean) / xp.exp(log_std)
    return xp.sum(-0.5 * z**2 - log_std - 0.5 * xp.log(2 * xp.pi), axis=-1)


def gaussian_entropy(log_std):
    """Entropy of N(μ, diag σ²): Σ_i ½ + ½ log 2π + log σ_i."""
    return jnp.sum(0.5 + 0.5 * math.log(2 * math.pi) + log_std, axis=-1)
