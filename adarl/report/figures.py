"""The report's figures, built with matplotlib's object API (no pyplot state, so any backend
setting is irrelevant and nothing leaks between figures; saving uses Agg for PNG and the PDF
backend for PDF). Each function takes tidy data and returns a `matplotlib.figure.Figure`;
`save_figure` writes it as PNG and PDF. Sizes and fonts are for a two-column paper: a full-width
figure is 7 in wide, a single-column one 3.4 in, with 8 pt text.

Bands over seeds are Student-t 95% confidence intervals of the mean (`stats.t_interval`),
clipped to the returns the task can give where those are known (`clip_band`; from 2 seeds a
t band is the mean ± 12.7 standard errors, far past them). Curves of at most `FEW_POINTS` points
carry markers (one evaluation is otherwise not drawn at all).
"""

from __future__ import annotations

import dataclasses
import functools
import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib
import matplotlib.ticker
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from adarl.algos import registry
from adarl.files import atomic_write_bytes
from adarl.results.collect import Spectrum
from adarl.results.runs import sort_methods
from adarl.stats import t_interval

FULL_WIDTH = 7.0
COLUMN_WIDTH = 3.4
PANEL_HEIGHT = 2.2
STYLE = {
    "font.size": 8,
    "axes.titlesize": 8,
    "axes.labelsize": 8,
    "legend.fontsize": 6.5,
    "xtick.labelsize": 7,
    "ytick.labelsize": 7,
    "lines.linewidth": 1.2,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "savefig.dpi": 200,
    "pdf.fonttype": 42,  # embed TrueType: text stays editable and searchable
}
UNBOUNDED = (-math.inf, math.inf)  # a return with no known bound
FEW_POINTS = 30  # a curve with at most this many points has a marker at each
MARGIN = 0.05  # room around the data on a return axis, as a fraction of its height
TRUNCATION_STYLE = {"color": "red", "linestyle": "--", "linewidth": 0.8, "alpha": 0.8}
INTRINSIC_STYLE = {"color": "black", "linestyle": ":", "linewidth": 1.0}


def styled(func):
    """Build the figure under the report's rc style."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with matplotlib.rc_context(STYLE):
            return func(*args, **kwargs)

    return wrapper


def save_figure(fig: Figure, stem: Path) -> list[Path]:
    """Write `stem.png` and `stem.pdf`, each atomically; returns both paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = []
    with matplotlib.rc_context(STYLE):
        for suffix in ("png", "pdf"):
            path = stem.parent / f"{stem.name}.{suffix}"  # not with_suffix: names may hold dots
            buffer = io.BytesIO()
            fig.savefig(
                buffer, format=suffix, metadata={"CreationDate": None} if suffix == "pdf" else None
            )
            atomic_write_bytes(path, buffer.getvalue())
            fig.set_layout_engine("none")  # laid out once by the first save; keep it (faster)
            paths.append(path)
    return paths


def method_colours(methods: Sequence[str]) -> dict[str, tuple]:
    """A fixed colour per method (tab10 in the report's method order)."""
    cmap = matplotlib.colormaps["tab10"]
    return {m: cmap(i % 10) for i, m in enumerate(sort_methods(methods))}


