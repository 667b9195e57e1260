"""Robustness sections: one-parameter sweeps (`adarl evaluate --sweep`), robustness suites
(`--suite`) with their heatmaps, and return against the size of the perturbation."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from adarl import stats
from adarl.evaluation import suites
from adarl.report import common, figures, tables
from adarl.report.common import (
    ReportOptions,
    Section,
    csv_text,
    interval_text,
    number_text,
    slug,
    write_file,
)
from adarl.results import collect
from adarl.results.runs import Run, sort_methods, sort_tasks
from adarl.runs import layout


def worst_and_average(
    summaries: pd.DataFrame, confidence: float = 0.95
) -> dict[str, tuple[float, float, float]]:
    """Mean over seeds of the worst-case and of the average return, each with its Student-t
    interval over seeds x̄ ± t_{(1+c)/2, n−1} · s/√n (`adarl.stats.mean_ci`; NaN bounds
    for one seed): {"worst": (point, low, high), "average": (...)}."""
    out = {}
    for column in ("worst", "average"):
        ci = stats.mean_ci(summaries[column].to_numpy(float), confidence)
        out[column] = (ci.point, ci.low, ci.high)
    return out


def heatmap_grid(table: pd.DataFrame, x: str, y: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x values, y values, mean return over seeds of each seed's point mean, shape (ny, nx))
    of a two-parameter suite's table."""
    means = suites.point_means(table)
    cells = (
        means.groupby([layout.param_column(y), layout.param_column(x)])["return"].mean().unstack()
    )
    return cells.columns.to_numpy(float), cells.index.to_numpy(float), cells.to_numpy(float)


def base_point(table: pd.DataFrame, parameter: str, dynamics: str | None) -> str:
    """The point a one-parameter sweep moves `parameter` away from: its base dynamics and the
    value of every other parameter the episodes recorded (`p_*`; "varies" where not one value):
    `nominal dynamics; foot_length 0.39, thigh_length 0.45`."""
    others = []
    for column in sorted(
        set(layout.param_columns(table.columns)) - {layout.param_column(parameter)}
    ):
        values = table[column].dropna().unique()
        value = f"{float(values[0]):.4g}" if len(values) == 1 else "varies"
        others.append(f"{layout.param_name(column)} {value}")
    return f"{dynamics or 'nominal'} dynamics" + (f"; {', '.join(others)}" if others else "")


def robustness_section(runs: list[Run], folder: Path, colours, notes: list[str]) -> Section:
    groups: dict[tuple[str, str, str], list[pd.DataFrame]] = {}
    held: dict[tuple[str, str, str], str] = {}
    bases: dict[tuple[str, str, str], str] = {}
    bounds: dict[tuple[str, str, str], tuple[float, float]] = {}
    nominal: dict[tuple[str, str], float] = {}
    for r in runs:
        for ev in collect.evaluations(r):
            swept = ev.swept
            if not swept:
                for c in layout.param_columns(ev.table.columns):
                    if ev.meta.get("dynamics") == "nominal" and not ev.meta.get("hold"):
                        nominal[(r.task, layout.param_name(c))] = float(ev.table[c].iloc[0])
                continue
            if len(swept) > 1:
                if ev.meta.get("suite"):
                    continue  # the suites section reports it
                notes.append(
                    f"{r.path}/evaluations/{ev.name}.csv sweeps {len(swept)} parameters; "
                    "only one-parameter sweeps are drawn."
                )
                continue
            param = swept[0]
            values = _swept_values(ev.table, param)
            per_seed = (
                ev.table.assign(value=values)
                .groupby(["seed", "value"], as_index=False)["return"]
                .mean()
            )
            key = (r.task, ev.name, param)
            groups.setdefault(key, []).append(per_seed.assign(method=r.label))
            if (r.task, param) not in nominal:  # no nominal evaluation recorded it: the task's
                value = common.nominal_value(r, param)
                if value is not None:
                    nominal[(r.task, param)] = value
            limit = ev.meta.get("max_episode_steps")
            found = common.return_bounds(r, int(limit) if limit else None)
            bounds[key] = common.widest_bounds(bounds.get(key), found)
            held[key] = ", ".join(f"{k}={v:g}" for k, v in (ev.meta.get("hold") or {}).items())
            base = base_point(ev.table, param, ev.meta.get("dynamics"))
            if bases.setdefault(key, base) != base:
                bases[key] = "differs between the runs drawn"
    if not groups:
        return Section(
            "Robustness",
            "No sweeps found; run `adarl evaluate RUN --sweep P=LO..HI:N` to add them.\n",
        )
    files, lines = [], []
    order = sort_tasks(k[0] for k in groups)
    for key in sorted(groups, key=lambda k: (order.index(k[0]), k[1], k[2])):
        task, name, param = key
        data = pd.concat(groups[key], ignore_index=True)
        title = f"{task}: {param}" + (f" (held: {held[key]})" if held[key] else "")
        value = nominal.get((task, param))
        fig = figures.robustness_curve(data, param, title, value, colours, bases[key], bounds[key])
        files += common.save_figure(folder, fig, f"robustness_{task}_{name}")
        at = "" if value is None else f"; nominal {value:.4g}"
        lines.append(f"- {title}: {', '.join(sort_methods(data['method'].unique()))}{at}")
    per_task: dict[str, tuple[float, float]] = {}
    for key in groups:
        per_task[key[0]] = common.widest_bounds(per_task.get(key[0]), bounds[key])
    band = common.band_text({t: per_task[t] for t in order})
    text = (
        "Return against each swept parameter: the mean over seeds of each seed's mean over "
        f"episodes, with a {band}, on a y-axis that includes 0. Grey dotted line: the nominal "
        "value (the task's `nominal` dynamics); the legend is above the axes; under each figure, "
        "its base point (the dynamics and the values of the parameters not swept).\n\n"
        + "\n".join(lines)
        + "\n"
    )
    return Section("Robustness", text, files)


