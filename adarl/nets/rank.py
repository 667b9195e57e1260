"""Rank adaptation maths for AdaRL, as the training code imports it. The one implementation is
the public `adarl.lowrank`; this module re-exports it under the names adarl has always used (the
learning-rate schedule adarl trains with is `adarl.algos.schedule`).

A bottleneck is stored padded to its full width `d`: factors `w1` (in × d) and `w2` (d × out) and
a 0/1 `mask` of length d whose first `rank` entries are 1. The layer computes
`((x @ w1) * mask) @ w2 + b`, so masked components contribute exactly nothing and receive exactly
zero gradient; shapes never change with the rank, so one compiled update serves every rank (and
several seeds with different ranks vmapped into one lane).
"""

from __future__ import annotations

from adarl.lowrank import (  # noqa: F401 - re-exported
    bottleneck_product,
    cut_layer,
    next_rank,
    rank_mask,
    relative_error,
    reparameterise,
    retain_or_cut,
    select_rank,
    select_rank_cumulative,
    select_rank_energy,
    select_rank_ratio,
    spectrum,
    svd,
)
