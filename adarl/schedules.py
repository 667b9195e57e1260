"""The learning-rate formulas of rank adaptation, written once over an array module (`xp`: NumPy
on the host, `jax.numpy` inside a jitted update): ReLoRA's cosine envelope with a warm-up after
each optimiser reset, and the older per-iteration restart. JAX-free, on the ground floor, so that
`adarl.algos.schedule` (the training timeline, imported without JAX) and `adarl.lowrank` (the
public optax schedules) share one implementation.
"""

from __future__ import annotations

import numpy as np


def restart_learning_rate(
    step_in_iteration,
    base_lr: float,
    warmup_steps: int,
    iteration_steps: int,
    min_ratio: float,
    xp=np,
):
    """Learning rate after an optimiser reset (ReLoRA-style restart, paper appendix).

    Linear warm-up from 0 to `base_lr` over `warmup_steps`, then cosine decay from `base_lr` to
    `min_ratio · base_lr` over the rest of the iteration (`iteration_steps` in all):
        t < w:  lr = base · t / w
        t ≥ w:  lr = base · (m + (1 − m) · ½ (1 + cos(π · min(1, (t − w) / (T − w)))))
    """
    t = xp.asarray(step_in_iteration, xp.float32)
    warm = t / max(warmup_steps, 1)
    decay_len = max(iteration_steps - warmup_steps, 1)
    progress = xp.clip((t - warmup_steps) / decay_len, 0.0, 1.0)
    cosine = min_ratio + (1.0 - min_ratio) * 0.5 * (1.0 + xp.cos(xp.pi * progress))
    return base_lr * xp.where(t < warmup_steps, warm, cosine)


def envelope_learning_rate(
    update,
    iteration_start,
    base_lr: float,
    warmup_steps: int,
    total_updates: int,
    min_ratio: float,
    warm_up,
    xp=np,
):
    """ReLoRA's schedule (its `get_cosine_schedule_with_multiple_warmups`): one cosine envelope
    over the whole run, and after each optimiser reset a linear warm-up that rises to the
    envelope's value at the end of the warm-up:
        env(t) = base · (m + (1 − m) · ½ (1 + cos(π · min(1, t / T))))
        τ = t − t_reset < w (and `warm_up`):  lr = env(t_reset + w) · τ / w;  otherwise lr = env(t)
    `t` counts gradient steps from the start of the run and T is the run's total."""
    t = xp.asarray(update, xp.float32)
    start = xp.asarray(iteration_start, xp.float32)

    def envelope(x):
        progress = xp.clip(x / max(total_updates, 1), 0.0, 1.0)
        return base_lr * (min_ratio + (1.0 - min_ratio) * 0.5 * (1.0 + xp.cos(xp.pi * progress)))

    tau = t - start
    warming = xp.logical_and(warm_up, tau < warmup_steps)
    ramp = envelope(start + warmup_steps) * tau / max(warmup_steps, 1)
    return xp.where(warming, ramp, envelope(t))
