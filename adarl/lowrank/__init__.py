"""Rank adaptation for any JAX network (AdaRL, arXiv 2510.11899): a factorised layer
W = W1·W2, its SVD truncation with AdaRL's rank rules, and the learning-rate schedule that
restarts after each cut. JAX and optax only; no adarl run machinery. docs/lowrank.md shows it
in a pure-JAX training step and inside Stable-Baselines-JAX.

A factorised layer is any dict in a parameter pytree holding 2-D arrays `w1` (n_in × r) and
`w2` (r × n_out), with an optional bias `b` (n_out,). It computes `x @ w1 @ w2 + b`: a linear
bottleneck, no bias or activation between the factors (paper appendix, Fig. 7). Two storage
forms, both handled by `truncate`:

* **compact**: no `mask`; r is the layer's rank and a cut changes the shapes (so the caller
  re-jits after it, and the optimiser state is rebuilt at the new shapes).
* **masked** (fixed shape, for code that must keep one shape under `jit`/`vmap`): the dict also
  holds `mask`, a 0/1 vector of length d (the stored width) whose first `rank` entries are 1;
  the layer computes `((x @ w1) * mask) @ w2 + b`, so masked components contribute exactly nothing
  and get exactly zero gradient (the mask itself is read through `stop_gradient`). Shapes never
  change with the rank. The mask lives in the parameters, so an optimiser that changes
  parameters without a gradient, such as weight decay (`optax.adamw`), shrinks it (1 → 0.99…):
  pass `mask=weight_decay_mask` to it (`optax.adamw(lr, weight_decay=…,
  mask=lowrank.weight_decay_mask)`); `truncate` refuses a mask that is not 0/1.

Inputs (issue 55): arguments that are Python values or concrete arrays are checked and a bad one
is a `ValueError` naming it and what is allowed (a rank of 0 or past the width, β outside (0, 1]
or NaN, a negative or NaN retain tolerance, a mask that is not a 0/1 prefix, a 2-D spectrum,
`cut_every` < 1, a non-finite layer given to `truncate`). Under `jit`, shapes and static
arguments are checked at trace time; traced values cannot raise, and behave as documented:
a layer whose W1·diag(mask)·W2 is not finite is left exactly as it was (rank, factors and mask;
its record's spectrum and error are NaN) and its SVD is never computed (jaxlib's SVD of a matrix
holding `inf` does not return); a traced β outside (0, 1] or NaN cuts nothing; a traced NaN or
negative tolerance keeps every old rank (`error <= tolerance` fails).

The per-layer cut (`cut_layer`) is what adarl's own SAC runs (`adarl.algos.sac.truncate`).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import optax

from adarl import schedules

RANK_RULES = ("cumulative", "ratio", "energy", "energy-squared")
#: adarl's defaults (`adarl train`: --rank-rule energy --beta 0.98), also `truncate`'s and
#: `cut_layer`'s
DEFAULT_RULE, DEFAULT_BETA = "energy", 0.98

# ============================================================================ input checks


def _concrete(value) -> bool:
    """A Python value or a concrete array (not a tracer under `jit`/`vmap`/`grad`)."""
    return not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(value))


def _scalar(value, name: str) -> float | None:
    """`value` as a float when it is a concrete scalar, None when traced; a ValueError if it
    is neither a number nor a scalar array."""
    if isinstance(value, bool):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if isinstance(value, numbers.Real):
        return float(value)
    if not _concrete(value):
        if jnp.ndim(value) != 0:
            raise ValueError(f"{name} must be a scalar, got shape {jnp.shape(value)}")
        return None
    try:
        array = jnp.asarray(value)
    except TypeError:
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if array.ndim != 0 or not jnp.issubdtype(array.dtype, jnp.number):
        raise ValueError(f"{name} must be a number, got {value!r}")
    return float(array)


def check_beta(beta) -> bool:
    """A ValueError unless a concrete `beta` is a number in (0, 1]; False when it is traced
    (unchecked: `cut_layer` then cuts nothing for a β outside (0, 1])."""
    value = _scalar(beta, "beta")
    if value is None:
        return False
    if not (0.0 < value <= 1.0):  # NaN fails too
        raise ValueError(f"beta must be a number in (0, 1], got {value!r}")
    return True


def check_tolerance(tolerance) -> None:
    """A ValueError unless `tolerance` is None (the retain clause off) or a concrete number
    ≥ 0 and finite; a traced one is unchecked (a NaN or negative one keeps every old rank)."""
    if tolerance is None:
        return
    value = _scalar(tolerance, "retain_tolerance")
    if value is not None and not (math.isfinite(value) and value >= 0.0):
        raise ValueError(
            f"retain_tolerance must be None (off) or a finite number >= 0, got {value!r}"
        )


def check_rule(rule) -> None:
    if rule not in RANK_RULES:
        raise ValueError(f"unknown rank rule {rule!r}; allowed: {', '.join(RANK_RULES)}")


def _count(value, name: str, least: int) -> int:
    """`value` as an int ≥ `least` (a Python or NumPy integer, not a bool); else a ValueError."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < least:
        raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")
    return int(value)


