"""Output of the Theorem 1 experiments: CSV tables, a JSON summary and figures (PNG + PDF), every
file written atomically (temp file in the same folder, then ``os.replace``).

Figures use Matplotlib's object-oriented API on the Agg canvas (no pyplot, no global backend).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from adarl.files import atomic_write_bytes
from adarl.theory.linalg import picard_limits
from adarl.theory.synthetic import COLUMNS, Sweep, best_rank, summarise

PICARD_COLUMNS = ["system", "i", "sigma", "abs_ub", "picard_limit", "picard_constant"]


def _fmt(value) -> str | int:
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return f"{float(value):.6g}"
    return value


def csv_text(rows: list[dict], columns: list[str]) -> str:
    """CSV with a header and one line per row (floats with 6 significant digits)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _fmt(row[k]) for k in columns})
    return buf.getvalue()


def picard_rows(
    system: str, sigma: np.ndarray, coef: np.ndarray, r0: int, p: float, c: float = 1.0
) -> list[dict]:
    """Rows of ``picard.csv``: ``σ_i``, ``|u_iᵀb|``, the Picard limit (``σ_i^p``, ``σ_{r°}^p`` past
    r°) and the constant C used for the bias term (``|u_iᵀb| ≤ C·limit``; the paper's C is 1)."""
    limit = picard_limits(sigma, r0, p)
    return [
        {
            "system": system,
            "i": i + 1,
            "sigma": sigma[i],
            "abs_ub": coef[i],
            "picard_limit": limit[i],
            "picard_constant": float(c),
        }
        for i in range(sigma.size)
    ]


def sweep_summary(sweeps: list[Sweep]) -> list[dict]:
    """Per ε: the best rank (smallest minimiser of the mean error), its error, the rank that
    minimises the mean bound, the worst ``error / bound`` over all draws and ranks, how often the
    error exceeded the bound, and the largest mean of the proof's third part
    ``‖A_{P,r}^† ε_A θ°‖`` over r (the term the paper calls ``2·O(Lε)``)."""
    out = []
    for sw in sweeps:
        mean = sw.error.mean(axis=0)
        r_best = best_rank(sw)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(sw.bound > 0, sw.error / sw.bound, 0.0)
        out.append(
            {
                "eps": sw.eps,
                "best_r": r_best,
                "error_at_best_r": float(mean[r_best - 1]),
                "error_at_r1": float(mean[0]),
                "error_at_rd": float(mean[-1]),
                "bound_best_r": int(np.nanargmin(sw.bound.mean(axis=0))) + 1,
                "max_error_over_bound": float(np.nanmax(ratio)),
                "bound_violations": int(np.sum(sw.error > sw.bound * (1 + 1e-9) + 1e-12)),
                "max_pert_part": float(sw.pert_part.mean(axis=0).max()),
            }
        )
    return out