def _grid(n_panels: int, width: float = FULL_WIDTH, max_cols: int = 4, sharey=False):
    cols = max(1, min(n_panels, max_cols))
    rows = -(-n_panels // cols)
    fig = Figure(figsize=(width, PANEL_HEIGHT * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False, sharey=sharey).ravel()
    for ax in axes[n_panels:]:
        ax.set_visible(False)
    return fig, list(axes[:n_panels])


def clip_band(
    low: np.ndarray, high: np.ndarray, bounds: tuple[float, float] = UNBOUNDED
) -> tuple[np.ndarray, np.ndarray]:
    """A band's edges within `bounds`, the lowest and highest return the task can give
    (`adarl.envs.tasks.return_bounds`): a mean over seeds never leaves them, so neither does an
    interval of it that is drawn."""
    return np.clip(low, *bounds), np.clip(high, *bounds)


def _band(ax, x, values, label, colour=None, bounds=UNBOUNDED, **line):
    """Mean over seeds (rows of `values`) with a 95% t band within `bounds` (`clip_band`)."""
    centre, low, high = t_interval(values)
    low, high = clip_band(low, high, bounds)
    (handle,) = ax.plot(x, centre, label=label, color=colour, **line)
    if values.shape[0] > 1 and len(x) == 1:  # a band of no width is not drawn: the interval
        ax.vlines(x, low, high, color=handle.get_color(), alpha=0.4, linewidth=3)
    elif values.shape[0] > 1:
        ax.fill_between(x, low, high, color=handle.get_color(), alpha=0.2, linewidth=0)
    return handle


class Log2Ticks(matplotlib.ticker.Locator):
    """Integer ticks on a log-2 axis, as many per octave as the view leaves room for: 2^k·{1,
    1.25, 1.5, 1.75} over up to 2.5 octaves (…, 16, 20, 24, 28, 32, …), 2^k·{1, 1.5} up to 5,
    else the powers of two; a panel's ranks can be read to a tick or two (the rank figure also
    writes each level on its line, `rank_trajectories`)."""

    def __call__(self):
        low, high = self.axis.get_view_interval()
        return self.tick_values(low, high)

    def tick_values(self, vmin, vmax):
        low, high = sorted((max(float(vmin), 1e-9), max(float(vmax), 1e-9)))
        octaves = np.log2(high / low)
        steps = (1, 1.25, 1.5, 1.75) if octaves <= 2.5 else (1, 1.5) if octaves <= 5 else (1,)
        ticks = {2**k * f for k in range(-4, 20) for f in steps}
        ticks = sorted(t for t in ticks if low <= t <= high and (t >= 1) == (t == round(t)))
        return ticks or [2.0 ** round(np.log2(np.sqrt(low * high)))]


def _log2_axis(ax, which: str) -> None:
    """Log-2 scale on axis `which` ("x"/"y") with plain labels at `Log2Ticks` (ranks)."""
    getattr(ax, f"set_{which}scale")("log", base=2)
    axis = getattr(ax, f"{which}axis")
    axis.set_major_locator(Log2Ticks())
    axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_locator(matplotlib.ticker.NullLocator())


def _few_points_marker(n_points: int) -> dict:
    """A marker at each point of a curve of at most `FEW_POINTS` points."""
    return {"marker": "o", "markersize": 3} if n_points <= FEW_POINTS else {}


def _from_zero(ax) -> None:
    """The y-axis includes 0 (a return axis that starts at 313 makes 2% look like a collapse)
    and every point and band of `ax` and of the axes sharing its y-axis, with `MARGIN` of the
    axis' height above and below them: no point sits on a spine, half cut. Data that all lie a
    margin or more above 0 get an axis from exactly 0."""
    boxes = [a.dataLim for a in ax.get_shared_y_axes().get_siblings(ax)]
    lows = [b.intervaly[0] for b in boxes if np.isfinite(b.intervaly).all()]
    highs = [b.intervaly[1] for b in boxes if np.isfinite(b.intervaly).all()]
    if not lows:
        return
    low, high = min(lows), max(highs)
    bottom, top = min(low, 0.0), max(high, 0.0)
    pad = MARGIN * (top - bottom) or 1.0
    ax.set_ylim(bottom - pad if low < pad else 0.0, top + pad)


def _legend_below(fig, ax) -> None:
    """`ax`'s legend under the figure's axes, outside them: it covers no point, line or band."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 3))


def _legend_above(ax) -> None:
    """`ax`'s legend just above it, outside it (covering no point, line or band) and inside the
    figure's layout; the figure's title goes above it as its suptitle (an axes title would
    overlap it), the space under the figure stays free for a note (`robustness_curve`'s
    base)."""
    handles, labels = ax.get_legend_handles_labels()
    ax.legend(
        handles,
        labels,
        loc="lower center",
        bbox_to_anchor=(0.5, 1.0),
        ncols=min(len(labels), 3),
        frameon=False,
        borderaxespad=0.2,
    )


def steps_label(steps: float) -> str:
    """An environment-step tick: 500, 250k, 1.5M."""
    for scale, suffix in ((1e6, "M"), (1e3, "k")):
        if abs(steps) >= scale:
            return f"{steps / scale:g}{suffix}"
    return f"{steps:g}"


def _steps_axis(ax) -> None:
    ax.set_xlabel("environment steps")
    ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: steps_label(v)))


def _rank_axes(
    ax, layer: str, title: str, intrinsic_rank, truncations: Sequence[int], legend: bool = True
) -> None:
    """A rank-over-training panel's furniture: the intrinsic rank 2·d_a+1, the truncation steps,
    the layer's title, axis labels, a log-2 rank axis and (first panel only: the panels share
    their lines) the legend."""
    if intrinsic_rank is not None:
        ax.axhline(intrinsic_rank, label=f"$2d_a+1$ = {intrinsic_rank}", **INTRINSIC_STYLE)
    for i, step in enumerate(truncations):
        ax.axvline(step, label="truncation" if i == 0 else None, **TRUNCATION_STYLE)
    ax.set_title(f"{title}: {layer}" if title else layer)
    _steps_axis(ax)
    ax.set_ylabel("rank")
    _log2_axis(ax, "y")
    if legend:
        ax.legend(loc="best")


def _by_seed(df: pd.DataFrame, x: str, y: str) -> tuple[np.ndarray, np.ndarray]:
    """Pivot a `x, seed, y` table to (x values, seeds × x matrix), NaN where a seed lacks x."""
    table = df.pivot_table(index=x, columns="seed", values=y, aggfunc="mean").sort_index()
    return table.index.to_numpy(float), table.to_numpy(float).T


# ----------------------------------------------------------------------------- figures
@styled
def training_curves(
    curves: Mapping[str, Mapping[str, pd.DataFrame]],
    truncations: Mapping[str, Sequence[int]] | None = None,
    colours: Mapping[str, tuple] | None = None,
    legend_loc: str = "figure",
    bounds: Mapping[str, tuple[float, float]] | None = None,
) -> Figure:
    """Return over training per task (one panel each), one line per method with its band over
    seeds (within `bounds[task]`, the returns the task can give, where given: `clip_band`;
    markers on a curve of few evaluations), and the truncation steps as red dashed vertical
    lines.

    `curves[task][method]` has columns `step, seed, return`; `legend_loc` "figure" (default)
    for one legend under all the panels (a method has one colour in every panel), clear of every
    point, curve and band; "below" for a legend under each panel (the figure grows to hold it);
    else matplotlib's `loc` inside each panel (its "best" ignores the bands).
    """
    tasks = list(curves)
    colours = colours or method_colours([m for t in tasks for m in curves[t]])
    fig, axes = _grid(len(tasks))
    for ax, task in zip(axes, tasks):
        for method in sort_methods(curves[task]):
            steps, values = _by_seed(curves[task][method], "step", "return")
            limits = (bounds or {}).get(task, UNBOUNDED)
            _band(
                ax,
                steps,
                values,
                method,
                colours.get(method),
                limits,
                **_few_points_marker(len(steps)),
            )
        for i, step in enumerate((truncations or {}).get(task, [])):
            ax.axvline(step, label="truncation" if i == 0 else None, **TRUNCATION_STYLE)
        ax.set_title(task)
        _steps_axis(ax)
        ax.set_ylabel("return (nominal dynamics)")
        if legend_loc == "below":
            ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.22), ncols=2)
        elif legend_loc != "figure":
            ax.legend(loc=legend_loc)
    if legend_loc == "below":
        fig.set_figheight(fig.get_figheight() * 1.45)
    if legend_loc == "figure":
        entries = {}  # label -> handle, in panel order, each once
        for ax in axes:
            handles, labels = ax.get_legend_handles_labels()
            for handle, label in zip(handles, labels):
                entries.setdefault(label, handle)
        fig.legend(
            list(entries.values()),
            list(entries),
            loc="outside lower center",
            ncols=min(len(entries), 6),
        )
    return fig


@styled
def rank_trajectories(
    history: pd.DataFrame,
    intrinsic_rank: int | None = None,
    title: str = "",
    truncations: Sequence[int] = (),
    end: float | None = None,
) -> Figure:
    """Rank of each bottleneck (one panel per layer) over training, one line per seed, with the
    intrinsic rank 2·d_a+1 as a horizontal line, and each level written on its line where it
    begins (`_level_labels`: 35, 30, 27, 26 read off the line, not between log-2 ticks). Each
    line holds its last rank to `end` (the run's last step), so a cut after the last log row
    still shows its level. `history`: `step, seed, layer, rank` (`collect.rank_history`: from
    the initial rank, with every cut at its step)."""
    layers = sorted(history["layer"].unique())
    fig, axes = _grid(len(layers), max_cols=3, sharey=True)
    levels = []
    for ax, layer in zip(axes, layers):
        data = history[history["layer"] == layer]
        starts = []
        for seed, rows in data.groupby("seed"):
            rows = rows.sort_values("step")
            steps, ranks = rows["step"].to_numpy(float), rows["rank"].to_numpy(float)
            if end is not None and len(steps) and steps[-1] < end:
                steps, ranks = np.r_[steps, end], np.r_[ranks, ranks[-1]]
            (line,) = ax.plot(steps, ranks, drawstyle="steps-post", label=f"seed {seed}")
            changed = np.r_[True, ranks[1:] != ranks[:-1]] & np.isfinite(ranks)
            starts += [(x, r, line.get_color()) for x, r in zip(steps[changed], ranks[changed])]
        levels.append(starts)
        _rank_axes(ax, layer, title, intrinsic_rank, truncations, legend=ax is axes[0])
    low, high = axes[0].get_ylim()  # shared: room above the top level for its label
    axes[0].set_ylim(low, high * 2 ** (1.5 * _label_octaves(axes[0])))
    for ax, starts in zip(axes, levels):
        _level_labels(ax, starts)
    return fig


def _label_octaves(ax) -> float:
    """How many octaves of `ax`'s log-2 y-axis a 6 pt label spans (7 pt with its spacing)."""
    low, high = ax.get_ylim()
    height_in = ax.get_position().height * ax.figure.get_figheight()
    return float(np.log2(high / low) * (7 / 72) / max(height_in, 1e-3))


MAX_LEVEL_STEPS = 12  # steps with a new level a rank panel writes; more: the first and the last


def _level_labels(ax, starts: Sequence[tuple[float, float, tuple]]) -> None:
    """Write each rank level (x where it begins, rank, line colour) just above its line. Levels
    that begin at one step and lie closer than a label's height on the log axis share one label
    in black: "26, 27", or the range "15–18" for three or more. Where levels begin at more than
    `MAX_LEVEL_STEPS` steps, only each line's first and last level are written."""
    gap = _label_octaves(ax)
    if len({x for x, _, _ in starts}) > MAX_LEVEL_STEPS:  # too many to write: first and last
        last = {colour: x for x, _, colour in sorted(starts, key=lambda s: s[0])}
        first = min(x for x, _, _ in starts)
        starts = [s for s in starts if s[0] == first or s[0] == last[s[2]]]
    by_step: dict[float, list[tuple[float, tuple]]] = {}
    for x, rank, colour in starts:
        by_step.setdefault(x, []).append((rank, colour))
    for x, found in by_step.items():
        found.sort(key=lambda item: -item[0])
        group = [found[0]]
        for item in [*found[1:], None]:
            if item is not None and np.log2(group[-1][0] / item[0]) < gap:
                group.append(item)
                continue
            values = sorted({int(r) if r == int(r) else r for r, _ in group})
            colours = {c for _, c in group}
            text = ", ".join(f"{v:g}" for v in values)
            ax.annotate(
                text if len(values) <= 2 else f"{values[0]:g}–{values[-1]:g}",
                (x, max(values)),
                xytext=(1.5, 1),
                textcoords="offset points",
                fontsize=6,
                va="bottom",
                ha="left",
                color=colours.pop() if len(colours) == 1 else "black",
            )
            group = [item]


@styled
def robustness_curve(
    data: pd.DataFrame,
    parameter: str,
    title: str = "",
    nominal: float | None = None,
    colours: Mapping[str, tuple] | None = None,
    base: str = "",
    bounds: tuple[float, float] = UNBOUNDED,
) -> Figure:
    """Return against one swept parameter, one line per method with its band over seeds (within
    `bounds`, the returns the task can give: `clip_band`), on a y-axis that includes 0 with room
    around every point (`_from_zero`), the nominal value as a grey dotted vertical line and the
    legend above the axes, under the title; `base`, the point the sweep moves one parameter away
    from (its dynamics and the other parameters' values), is written under the figure.

    `data`: `method, seed, value, return` (return: a seed's mean over episodes at that value).
    """
    colours = colours or method_colours(data["method"].unique())
    fig = Figure(figsize=(COLUMN_WIDTH, 2.6 + (0.3 if base else 0.0)), layout="constrained")
    ax = fig.add_subplot()
    for method in sort_methods(data["method"].unique()):
        x, values = _by_seed(data[data["method"] == method], "value", "return")
        _band(ax, x, values, method, colours.get(method), bounds, marker="o", markersize=3)
    if nominal is not None:
        ax.axvline(nominal, color="grey", linestyle=":", linewidth=1.0, label="nominal")
    _from_zero(ax)
    ax.set_xlabel(parameter)
    ax.set_ylabel("return")
    fig.suptitle(title or f"robustness to {parameter}", fontsize=STYLE["axes.titlesize"])
    _legend_above(ax)
    if base:
        fig.supxlabel(_wrapped(f"base: {base}", 70), fontsize=6.5, ha="center")
    return fig


def _wrapped(text: str, width: int) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width, break_on_hyphens=False))