def check_mask(mask, where: str = "mask") -> None:
    """A ValueError unless a concrete `mask` (one per layer of a stack on its last axis) is
    0/1 with its ones first, as `rank_mask` builds it; a traced one is unchecked (read as its
    sum). A mask that weight decay shrank is the usual cause (see `weight_decay_mask`)."""
    if not _concrete(mask):
        return
    m = jnp.asarray(mask)
    if m.ndim < 1:
        raise ValueError(f"{where} must be a vector of 0/1 entries, got shape {m.shape}")
    expected = rank_mask(m.sum(axis=-1, keepdims=True), m.shape[-1], m.dtype)
    wrong = m != expected
    if bool(jnp.any(wrong)):
        example = float(m[wrong][0])
        raise ValueError(
            f"{where} is not a 0/1 mask with its ones first (it holds {example!r} where "
            "rank_mask(rank, width) would not); did weight decay shrink it? pass "
            "mask=lowrank.weight_decay_mask to the optimiser"
        )


# ============================================================================ rank rules


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
    `energy` (on σ_i) or `energy-squared` (on σ_i², the form of Trained Rank Pruning). `sigma`
    must be 1-D (vmap for several) and a concrete `beta` in (0, 1] (`check_beta`)."""
    check_rule(rule)
    if jnp.ndim(sigma) != 1:
        raise ValueError(
            f"sigma must be a 1-D spectrum, got shape {jnp.shape(sigma)} (vmap select_rank over "
            "a stack of spectra)"
        )
    check_beta(beta)
    if _concrete(sigma) and not bool(
        jnp.all(jnp.isfinite(sigma)) & jnp.all(jnp.asarray(sigma) >= 0)
    ):
        raise ValueError(
            f"sigma must be a spectrum of finite, non-negative singular values, got {sigma!r} "
            "(a diverged layer's SVD?)"
        )
    if rule == "cumulative":
        return select_rank_cumulative(sigma, beta)
    if rule == "ratio":
        return select_rank_ratio(sigma, beta)
    if rule == "energy":
        return select_rank_energy(sigma, beta)
    return select_rank_energy(sigma**2, beta)  # energy-squared


def next_rank(old_rank: jnp.ndarray, proposed: jnp.ndarray) -> jnp.ndarray:
    """The rank never grows and never drops below 1: r_new = max(1, min(r_old, r̂))."""
    return jnp.maximum(1, jnp.minimum(old_rank, proposed)).astype(jnp.int32)


# ============================================================================ the layer


def rank_mask(rank: jnp.ndarray, width: int, dtype=jnp.float32) -> jnp.ndarray:
    """0/1 vector of length `width` with ones in the first `rank` entries."""
    return (jnp.arange(width) < rank).astype(dtype)


def bottleneck_product(w1: jnp.ndarray, w2: jnp.ndarray, mask: jnp.ndarray) -> jnp.ndarray:
    """The effective weight W = W1 · diag(mask) · W2 of a padded bottleneck."""
    return (w1 * mask[None, :]) @ w2


def init_factorised(
    key: jax.Array,
    n_in: int,
    n_out: int,
    rank: int,
    *,
    width: int | None = None,
    bias: bool = True,
    dtype=jnp.float32,
) -> dict[str, jax.Array]:
    """A factorised layer of rank `rank` as PyTorch builds the bottleneck the paper trains:
    nn.Linear(n_in, r, bias=False) then nn.Linear(r, n_out), i.e. W1 ~ U(±1/√n_in) and W2, b ~
    U(±1/√r). With `width` (≥ rank) it is stored masked, `width` wide, components past `rank`
    exactly zero; else compact (r wide, no mask). The masked layer is the compact one of the
    same key padded with zeros (the same function). `n_in`, `n_out` and `rank` are integers
    ≥ 1, `width` None or an integer ≥ `rank`; else a ValueError."""
    n_in, n_out = _count(n_in, "n_in", 1), _count(n_out, "n_out", 1)
    rank = _count(rank, "rank", 1)
    if width is not None and _count(width, "width", 1) < rank:
        raise ValueError(f"rank {rank} exceeds width {width}; allowed: 1 <= rank <= width")
    k1, k2, k3 = jax.random.split(key, 3)
    w1 = jax.random.uniform(k1, (n_in, rank), dtype, -1.0, 1.0) / jnp.sqrt(n_in).astype(dtype)
    bound = 1.0 / jnp.sqrt(rank).astype(dtype)
    w2 = jax.random.uniform(k2, (rank, n_out), dtype, -1.0, 1.0) * bound
    layer = {"w1": w1, "w2": w2}
    if width is not None:
        pad = int(width) - rank
        layer = {
            "w1": jnp.pad(w1, ((0, 0), (0, pad))),
            "w2": jnp.pad(w2, ((0, pad), (0, 0))),
            "mask": rank_mask(rank, int(width), dtype),
        }
    if bias:
        layer["b"] = jax.random.uniform(k3, (n_out,), dtype, -1.0, 1.0) * bound
    return layer


def apply_factorised(layer: dict, x: jnp.ndarray) -> jnp.ndarray:
    """x · W1 · diag(mask) · W2 + b (no mask: all components; no `b`: no bias)."""
    h = x @ layer["w1"]
    if "mask" in layer:
        h = h * jax.lax.stop_gradient(layer["mask"])
    out = h @ layer["w2"]
    return out + layer["b"] if "b" in layer else out


def is_factorised(node: Any) -> bool:
    """True for a dict holding `w1` and `w2` of 2 dimensions (a factorised layer) or 3 (a stack
    of them on axis 0, e.g. twin critics under `vmap` or Flax's `nn.vmap`)."""
    return (
        isinstance(node, dict)
        and "w1" in node
        and "w2" in node
        and getattr(node["w1"], "ndim", 0) in (2, 3)
        and getattr(node["w2"], "ndim", 0) == getattr(node["w1"], "ndim", 0)
    )


def layer_rank(layer: dict) -> jax.Array:
    """The rank of a factorised layer (one per layer of a stack): its mask's sum, or W1's width
    when compact. A concrete mask that is not 0/1 with its ones first is a ValueError
    (`check_mask`)."""
    if "mask" in layer:
        check_mask(layer["mask"])
        return layer["mask"].sum(axis=-1).astype(jnp.int32)
    return jnp.full(layer["w1"].shape[:-2], layer["w1"].shape[-1], jnp.int32)


def factorised_layers(params: Any) -> dict[str, dict]:
    """Every factorised layer of a pytree, keyed by its path (`jax.tree_util.keystr`)."""
    found = {}

    def visit(path, node):
        if is_factorised(node):
            found[jax.tree_util.keystr(path)] = node
        return node

    jax.tree_util.tree_map_with_path(visit, params, is_leaf=is_factorised)
    return found


# ============================================================================ the cut


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
    Returns `(u, s, vt)` with `s` descending. A product holding `inf` or NaN is never
    decomposed (jaxlib's SVD of a matrix holding `inf` does not return): the SVD runs on zeros
    and `s` is NaN (`cut_layer` then leaves the layer as it was). A finite product is
    decomposed exactly as it is."""
    width = mask.shape[0]
    product = bottleneck_product(w1, w2, mask)
    finite = jnp.all(jnp.isfinite(product))
    u, s, vt = svd(jnp.where(finite, product, jnp.zeros_like(product)))
    s = jnp.where(finite, s, jnp.nan)
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
    """W1 = U_r √Σ_r, W2 = √Σ_r V_rᵀ (paper Sec. 4, the best rank-r approximation by
    Eckart–Young), components past r exactly zero. Returns `(w1, w2, mask)`."""
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


class LayerRecord(NamedTuple):
    """What one layer's cut found (arrays; per network when the layer is stacked)."""

    old_rank: jax.Array  #: the rank before the cut
    proposed: jax.Array  #: the rule's r̂ (may be 0 or exceed the old rank)
    candidate: jax.Array  #: r_c = max(1, min(r_old, r̂)) (the rank if the retain clause accepts)
    applied: jax.Array  #: the rank after the cut
    error: jax.Array  #: relative output (or weight) error of the candidate
    spectrum: jax.Array  #: singular values of W1·diag(mask)·W2, descending, d of them


def weight_error(w1, w2, mask, reference_w1, reference_w2, reference_mask) -> jax.Array:
    """Relative error ‖W_c − W‖_F / ‖W‖_F of a candidate layer against the layer it replaces."""
    return relative_error(
        bottleneck_product(w1, w2, mask),
        bottleneck_product(reference_w1, reference_w2, reference_mask),
    )


def cut_layer(
    w1: jax.Array,
    w2: jax.Array,
    mask: jax.Array,
    *,
    rule: str = DEFAULT_RULE,
    beta: float = DEFAULT_BETA,
    retain_tolerance: float | None = None,
    error_fn: Callable[[jax.Array, jax.Array, jax.Array], jax.Array] | None = None,
    apply_cuts: bool = True,
    batched: bool = False,
) -> tuple[jax.Array, jax.Array, jax.Array, LayerRecord]:
    """One layer's cut, fixed shape (AdaRL, paper Sec. 4): the SVD of W1·diag(mask)·W2, the
    rule's r̂ (`select_rank`), the candidate r_c = max(1, min(r_old, r̂)), the retain clause
    (`retain_or_cut`) on `error_fn(w1_c, w2_c, mask_c)` (default: the relative change of the
    layer's weight), and the re-parameterisation W1 = U_r√Σ_r, W2 = √Σ_r V_rᵀ at the chosen rank.
    `apply_cuts=False` is AdaRL's control: the same SVD basis, the old rank kept. `batched`:
    the arrays stack several layers on axis 0 (e.g. twin critics), each cut on its own, and
    `error_fn` returns one error per layer. Returns `(w1, w2, mask, record)`; jit- and
    vmap-safe. Defaults are adarl's (`energy`, β 0.98).

    Inputs: shapes, `rule`, and a concrete `beta` (in (0, 1]) and `retain_tolerance` (None or
    ≥ 0) are checked (ValueError). Concrete arrays whose product W1·diag(mask)·W2 is not finite
    are a ValueError, as is a concrete mask that is not 0/1 with its ones first. Traced (under
    `jit`): a layer whose product is not finite is returned exactly as it was (record: old
    rank throughout, NaN spectrum and error) and is never decomposed; a traced β outside
    (0, 1] or NaN proposes the full width (nothing is cut)."""
    check_rule(rule)
    _check_shapes(w1, w2, mask, batched)
    beta_checked = check_beta(beta)
    check_tolerance(retain_tolerance)
    check_mask(mask)
    each = jax.vmap if batched else (lambda f: f)
    finite = each(product_finite)(w1, w2, mask)
    if _concrete((w1, w2, mask)) and not bool(jnp.all(finite)):
        raise ValueError(
            "the layer's W1·diag(mask)·W2 holds inf or NaN (diverged weights?); allowed: finite "
            "factors (the SVD of a non-finite matrix is undefined)"
        )
    old = mask.sum(axis=-1).astype(jnp.int32)
    u, s, vt = each(spectrum)(w1, w2, mask)
    proposed = each(lambda x: select_rank(x, beta, rule))(s)
    if not beta_checked:  # traced: an invalid β proposes the full width, so nothing is cut
        valid = jnp.logical_and(beta > 0, beta <= 1)
        proposed = jnp.where(valid, proposed, mask.shape[-1]).astype(jnp.int32)
    candidate = next_rank(old, proposed)
    reparam = each(lambda u_, s_, vt_, r_: reparameterise(u_, s_, vt_, r_, dtype=w1.dtype))
    new_w1, new_w2, new_mask = reparam(u, s, vt, candidate)
    if error_fn is None:
        error = each(weight_error)(new_w1, new_w2, new_mask, w1, w2, mask)
    else:
        error = error_fn(new_w1, new_w2, new_mask)
    new = retain_or_cut(old, candidate, error, retain_tolerance)
    if not apply_cuts:  # the control: the proposal is recorded, the old rank kept
        new = old
    if retain_tolerance is not None or not apply_cuts:  # else the candidate's, as before
        new_w1, new_w2, new_mask = reparam(u, s, vt, new)
    # a non-finite layer (only traced ones get here) comes back as it was; finite ones exactly
    # as computed (`where` selects, it does not compute)
    new_w1 = jnp.where(finite[..., None, None], new_w1, w1)
    new_w2 = jnp.where(finite[..., None, None], new_w2, w2)
    new_mask = jnp.where(finite[..., None], new_mask, mask)
    proposed, candidate = jnp.where(finite, proposed, old), jnp.where(finite, candidate, old)
    error = jnp.where(finite, error, jnp.nan)
    applied = new_mask.sum(axis=-1).astype(jnp.int32)
    record = LayerRecord(old, proposed, candidate, applied, error, s)
    return new_w1, new_w2, new_mask, record


def product_finite(w1, w2, mask) -> jax.Array:
    """True when every entry of W1·diag(mask)·W2 is finite (the SVD's input; the factors can be
    finite and their product overflow)."""
    return jnp.all(jnp.isfinite(bottleneck_product(w1, w2, mask)))


def _check_shapes(w1, w2, mask, batched: bool) -> None:
    """A ValueError unless w1 (…, n_in, d), w2 (…, d, n_out) and mask (…, d) fit, with one
    leading stack axis when `batched` and none otherwise (static: checked under jit too)."""
    nd = 3 if batched else 2
    shapes = (jnp.shape(w1), jnp.shape(w2), jnp.shape(mask))
    if (
        len(shapes[0]) != nd
        or len(shapes[1]) != nd
        or len(shapes[2]) != nd - 1
        or not (shapes[0][-1] == shapes[1][-2] == shapes[2][-1])
        or not (shapes[0][:-2] == shapes[1][:-2] == shapes[2][:-1])
    ):
        stack = "a stack on axis 0 of " if batched else ""
        raise ValueError(
            f"w1, w2, mask have shapes {shapes[0]}, {shapes[1]}, {shapes[2]}; allowed: {stack}"
            "(n_in, d), (d, n_out), (d,)"
        )


class Truncation(NamedTuple):
    """`truncate`'s result."""

    params: Any  #: the parameters after the cut
    opt_state: Any  #: the optimiser state fitted to them (None when none was given)
    records: dict[str, LayerRecord]  #: per factorised layer, keyed by its path


def _replace_layers(params: Any, new: dict[str, dict]) -> Any:
    def swap(path, node):
        return new.get(jax.tree_util.keystr(path), node) if is_factorised(node) else node

    return jax.tree_util.tree_map_with_path(swap, params, is_leaf=is_factorised)


def fit_opt_state(
    opt_state: Any,
    old_params: Any,
    new_params: Any,
    *,
    optimizer: optax.GradientTransformation | None = None,
    reset: bool = True,
) -> Any:
    """The optimiser state for `new_params` after a cut. `reset` (AdaRL): `optimizer.init`, or,
    without `optimizer`, every leaf zeroed at its new shape (Adam's and SGD-momentum's fresh
    state). Not `reset`: every moment whose parameter kept its shape is kept (all of them for
    masked layers), the others start from zero at the new shape; counts are kept."""
    if opt_state is None:
        return None
    if reset and optimizer is not None:
        return optimizer.init(new_params)
    structure = jax.tree_util.tree_structure(old_params)

    def like_params(node) -> bool:
        try:
            return jax.tree_util.tree_structure(node) == structure
        except Exception:  # noqa: BLE001 - nodes that are not pytrees are leaves
            return False

    nodes = jax.tree_util.tree_leaves(opt_state, is_leaf=like_params)
    moments = [n for n in nodes if not like_params(n) and jnp.ndim(n) >= 1]
    if moments and not any(like_params(n) for n in nodes):
        # per-parameter arrays, none of them laid out as these params: another model's state
        raise ValueError(
            "opt_state does not match params: none of its per-parameter parts has the structure "
            "of the params being cut (another model's optimiser state?); allowed: the state of "
            "the optimiser that trains these params"
        )

    def fit(node):
        if like_params(node):
            return jax.tree_util.tree_map(
                lambda old, p: (
                    old if not reset and old.shape == p.shape else jnp.zeros(p.shape, old.dtype)
                ),
                node,
                new_params,
            )
        return jnp.zeros_like(node) if reset and hasattr(node, "shape") else node

    return jax.tree_util.tree_map(fit, opt_state, is_leaf=like_params)


def truncate(
    params: Any,
    opt_state: Any = None,
    *,
    rule: str = DEFAULT_RULE,
    beta: float = DEFAULT_BETA,
    retain_tolerance: float | None = None,
    output_fn: Callable[[Any], jax.Array] | None = None,
    optimizer: optax.GradientTransformation | None = None,
    reset: bool = True,
    apply_cuts: bool = True,
) -> Truncation:
    """AdaRL's rank adaptation (paper Sec. 4, Eq. 5) on every factorised layer of `params`.

    Each layer is cut by `cut_layer`: SVD of W1·W2, the rule's r̂ (`rule`: `cumulative` = Eq. 5,
    `ratio` = Eq. 7, `energy`, `energy-squared`; threshold `beta`), r_c = max(1, min(r_old, r̂)),
    the retain clause with `retain_tolerance` (None: off) on the relative change of
    `output_fn(params)` with only that layer cut (as adarl: e.g. the policy's action on a batch
    of states), or of the layer's weight when `output_fn` is None; then W1 = U_r√Σ_r,
    W2 = √Σ_r V_rᵀ. Masked layers keep their shapes (jit/vmap-safe); compact layers are sliced
    to the applied rank (concrete values: call it outside `jit`). The optimiser state is fitted
    by `fit_opt_state` (`reset=True`: AdaRL's reset). `apply_cuts=False` is the control: the
    same basis and reset, the old ranks kept. Defaults are adarl's: `energy`, β 0.98.

    Inputs are checked as `cut_layer` checks them; a concrete layer whose W1·diag(mask)·W2 is
    not finite is a ValueError naming its path (a traced one is left as it was).
    """
    check_rule(rule)
    check_beta(beta)
    check_tolerance(retain_tolerance)
    layers = factorised_layers(params)
    for path, layer in layers.items():
        if "mask" in layer:
            check_mask(layer["mask"], f"layer {path}'s mask")
            mask = layer["mask"]
        else:
            mask = jnp.ones(layer["w1"].shape[:-2] + layer["w1"].shape[-1:], layer["w1"].dtype)
        _check_shapes(layer["w1"], layer["w2"], mask, layer["w1"].ndim == 3)
        if _concrete((layer["w1"], layer["w2"], mask)):
            product = (layer["w1"] * mask[..., None, :]) @ layer["w2"]
            if not bool(jnp.all(jnp.isfinite(product))):
                raise ValueError(
                    f"layer {path}'s W1·diag(mask)·W2 holds inf or NaN (diverged weights?); "
                    "allowed: finite factors (the SVD of a non-finite matrix is undefined)"
                )
    reference = None if output_fn is None else output_fn(params)
    new_layers, records = {}, {}
    for path, layer in layers.items():
        masked, batched = "mask" in layer, layer["w1"].ndim == 3
        shape = layer["w1"].shape[:-2] + layer["w1"].shape[-1:]
        mask = layer["mask"] if masked else jnp.ones(shape, layer["w1"].dtype)
        error_fn = None
        if output_fn is not None:

            def error_fn(w1, w2, m, path=path, layer=layer, masked=masked, batched=batched):
                candidate = dict(layer, w1=w1, w2=w2, **({"mask": m} if masked else {}))
                out = output_fn(_replace_layers(params, {path: candidate}))
                error = relative_error(out, reference)  # a stack is cut and measured at once
                return jnp.broadcast_to(error, m.shape[:1]) if batched else error

        w1, w2, m, record = cut_layer(
            layer["w1"],
            layer["w2"],
            mask,
            rule=rule,
            beta=beta,
            retain_tolerance=retain_tolerance,
            error_fn=error_fn,
            apply_cuts=apply_cuts,
            batched=batched,
        )
        if masked:
            new_layers[path] = dict(layer, w1=w1, w2=w2, mask=m)
        else:  # a compact stack is cut to its largest rank (components past each one's are zero)
            r = int(jnp.max(record.applied))
            new_layers[path] = dict(layer, w1=w1[..., :r], w2=w2[..., :r, :])
        records[path] = record
    new_params = _replace_layers(params, new_layers)
    fitted = fit_opt_state(opt_state, params, new_params, optimizer=optimizer, reset=reset)
    return Truncation(new_params, fitted, records)


def to_compact(params: Any) -> Any:
    """Masked factorised layers cut to their rank (mask dropped): the same function, fewer
    parameters (e.g. to export the compressed network); a stack keeps its largest rank (the
    components past each layer's own are zero). Concrete values only; a mask that is not 0/1
    with its ones first is a ValueError."""
    new = {}
    for path, layer in factorised_layers(params).items():
        if "mask" in layer:
            check_mask(layer["mask"], f"layer {path}'s mask")
            r = int(layer["mask"].sum(axis=-1).max())
            rest = {k: v for k, v in layer.items() if k != "mask"}
            new[path] = dict(rest, w1=layer["w1"][..., :r], w2=layer["w2"][..., :r, :])
    return _replace_layers(params, new)


def weight_decay_mask(params: Any) -> Any:
    """A pytree of bools shaped like `params`: False for the `mask` of every masked factorised
    layer, True elsewhere. Give it to an optimiser's weight decay (`optax.adamw(lr,
    weight_decay=wd, mask=lowrank.weight_decay_mask)`): decay changes every parameter it is
    applied to, gradient or not, and would shrink the masks (1 → 1 − lr·wd each step), after
    which they are no longer ranks."""

    def leaves(node):
        if is_factorised(node):
            return {
                k: jax.tree_util.tree_map(lambda _, k=k: k != "mask", v) for k, v in node.items()
            }
        return jax.tree_util.tree_map(lambda _: True, node)

    return jax.tree_util.tree_map(leaves, params, is_leaf=is_factorised)


# ============================================================================ learning rate


def restart_learning_rate(step_in_iteration, base_lr, warmup_steps, iteration_steps, min_ratio):
    """`adarl.schedules.restart_learning_rate` in `jax.numpy`: linear warm-up to `base_lr`, then a
    cosine to `min_ratio · base_lr` over the rest of an iteration of `iteration_steps`."""
    return schedules.restart_learning_rate(
        step_in_iteration, base_lr, warmup_steps, iteration_steps, min_ratio, xp=jnp
    )


def envelope_learning_rate(
    update, iteration_start, base_lr, warmup_steps, total_updates, min_ratio, warm_up
):
    """`adarl.schedules.envelope_learning_rate` in `jax.numpy`: ReLoRA's cosine envelope over the
    run, with a linear warm-up after each optimiser reset at `iteration_start`."""
    return schedules.envelope_learning_rate(
        update, iteration_start, base_lr, warmup_steps, total_updates, min_ratio, warm_up, xp=jnp
    )


def envelope_schedule(
    base_lr: float,
    *,
    total_steps: int,
    warmup_steps: int,
    cut_every: int,
    min_ratio: float = 0.0,
    warm_up_first: bool = False,
) -> optax.Schedule:
    """`envelope_learning_rate` as an optax schedule of the global gradient step t, for cuts
    after every `cut_every` steps: the warm-up restarts at t_reset = ⌊t / d_t⌋·d_t (from the
    first cut on, or from the start with `warm_up_first`). Equal to adarl's learning rate when
    d_t is a multiple of its `update_every`. Feed it the global step (the optimiser's count
    restarts at a reset), e.g. `updates * -schedule(step)`. `total_steps` and `cut_every` are
    integers ≥ 1, `warmup_steps` ≥ 0, `base_lr` finite ≥ 0 and `min_ratio` in [0, 1]; else a
    ValueError."""
    _check_schedule(base_lr, warmup_steps, cut_every, min_ratio)
    _count(total_steps, "total_steps", 1)

    def schedule(step):
        start = (jnp.asarray(step, jnp.int32) // cut_every) * cut_every
        warm_up = jnp.logical_or(start > 0, warm_up_first)
        return envelope_learning_rate(
            step, start, base_lr, warmup_steps, total_steps, min_ratio, warm_up
        )

    return schedule


def restart_schedule(
    base_lr: float, *, warmup_steps: int, cut_every: int, min_ratio: float = 0.0
) -> optax.Schedule:
    """`restart_learning_rate` as an optax schedule of the steps since the last reset: a full
    warm-up + cosine over every iteration of d_t = `cut_every` steps. Since `truncate` resets
    the optimiser's count, it also works inside a chain (`optax.scale_by_schedule`).
    `cut_every` is an integer ≥ 1, `warmup_steps` ≥ 0, `base_lr` finite ≥ 0 and `min_ratio`
    in [0, 1]; else a ValueError."""
    _check_schedule(base_lr, warmup_steps, cut_every, min_ratio)

    def schedule(count):
        return restart_learning_rate(count, base_lr, warmup_steps, cut_every, min_ratio)

    return schedule


def _check_schedule(base_lr, warmup_steps, cut_every, min_ratio) -> None:
    _count(cut_every, "cut_every", 1)
    _count(warmup_steps, "warmup_steps", 0)
    lr = _scalar(base_lr, "base_lr")
    if lr is not None and not (math.isfinite(lr) and lr >= 0):
        raise ValueError(f"base_lr must be a finite number >= 0, got {lr!r}")
    ratio = _scalar(min_ratio, "min_ratio")
    if ratio is not None and not (0.0 <= ratio <= 1.0):
        raise ValueError(f"min_ratio must be a number in [0, 1], got {ratio!r}")


__all__ = [
    "DEFAULT_BETA",
    "DEFAULT_RULE",
    "RANK_RULES",
    "LayerRecord",
    "Truncation",
    "apply_factorised",
    "bottleneck_product",
    "check_beta",
    "check_mask",
    "check_tolerance",
    "cut_layer",
    "envelope_learning_rate",
    "envelope_schedule",
    "factorised_layers",
    "fit_opt_state",
    "init_factorised",
    "is_factorised",
    "layer_rank",
    "next_rank",
    "product_finite",
    "rank_mask",
    "relative_error",
    "reparameterise",
    "restart_learning_rate",
    "restart_schedule",
    "retain_or_cut",
    "select_rank",
    "select_rank_cumulative",
    "select_rank_energy",
    "select_rank_ratio",
    "spectrum",
    "svd",
    "to_compact",
    "truncate",
    "weight_decay_mask",
    "weight_error",
]