def suites_section(runs: list[Run], folder: Path, options: ReportOptions, colours=None) -> Section:
    """Worst-case and average return over each robustness suite's grid (`adarl evaluate
    --suite`), mean over seeds with bootstrap intervals; a heatmap per two-parameter suite and,
    for suites over the training parameters, return against the size of the perturbation."""
    found: dict[tuple[str, str, str], list[tuple[pd.DataFrame, pd.DataFrame]]] = {}
    bounds: dict[str, tuple[float, float]] = {}
    for r in runs:
        for ev in collect.evaluations(r):
            name = ev.meta.get("suite")
            if name and ev.meta.get("final_checkpoint", True):
                summary = suites.seed_summary(ev.table, name)
                found.setdefault((r.task, name, r.label), []).append((summary, ev.table))
                limit = ev.meta.get("max_episode_steps")
                found_bounds = common.return_bounds(r, int(limit) if limit else None)
                bounds[r.task] = common.widest_bounds(bounds.get(r.task), found_bounds)
    title = "Robustness suites"
    if not found:
        return Section(
            title,
            "No suite evaluations found; run `adarl evaluate RUN --suite NAME` to add them.\n",
        )
    conf = options.confidence
    order = sort_tasks(k[0] for k in found)
    methods = sort_methods(k[2] for k in found)
    keys = sorted(found, key=lambda k: (order.index(k[0]), k[1], methods.index(k[2])))
    rows, files = [], []
    for task, name, method in keys:
        summary = pd.concat([s for s, _ in found[(task, name, method)]], ignore_index=True)
        estimate = worst_and_average(summary, conf)
        rows.append(
            {
                "task": task,
                "suite": name,
                "method": method,
                "seeds": len(summary),
                "points": int(summary["points"].max()),
                "episodes": int(summary["episodes"].min()),
                **{f"{k}_{part}": v for k, e in estimate.items() for part, v in zip(("mean", "low", "high"), e)},
            }
        )  # fmt: skip
        suite = suites.get_suite(name, task)
        if len(suite.ranges) == 2:
            table = pd.concat([t for _, t in found[(task, name, method)]], ignore_index=True)
            x, y = suite.ranges[1].param, suite.ranges[0].param
            fig = figures.suite_heatmap(
                *heatmap_grid(table, x, y), x, y, f"{task}, {name}: {method}"
            )
            files += common.save_figure(folder, fig, f"suite_{task}_{name}_{method}")
    size_files, size_text = size_curves(found, keys, folder, options, colours, bounds)
    files += size_files
    df = pd.DataFrame(rows)
    files.insert(0, write_file(folder, "tables/suites.csv", csv_text(df)))
    md = tables.markdown_table(
        ["task", "suite", "method", "seeds", "points × episodes", "worst-case", f"{conf:.0%} CI",
         "average", f"{conf:.0%} CI"],
        [
            [row.task, row.suite, row.method, row.seeds, f"{row.points} × {row.episodes}",
             *interval_text(row.worst_mean, row.worst_low, row.worst_high, 1),
             *interval_text(row.average_mean, row.average_low, row.average_high, 1)]
            for row in df.itertuples()
        ],
    )  # fmt: skip
    files.insert(1, write_file(folder, "tables/suites.md", md))
    text = (
        "Per seed, the worst-case return is the lowest and the average return the mean, over "
        "the suite's grid points, of the mean return over each point's episodes (as M2TD3 and "
        "RRLS report them; suites and sources: docs/evaluation.md). Shown: the mean over seeds "
        f"with a {conf:.0%} Student-t interval over seeds (none from one seed). "
        "Heatmaps: two-parameter suites, mean over seeds, the worst point circled.\n\n"
    )
    return Section(title, text + md + size_text, files)