@styled
def suite_heatmap(
    x_values: np.ndarray,
    y_values: np.ndarray,
    returns: np.ndarray,
    x: str,
    y: str,
    title: str = "",
) -> Figure:
    """Return over a two-parameter suite's grid (`returns`: shape (len(y), len(x)), the mean over
    seeds of each seed's mean return at the point), the worst point circled."""
    fig = Figure(figsize=(COLUMN_WIDTH, 2.8), layout="constrained")
    ax = fig.add_subplot()
    ax.grid(False)
    mesh = ax.pcolormesh(_edges(x_values), _edges(y_values), returns, cmap="viridis")
    fig.colorbar(mesh, ax=ax, label="return")
    if np.isfinite(returns).any():
        row, col = np.unravel_index(np.nanargmin(returns), returns.shape)
        ax.plot(x_values[col], y_values[row], "o", mfc="none", mec="red", ms=7, label="worst")
        ax.legend(loc="upper right")
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    ax.set_title(title)
    return fig


@styled
def robustness_size_curve(
    data: pd.DataFrame,
    title: str = "",
    colours: Mapping[str, tuple] | None = None,
    xlabel: str = "perturbation size (max_i |p_i − c_i| / a_i)",
    bounds: tuple[float, float] = UNBOUNDED,
) -> Figure:
    """Return against the size of the perturbation (`adarl.report.perturbation`), one line
    per method with its 95% t band over seeds (within `bounds`: `clip_band`). Left: each seed's
    mean return over the grid points of a ring; right: the worst point within the size (points
    of size ≤ r). A dotted line marks the edge of the training range (size 1); the legend is
    under the panels.

    `data`: `method, seed, ring, mean, worst_within` (`perturbation.ring_returns` per method)."""
    colours = colours or method_colours(data["method"].unique())
    fig = Figure(figsize=(FULL_WIDTH, 2.6), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    panels = (("mean", "mean over the ring's points"), ("worst_within", "worst point within size"))
    for ax, (column, label) in zip(axes, panels):
        for method in sort_methods(data["method"].unique()):
            x, values = _by_seed(data[data["method"] == method], "ring", column)
            _band(ax, x, values, method, colours.get(method), bounds, marker="o", markersize=3)
        if float(data["ring"].max()) >= 1.0:
            ax.axvline(1.0, color="grey", linestyle=":", linewidth=1.0, label="training range")
        ax.set_xlabel(xlabel)
        ax.set_title(label)
        right = ax.get_xlim()[1]
        ax.set_xlim(-MARGIN * right, right)  # sizes are ≥ 0; a ring of size 0 is not half cut
    _from_zero(axes[0])  # the panels share their y-axis
    axes[0].set_ylabel("return")
    _legend_below(fig, axes[1])
    if title:
        fig.suptitle(title)
    return fig


def _edges(centres: np.ndarray) -> np.ndarray:
    """Cell edges around (sorted) centres: midpoints, and half a step beyond the ends."""
    c = np.asarray(centres, float)
    if len(c) == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    mid = (c[1:] + c[:-1]) / 2
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


@styled
def bias_variance(
    fixed: pd.DataFrame,
    adarl_ranks: Sequence[float] | None = None,
    adarl_scores: Sequence[float] | None = None,
    intrinsic_rank: int | None = None,
    title: str = "",
) -> Figure:
    """Final return against the fixed rank of `sac-fixed-rank` runs (mean and 95% t interval
    over seeds), with AdaRL's converged rank marked: a vertical dashed line at its mean over
    seeds, the seeds' range shaded, and AdaRL's own return as a point when given.

    `fixed`: `rank, seed, score`.
    """
    fig = Figure(figsize=(COLUMN_WIDTH, 2.6), layout="constrained")
    ax = fig.add_subplot()
    ranks, values = _by_seed(fixed, "rank", "score")
    centre, low, high = t_interval(values)
    ax.errorbar(
        ranks,
        centre,
        yerr=[centre - low, high - centre],
        marker="o",
        markersize=3,
        capsize=2,
        label="SAC, fixed rank",
    )
    if adarl_ranks is not None and len(adarl_ranks):
        r = np.asarray(adarl_ranks, float)
        ax.axvline(
            r.mean(), color="C3", linestyle="--", label=f"AdaRL converged rank ({r.mean():.3g})"
        )
        if r.max() > r.min():
            ax.axvspan(r.min(), r.max(), color="C3", alpha=0.1, linewidth=0)
        if adarl_scores is not None and len(adarl_scores):
            s = np.asarray(adarl_scores, float)
            ax.plot(
                [r.mean()],
                [s.mean()],
                marker="*",
                markersize=9,
                color="C3",
                linestyle="none",
                label="AdaRL",
            )
    if intrinsic_rank is not None:
        ax.axvline(intrinsic_rank, label=f"$2d_a+1$ = {intrinsic_rank}", **INTRINSIC_STYLE)
    _log2_axis(ax, "x")
    ax.set_xlabel("rank of the bottleneck")
    ax.set_ylabel("final return (nominal dynamics)")
    ax.set_title(title or "bias–variance: return against rank")
    ax.legend(loc="best")
    return fig


@styled
def rank_rule_ablation(
    histories: Mapping[str, pd.DataFrame],
    intrinsic_rank: int | None = None,
    title: str = "",
    truncations: Sequence[int] = (),
) -> Figure:
    """Rank over training under each rank rule (one panel per layer, one line per rule with its
    band over seeds). `histories[rule]`: `step, seed, layer, rank`."""
    layers = sorted(set().union(*(h["layer"].unique() for h in histories.values())))
    fig, axes = _grid(len(layers), max_cols=3, sharey=True)
    for ax, layer in zip(axes, layers):
        for rule, history in histories.items():
            data = history[history["layer"] == layer]
            if data.empty:
                continue
            steps, values = _by_seed(data, "step", "rank")
            _band(ax, steps, values, rule, drawstyle="steps-post")
        _rank_axes(ax, layer, title, intrinsic_rank, truncations, legend=ax is axes[0])
    return fig


def network_spectrum(
    spectrum: Spectrum, layer: str, ranks: pd.DataFrame | None = None
) -> np.ndarray:
    """The singular values σ_1 ≥ σ_2 ≥ … of `layer`'s networks at `spectrum`'s truncation, mean
    over the seeds whose network has an i-th component.

    A network of rank r before the cut has r components; its stored spectrum is as wide as the
    widest network stored with it (the other seeds of its lane, and q1 and q2, which are stored
    stacked), the values past r being zeros (padding) or the SVD's noise on exactly-zero
    components (3e-05 at a σ_1 of a few). With `ranks` (truncations.csv's `step, seed, layer,
    old_rank`), seed s keeps σ_1…σ_{r_s}; without it, only the zeros are dropped."""
    values = np.sort(np.asarray(spectrum.layers[layer], float), axis=-1)[:, ::-1]
    values = np.where(values > 0, values, np.nan)
    if ranks is not None and not ranks.empty and "old_rank" in ranks:
        rows = ranks[(ranks["step"] == spectrum.step) & (ranks["layer"] == layer)]
        by_seed = dict(zip(rows["seed"].astype(int), rows["old_rank"].astype(float)))
        kept = np.array([by_seed.get(int(s), np.inf) for s in spectrum.seeds], float)
        if len(kept) == len(values):
            values = np.where(np.arange(values.shape[1])[None, :] < kept[:, None], values, np.nan)
    counts = np.isfinite(values).sum(axis=0)
    sigma = np.where(counts > 0, np.nansum(values, axis=0) / np.maximum(counts, 1), np.nan)
    present = np.flatnonzero(counts > 0)
    return sigma[: present[-1] + 1] if len(present) else sigma[:0]


@styled
def singular_value_spectra(
    spectra: Sequence[Spectrum], title: str = "", ranks: pd.DataFrame | None = None
) -> Figure:
    """Singular values of each bottleneck (one panel per layer) at each truncation (one line
    per truncation step, light to dark), on a log scale: each network's own components only
    (`network_spectrum`; `ranks`: truncations.csv), mean over seeds."""
    layers = sorted(set().union(*(s.layers for s in spectra)))
    fig, axes = _grid(len(layers), max_cols=3)
    cmap = matplotlib.colormaps["viridis"]
    for ax, layer in zip(axes, layers):
        steps = [s for s in spectra if layer in s.layers]
        for i, spectrum in enumerate(steps):
            sigma = network_spectrum(spectrum, layer, ranks)
            colour = cmap(i / max(len(steps) - 1, 1))
            ax.plot(
                np.arange(1, len(sigma) + 1), sigma, color=colour, label=f"step {spectrum.step}"
            )
        ax.set_yscale("log")
        ax.set_title(f"{title}: {layer}" if title else layer)
        ax.set_xlabel("index i")
        ax.set_ylabel("singular value σ_i")
        ax.legend(loc="best")
    return fig


@styled
def aggregate_intervals(estimates: pd.DataFrame, xlabel: str = "normalised score") -> Figure:
    """Point estimates with 95% bootstrap intervals, one panel per metric (IQM, mean), one row
    per method. `estimates`: `method, metric, point, low, high`."""
    metrics = list(dict.fromkeys(estimates["metric"]))
    methods = sort_methods(estimates["method"].unique())[::-1]
    colours = method_colours(methods)
    fig = Figure(figsize=(FULL_WIDTH, 0.35 * len(methods) + 0.9), layout="constrained")
    axes = fig.subplots(1, len(metrics), squeeze=False, sharey=True).ravel()
    for ax, metric in zip(axes, metrics):
        rows = estimates[estimates["metric"] == metric].set_index("method")
        for y, method in enumerate(methods):
            if method not in rows.index:
                continue
            r = rows.loc[method]
            ax.plot(
                [r["low"], r["high"]],
                [y, y],
                color=colours[method],
                linewidth=5,
                alpha=0.5,
                solid_capstyle="butt",
            )
            ax.plot([r["point"]], [y], marker="|", color="black", markersize=10, label=method)
        ax.set_yticks(range(len(methods)), methods)
        ax.set_title(metric)
        ax.set_xlabel(xlabel)
    return fig


@styled
def performance_profiles(
    taus: np.ndarray,
    profiles: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
) -> Figure:
    """Performance profiles: fraction of runs scoring above τ, one line per method with its
    95% bootstrap band. `profiles[method] = (profile, low, high)` over `taus`."""
    colours = method_colours(list(profiles))
    fig = Figure(figsize=(COLUMN_WIDTH, 2.6), layout="constrained")
    ax = fig.add_subplot()
    for method in sort_methods(profiles):
        p, lo, hi = profiles[method]
        ax.plot(taus, p, label=method, color=colours[method])
        ax.fill_between(taus, lo, hi, color=colours[method], alpha=0.2, linewidth=0)
    ax.set_xlabel("normalised score τ")
    ax.set_ylabel("fraction of runs with score > τ")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title("performance profiles")
    ax.legend(loc="best")
    return fig


@styled
def probability_of_improvement(
    estimates: pd.DataFrame, reference: str = registry.REFERENCE
) -> Figure:
    """P(reference > baseline) with 95% bootstrap intervals, one row per baseline.
    `estimates`: `baseline, point, low, high`."""
    baselines = sort_methods(estimates["baseline"].unique())[::-1]
    fig = Figure(figsize=(COLUMN_WIDTH, 0.35 * len(baselines) + 0.9), layout="constrained")
    ax = fig.add_subplot()
    rows = estimates.set_index("baseline")
    for y, baseline in enumerate(baselines):
        r = rows.loc[baseline]
        ax.plot(
            [r["low"], r["high"]], [y, y], color="C0", linewidth=5, alpha=0.5, solid_capstyle="butt"
        )
        ax.plot([r["point"]], [y], marker="|", color="black", markersize=10)
    ax.axvline(0.5, color="grey", linestyle=":", linewidth=1.0)
    ax.set_yticks(range(len(baselines)), [f"P({reference} > {b})" for b in baselines])
    ax.set_xlim(0, 1)
    ax.set_xlabel("probability of improvement")
    ax.set_title(f"probability of improvement of {reference}")
    return fig


@styled
def learning_rate_schedules(
    total_steps: int = 3_000_000, truncate_every: int = 1_000_000, points: int = 3_001
) -> Figure:
    """The actor's learning rate over an AdaRL run of `total_steps` steps and d_t =
    `truncate_every` (default: the paper's Hopper schedule) under `--lr-schedule envelope` and
    `restart`, computed by `schedule.learning_rate` itself (the training's own schedule) at the
    config's defaults; warm-ups drawn to scale."""
    from adarl.algos import schedule
    from adarl.algos.sac_config import SAC_FAMILY, SACConfig

    config = SACConfig(
        total_steps=total_steps, truncate_every=truncate_every, **SAC_FAMILY["adarl"]
    )
    total_updates, warmup = schedule.total_updates(config), config.warmup_steps
    cut_updates = schedule.truncation_updates(config)
    t = np.unique(
        np.concatenate(
            [
                np.linspace(0, total_updates - 1, points),
                *[np.linspace(k, k + 2 * warmup, 50) for k in cut_updates],
            ]
        )
    )
    state = schedule.counters(config, t)  # the update's counters after t updates

    def rate(name: str) -> np.ndarray:
        c = dataclasses.replace(config, lr_schedule=name)
        return np.asarray(schedule.learning_rate(c, config.lr_actor, state))

    envelope, restart = rate("envelope"), rate("restart")
    fig = Figure(figsize=(COLUMN_WIDTH, PANEL_HEIGHT), layout="constrained")
    ax = fig.add_subplot()
    ax.plot(t, envelope, label="envelope (default)")
    ax.plot(t, restart, label="restart", linestyle="--")
    for k in cut_updates:
        ax.axvline(k, **TRUNCATION_STYLE)
    ax.set_xlabel("gradient step")
    ax.set_ylabel("learning rate")
    ax.legend(loc="lower left")
    return fig