# ----------------------------------------------------------------------------- figures
def _new_figure(width: float, height: float, **margins):
    """Figure on an Agg canvas with fixed margins (a layout engine would double the drawing time).

    ``margins`` are ``subplots_adjust`` arguments given in inches from each edge.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    m = {"left": 0.7, "right": 0.15, "bottom": 0.5, "top": 0.45} | margins
    fig.subplots_adjust(
        left=m["left"] / width,
        right=1 - m["right"] / width,
        bottom=m["bottom"] / height,
        top=1 - m["top"] / height,
        wspace=m.get("wspace", 0.25),
        hspace=m.get("hspace", 0.35),
    )
    return fig


def _colors(n: int):
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    return [cmap(x) for x in np.linspace(0.0, 0.85, max(n, 1))]


def _style(ax, xlabel: str, floor: float | None = None) -> None:
    """Log y axis with plain-text labels (no mathtext: it is slow), integer x ticks, grid."""
    from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter

    ax.set_yscale("log")
    ax.yaxis.set_major_locator(LogLocator(base=10, numticks=8))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda y, _: f"{y:g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())
    if floor is not None:
        ax.set_ylim(bottom=floor)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(xlabel)
    ax.grid(True, which="major", alpha=0.3)


def _display_floor(values: list[np.ndarray]) -> float:
    """Lower y-limit for log plots: below the smallest value that is not rounding noise."""
    pos = np.concatenate([v[v > 1e-12] for v in values] + [np.array([1.0])])
    return float(pos.min()) / 3


def plot_error(sweeps: list[Sweep], r0: int, title: str):
    """Mean ``‖θ_r − θ°‖₂`` against r for each ε (10–90 % band over draws), best r marked, r°
    dotted; right panel: the Q-value error under the ground-truth distribution ``‖θ_r − θ°‖_{A°}``."""
    fig = _new_figure(10, 4, left=0.75, top=0.5, wspace=0.22)
    axes = fig.subplots(1, 2)
    colors = _colors(len(sweeps))
    panels = (
        (axes[0], "error", "‖θ_r − θ°‖₂"),
        (axes[1], "pred_error", "‖θ_r − θ°‖_A°  (RMS Q-value error under P°)"),
    )
    for ax, key, label in panels:
        means = []
        for sw, color in zip(sweeps, colors):
            vals = getattr(sw, key)
            r = np.arange(1, vals.shape[1] + 1)
            mean = vals.mean(axis=0)
            means.append(mean)
            lo, hi = np.quantile(vals, [0.1, 0.9], axis=0)
            ax.plot(r, mean, "-o", ms=3, color=color, label=f"ε = {sw.eps:g}")
            ax.fill_between(r, lo, hi, color=color, alpha=0.15, lw=0)
            if key == "error":
                rb = best_rank(sw)
                ax.plot([rb], [mean[rb - 1]], "*", ms=12, color=color, mec="k", mew=0.5)
        ax.axvline(r0, color="grey", ls=":", lw=1)
        _style(ax, "truncation rank r", _display_floor(means))
        ax.set_ylabel(label, fontsize=9)
    axes[0].legend(fontsize=8, title="★ best r   ┆ r°", title_fontsize=8)
    fig.suptitle(title, fontsize=10)
    return fig


BOUND_SERIES = [
    ("error", "k", "-", 2.0, "error ‖θ_r − θ°‖"),
    ("var_part", "tab:blue", "-", 1.0, "‖A†_{P,r} (b_P − b°)‖"),
    ("bias_part", "tab:orange", "-", 1.0, "‖Σ_{i>r} v_i v_iᵀ θ°‖"),
    ("pert_part", "tab:green", "-", 1.0, "‖A†_{P,r} ε_A θ°‖"),
    ("var_term", "tab:blue", "--", 1.0, "variance term ‖b_P − b°‖ / σ_{P,r}"),
    ("bias_term", "tab:orange", "--", 1.0, "bias term (d−r)(σ°_r^{p−1} + r° σ°_1^{p−1})"),
    ("lipschitz_term", "tab:green", "--", 1.0, "O(Lε) term ‖ε_A‖ ‖θ°‖ / σ_{P,r}"),
    ("bound", "k", "--", 1.5, "bound = sum of the dashed terms"),
]


def plot_bound(sweeps: list[Sweep], r0: int, title: str):
    """One panel per ε: the measured error, the proof's exact parts (solid) and the theorem's
    computable terms and total bound (dashed), against r, log scale."""
    n = len(sweeps)
    ncols = min(n, 3)
    nrows = -(-n // ncols)
    fig = _new_figure(4 * ncols, 3 * nrows + 1.5, bottom=1.35, top=0.65, hspace=0.4)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    for ax, sw in zip(axes, sweeps):
        r = np.arange(1, sw.error.shape[1] + 1)
        shown = []
        for key, color, ls, lw, label in BOUND_SERIES:
            mean = getattr(sw, key).mean(axis=0)
            shown.append(mean)
            ax.plot(r, np.where(mean > 0, mean, np.nan), ls=ls, color=color, lw=lw, label=label)
        ax.axvline(r0, color="grey", ls=":", lw=1)
        _style(ax, "r", _display_floor(shown))
        ax.set_title(f"ε = {sw.eps:g}", fontsize=9)
    for ax in axes[n:]:
        ax.set_visible(False)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncols=2, fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=10)
    return fig


def plot_picard(systems: list[tuple[str, np.ndarray, np.ndarray, int, float, float]]):
    """Picard plot per system ``(name, σ, |u_iᵀb|, r°, p, C)``: ``σ_i``, ``|u_iᵀb|``, the limit
    ``σ_i^p`` and, when C ≠ 1, ``C·σ_i^p``, against i ≤ r° (beyond r°, ``u_iᵀb = 0``)."""
    fig = _new_figure(4.5 * len(systems), 3.5, wspace=0.3)
    axes = np.atleast_1d(fig.subplots(1, len(systems), squeeze=False)).ravel()
    for ax, (name, sigma, coef, r0, p, c) in zip(axes, systems):
        i = np.arange(1, r0 + 1)
        limit = picard_limits(sigma, r0, p)[:r0]
        ax.plot(i, sigma[:r0], "o-", label="σ_i")
        ax.plot(i, np.where(coef[:r0] > 0, coef[:r0], np.nan), "s-", label="|u_iᵀ b°|")
        ax.plot(i, limit, "k--", label=f"σ_i^p, p = {p:g}")
        if c > 1:
            ax.plot(i, c * limit, "k:", label=f"C σ_i^p, C = {c:.3g}")
        _style(ax, "i")
        ax.set_title(name, fontsize=9)
        ax.legend(fontsize=8)
    return fig


def save_figure(fig, out_dir: Path, stem: str) -> list[Path]:
    """Write ``stem.png`` (100 dpi) and ``stem.pdf`` atomically; returns the paths."""
    paths = []
    for ext, kwargs in (("png", {"dpi": 100}), ("pdf", {})):
        buf = io.BytesIO()
        fig.savefig(buf, format=ext, **kwargs)
        path = out_dir / f"{stem}.{ext}"
        atomic_write_bytes(path, buf.getvalue())
        paths.append(path)
    return paths


def write_sweep(out_dir: Path, stem: str, sweeps: list[Sweep], r0: int, title: str) -> list[Path]:
    """``stem.csv`` (columns ``COLUMNS``) plus the error and bound figures of one experiment."""
    path = out_dir / f"{stem}.csv"
    atomic_write_bytes(path, csv_text(summarise(sweeps), COLUMNS).encode())
    paths = [path]
    paths += save_figure(plot_error(sweeps, r0, title), out_dir, f"{stem}_error")
    paths += save_figure(plot_bound(sweeps, r0, title), out_dir, f"{stem}_bound")
    return paths


def write_json(path: Path, obj) -> Path:
    """Pretty JSON, NumPy scalars/arrays converted; NaN and inf written as strings."""

    def clean(x):
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list | tuple | np.ndarray):
            return [clean(v) for v in x]
        if isinstance(x, np.integer):
            return int(x)
        if isinstance(x, float | np.floating):
            x = float(x)
            return x if np.isfinite(x) else str(x)
        return x

    atomic_write_bytes(path, (json.dumps(clean(obj), indent=2) + "\n").encode())
    return path