def size_curves(
    found: dict, keys: list, folder: Path, options: ReportOptions, colours=None, bounds=None
) -> tuple[list[Path], str]:
    """Return against the size of the perturbation (`adarl.report.perturbation`) for every
    task × suite whose parameters all have a training range: one figure and one table each,
    `figures/robustness_size_<task>_<suite>`, `tables/robustness_size_<task>_<suite>.csv`;
    bands within `bounds[task]` (the returns the task can give) where given."""
    bounds = bounds or {}
    from adarl.report import perturbation

    curves: dict[tuple[str, str], list[pd.DataFrame]] = {}
    for task, name, method in keys:
        params = [r.param for r in suites.get_suite(name, task).ranges]
        box = perturbation.training_box(task, params)
        if box is None:
            continue
        table = pd.concat([t for _, t in found[(task, name, method)]], ignore_index=True)
        rings = perturbation.ring_returns(suites.point_means(table), params, *box)
        curves.setdefault((task, name), []).append(rings.assign(method=method))
    files, lines = [], []
    for (task, name), frames in curves.items():
        data = pd.concat(frames, ignore_index=True)
        stem = f"robustness_size_{task}_{name}"
        fig = figures.robustness_size_curve(
            data, f"{task}, suite {name}", colours, bounds=bounds.get(task, figures.UNBOUNDED)
        )
        files += common.save_figure(folder, fig, stem)
        summary = perturbation.ring_summary(data, options.confidence)
        order = sort_methods(summary["method"].unique())
        summary = summary.sort_values(
            ["method", "ring"], key=lambda c: c.map(order.index) if c.name == "method" else c
        )
        files.append(write_file(folder, f"tables/{slug(stem)}.csv", csv_text(summary)))
        rings = perturbation.describe_rings(data)
        sizes = ", ".join(f"{ring:.3g} ({count})" for ring, count in rings.items())
        lines.append(f"{task}, {name}: rings (grid points) {sizes}; `figures/{slug(stem)}`\n")
        cells = summary.pivot(index="method", columns="ring", values="mean_mean").loc[order]
        worst = summary.groupby("method")["worst_within_mean"].last().loc[order]
        lines.append(
            tables.markdown_table(
                ["mean return at size", *(f"{ring:.3g}" for ring in cells.columns),
                 f"worst within {cells.columns[-1]:.3g}"],
                [[m, *(number_text(v) for v in cells.loc[m]), number_text(worst[m])] for m in order],
            )
        )  # fmt: skip
    if not lines:
        return files, ""
    band = common.band_text({task: bounds.get(task, figures.UNBOUNDED) for task, _ in curves})
    text = (
        "\n\n**Return against the size of the perturbation.** The size of a grid point is "
        "max_i |p_i − c_i| / a_i, its distance from the nominal point c in units of each "
        "parameter's training half-range a (1 = the edge of the training range; "
        "docs/evaluation.md). Left: per seed, the mean return over the points of each size "
        "(a ring); right: the worst point of size ≤ r, the worst-case return of the training box "
        f"scaled by r. Mean over seeds with a {band}, the legend under the panels; "
        f"{options.confidence:.0%} intervals in `tables/robustness_size_<task>_<suite>.csv`.\n\n"
        + "\n".join(lines)
        + "\n"
    )
    return files, text


def _swept_values(table: pd.DataFrame, param: str) -> np.ndarray:
    column = layout.param_column(param)
    if column in table:
        return table[column].to_numpy(float).round(9)
    pattern = re.compile(rf"(?:^|[:,]){re.escape(param)}=([^,]+)")
    return np.array([float(pattern.search(str(label)).group(1)) for label in table["dynamics"]])
