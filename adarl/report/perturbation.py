"""Return against the size of the perturbation, from a suite's grid evaluation.

The size of a grid point p is its distance from the nominal point c (the centre of the paper's
training schedule, the `nominal` dynamics) in units of each parameter's training half-range a
(the schedule's amplitude |a_i|, so the training range is c_i ∓ a_i):

    size(p) = max_i |p_i − c_i| / a_i          (max-norm, Chebyshev; the default)
    size(p) = sqrt(Σ_i ((p_i − c_i) / a_i)²)   (Euclidean, `norm="euclidean"`)

Why the max-norm: the uncertainty sets robust RL trains and evaluates on are boxes, a product of
one interval per parameter: M2TD3's uncertainty parameter sets (Tanabe et al. 2022,
akimotolab/M2TD3 configs/environment/*.yaml, one [min, max] per parameter), RRLS's
`*ParamsBound` (Zouitine et al. 2024, SuReLI/RRLS rrls/envs/hopper.py: a [min, max] per
parameter), and the AdaRL paper's own schedule (each parameter c_i + a_i·sin(ωi), so
|p_i − c_i| ≤ a_i). The points of size ≤ r are then exactly the training box shrunk (r < 1) or
grown (r > 1) by r about its centre, and the worst case over them is the worst-case return of
that scaled uncertainty set. It is also robust control's normalisation of parametric
uncertainty, p_i = c_i + a_i δ_i with ‖δ‖_∞ ≤ 1, whose stability margin is the largest such
scaling (Zhou, Doyle & Glover 1996, "Robust and Optimal Control": parametric uncertainty as
linear fractional transformations with normalised δ_i ∈ [−1, 1]). On a product grid of
`np.linspace(c − a, c + a, n)` values the max-norm sizes are the grid's own concentric square
rings: for n = 10 the normalised values are ±1/9, ±3/9, …, ±1, the sizes 1/9, 3/9, 5/9, 7/9, 1
with 4, 12, 20, 28, 36 points (the nominal point itself is not on the grid; for odd n it is, a
ring of size 0). The Euclidean size gives 14 distinct values on that grid, circles that cut
through it, and needs binning.

A ring is the set of grid points of one size (by default, every distinct size is its own ring:
exact, nothing merged) or of sizes in one bin (e0, e1] of given edges, labelled by its upper edge
(a size exactly 0, the nominal point, has its own ring 0).

Per seed and ring: the **mean** (of the points' mean returns over their episodes) and the
**worst** point; and per seed and size r the **worst within** r: the lowest point mean over all
points of size ≤ r, i.e. the worst-case return of the uncertainty set scaled by r, which at the
suite's largest size equals the suite's worst-case return (`suites.seed_summary`). Over seeds:
the mean with a Student-t band (`stats.t_interval`), as the report's other curves.

Pure functions; `adarl.report` writes the figure and table.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from adarl import stats
from adarl.errors import UsageError
from adarl.runs import layout

NORMS = ("max", "euclidean")
#: Sizes closer than this are one size (grid values read back from CSV: 6 significant digits).
TOLERANCE = 1e-4
#: Ring labels (the size of a ring's points) are rounded to this many decimals.
LABEL_DECIMALS = 4
#: Columns of `ring_returns` (one row per seed and ring).
RING_COLUMNS = ["seed", "ring", "points", "mean", "worst", "worst_within"]


def training_box(task: str, params: Sequence[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """(centre c, half-range a) of each parameter in `params` under the task's `paper` training
    schedule (`adarl.envs.tasks`: c + a·sin(ωi)); None when a parameter is not scheduled (the
    literature's suites vary masses and friction the paper never trains on: no training range)."""
    from adarl.envs.tasks import TASKS

    schedule = TASKS[task].schedules["paper"] if task in TASKS else {}
    if not params or any(p not in schedule for p in params):
        return None
    return (
        np.array([schedule[p].center for p in params], float),
        np.array([abs(schedule[p].amplitude) for p in params], float),
    )


def perturbation_size(
    points: np.ndarray, centre: Sequence[float], half_range: Sequence[float], norm: str = "max"
) -> np.ndarray:
    """Size of each row of `points` (shape (n, d)): its distance from `centre` in units of
    `half_range`, max-norm (Chebyshev) or Euclidean (module docstring)."""
    if norm not in NORMS:
        raise UsageError(f"unknown norm {norm!r}; allowed: {', '.join(NORMS)}")
    points = np.atleast_2d(np.asarray(points, float))
    half_range = np.asarray(half_range, float)
    if np.any(half_range <= 0):
        raise UsageError(f"half-ranges must be > 0, got {half_range.tolist()}")
    scaled = np.abs(points - np.asarray(centre, float)) / half_range
    return scaled.max(axis=1) if norm == "max" else np.sqrt((scaled**2).sum(axis=1))


def assign_rings(sizes: np.ndarray, edges: Sequence[float] | None = None) -> np.ndarray:
    """The ring of each size. `edges` None: every distinct size is a ring, labelled by the size
    (rounded to `LABEL_DECIMALS`); sizes closer than `TOLERANCE` are one size (evaluation CSVs
    keep 6 significant digits, so one grid ring's points can differ in the 6th digit). With
    `edges` (increasing): the upper edge e_k of the bin (e_{k−1}, e_k] that holds the size, with 0
    a ring of its own; a size above the last edge is an error (one line)."""
    sizes = np.asarray(sizes, float)
    if edges is None:
        if sizes.size == 0:
            return sizes
        distinct = np.unique(sizes)
        group = np.cumsum(np.concatenate([[True], np.diff(distinct) > TOLERANCE])) - 1
        labels = np.array([distinct[group == g].mean() for g in range(group[-1] + 1)])
        return labels.round(LABEL_DECIMALS)[group[np.searchsorted(distinct, sizes)]]
    edges = np.asarray(edges, float)
    if edges.ndim != 1 or len(edges) == 0 or np.any(np.diff(edges) <= 0) or edges[0] < 0:
        raise UsageError(f"ring edges must be increasing and ≥ 0, got {edges.tolist()}")
    if sizes.size and sizes.max() > edges[-1] + TOLERANCE:
        raise UsageError(f"a size {sizes.max():g} lies beyond the last ring edge {edges[-1]:g}")
    index = np.minimum(np.searchsorted(edges, sizes - TOLERANCE, side="left"), len(edges) - 1)
    return np.where(sizes <= TOLERANCE, 0.0, edges[index])


def ring_returns(
    point_means: pd.DataFrame,
    params: Sequence[str],
    centre: Sequence[float],
    half_range: Sequence[float],
    edges: Sequence[float] | None = None,
    norm: str = "max",
) -> pd.DataFrame:
    """Per seed and ring (`RING_COLUMNS`): the number of grid points in the ring, the mean and the
    lowest of their mean returns, and the worst within the ring's size (lowest over all points of
    a ring ≤ this one). `point_means`: one row per seed and grid point, columns `seed`, `return`
    (the point's mean over episodes, `suites.point_means`) and `p_<param>` for each of `params`."""
    values = point_means[[layout.param_column(p) for p in params]].to_numpy(float)
    rings = assign_rings(perturbation_size(values, centre, half_range, norm), edges)
    data = point_means[["seed", "return"]].assign(ring=rings)
    rows = []
    for seed, group in data.groupby("seed", sort=True):
        by_ring = group.groupby("ring", sort=True)["return"]
        worst = by_ring.min()
        within = np.minimum.accumulate(worst.to_numpy(float))
        for (ring, count), mean, low, low_within in zip(
            by_ring.size().items(), by_ring.mean(), worst, within
        ):
            rows.append([int(seed), float(ring), int(count), float(mean), float(low), low_within])
    return pd.DataFrame(rows, columns=RING_COLUMNS)


def ring_summary(per_seed: pd.DataFrame, confidence: float = 0.95) -> pd.DataFrame:
    """Over seeds, per ring (and per `method` when the column is there): seeds, points, and for
    `mean`, `worst` and `worst_within` the mean over seeds with its Student-t interval
    (`<column>_mean`, `_low`, `_high`). Seeds without a ring (a partial grid) are left out of it."""
    keys = ["method", "ring"] if "method" in per_seed else ["ring"]
    rows = []
    for key, group in per_seed.groupby(keys, sort=False):
        key = key if isinstance(key, tuple) else (key,)
        row = dict(zip(keys, key)) | {"seeds": len(group), "points": int(group["points"].max())}
        for column in ("mean", "worst", "worst_within"):
            centre, low, high = stats.t_interval(group[column].to_numpy(float), confidence)
            row |= {f"{column}_mean": float(centre), f"{column}_low": float(low)}
            row[f"{column}_high"] = float(high)
        rows.append(row)
    out = pd.DataFrame(rows)
    return out.sort_values(keys, kind="stable", ignore_index=True) if len(out) else out


def describe_rings(per_seed: pd.DataFrame) -> Mapping[float, int]:
    """{ring: grid points in it} (the largest count over seeds), for captions."""
    return per_seed.groupby("ring", sort=True)["points"].max().to_dict()
