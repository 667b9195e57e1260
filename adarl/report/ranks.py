"""Sections on training and rank: training curves, rank over training and where it settled,
bias–variance (fixed-rank sweep), rank-rule ablation, singular-value spectra, policy size."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from adarl.algos import registry
from adarl.errors import UsageError
from adarl.report import common, figures, tables
from adarl.report.common import REFERENCE, Section, csv_text, slug, write_file
from adarl.results import collect
from adarl.results.runs import Run, config_value, sort_tasks
from adarl.runs.layout import TRUNCATIONS_CSV


def intrinsic_rank(run: Run) -> int | None:
    """2·d_a+1 of the run's task (from `adarl.envs`, made as the run made it: its env_kwargs and
    env_module; else, as for an env-module the user did not name, which is never imported, from
    the action size of its final policy file; else the config), None if unknown."""
    try:
        from adarl.envs.tasks import task_of

        return int(task_of({**dict(run.config), "task": run.task}).intrinsic_rank)
    except (ImportError, AttributeError, KeyError, TypeError, UsageError):
        pass
    try:
        from adarl.policy import load
        from adarl.runs.checkpoints import policy_files, select_checkpoint

        path = next(iter(policy_files(select_checkpoint(run.path)).values()))
        return 2 * int(load(path).low.shape[0]) + 1
    except (StopIteration, OSError, ValueError, KeyError):  # UsageError: a ValueError
        value = config_value(run.config, "intrinsic_rank")
        return None if value is None else int(value)


def training_section(runs: list[Run], folder: Path, colours) -> Section:
    curves: dict[str, dict[str, list[pd.DataFrame]]] = {}
    truncations: dict[str, set[int]] = {}
    bounds: dict[str, tuple[float, float]] = {}
    sources = set()
    for r in runs:
        curve, source = collect.training_curve(r)
        if curve.empty:
            continue
        sources.add(source)
        curves.setdefault(r.task, {}).setdefault(r.label, []).append(curve)
        truncations.setdefault(r.task, set()).update(collect.truncation_steps(r))
        bounds[r.task] = common.widest_bounds(bounds.get(r.task), common.return_bounds(r))
    if not curves:
        return Section("Training curves", "No evaluation or episode logs found.\n", empty=True)
    tasks = sort_tasks(curves)
    merged = {t: {m: pd.concat(frames) for m, frames in curves[t].items()} for t in tasks}
    fig = figures.training_curves(
        merged, {t: sorted(truncations.get(t, ())) for t in tasks}, colours, bounds=bounds
    )
    files = common.save_figure(folder, fig, "training_curves")
    band = common.band_text({t: bounds[t] for t in tasks})
    text = (
        "Return over training (source: " + "; ".join(sorted(sources)) + "), mean over seeds with a "
        f"{band}; markers where a curve has at most {figures.FEW_POINTS} points; red dashed lines "
        "mark the steps at which rank-adaptive runs truncated; the legend is under the panels.\n"
    )
    return Section("Training curves", text, files)


def rank_section(runs: list[Run], folder: Path) -> Section:
    files, lines = [], []
    for r in runs:
        history, steps = collect.rank_history(r), collect.truncation_steps(r)
        if history.empty or not steps:
            continue
        intrinsic = intrinsic_rank(r)
        end = max(float(history["step"].max()), float(collect.final_step(r) or 0))
        fig = figures.rank_trajectories(history, intrinsic, f"{r.task} {r.label}", steps, end)
        files += common.save_figure(folder, fig, f"ranks_{r.task}_{r.label}")
        final = collect.final_ranks(r)
        per_layer = final.groupby("layer")["rank"].agg(lambda s: " ".join(str(int(v)) for v in s))
        lines.append(
            f"- {r.task} {r.label} ({r.path}): final rank per seed — "
            + "; ".join(f"{layer}: {ranks}" for layer, ranks in per_layer.items())
            + f"; intrinsic rank 2·d_a+1 = {intrinsic}"
        )
    if not files:
        return Section("Rank over training", "No rank-adaptive runs.\n", empty=True)
    table, md = settling_table(runs)
    files.append(write_file(folder, "tables/rank_settling.md", md))
    files.append(write_file(folder, "tables/rank_settling.csv", csv_text(table)))
    text = (
        "Estimated rank of each bottleneck, per seed, from the initial rank through every cut "
        "(truncations.csv's old and new ranks at each cut's step) to the run's last step; dotted "
        "line: 2·d_a+1.\n\n"
        + "\n".join(lines)
        + "\n\nWhere the ranks stopped (per bottleneck, over seeds): the final rank (mean and "
        "range), the truncations that cut it and the cuts the retain clause refused (totals "
        "over seeds), the median step of its last cut, and how many seeds kept their rank at "
        "the last truncation (settled).\n\n" + md
    )
    return Section("Rank over training", text, files)


def settling_table(runs: list[Run]) -> tuple[pd.DataFrame, str]:
    """One row per run and bottleneck summarising `collect.rank_settling` over seeds."""
    rows = []
    for r in runs:
        settling = collect.rank_settling(r)
        for layer, g in settling.groupby("layer", sort=True):
            rows.append(
                {
                    "task": r.task,
                    "method": r.label,
                    "layer": layer,
                    "intrinsic_rank": intrinsic_rank(r),
                    "final_rank_mean": float(g["final_rank"].mean()),
                    "final_rank_min": int(g["final_rank"].min()),
                    "final_rank_max": int(g["final_rank"].max()),
                    "truncations": int(g["truncations"].max()),
                    "cuts": int(g["cuts"].sum()),
                    "retained": int(g["retained"].sum()),
                    "median_last_cut": float(g["last_change"].median()),
                    "settled_seeds": int(g["settled"].sum()),
                    "seeds": len(g),
                }
            )
    table = pd.DataFrame(rows)
    md = tables.markdown_table(
        [
            "task",
            "method",
            "layer",
            "2·d_a+1",
            "final rank",
            "truncations",
            "cuts",
            "retained",
            "last cut (median step)",
            "settled",
        ],
        [
            [
                row.task,
                row.method,
                row.layer,
                str(row.intrinsic_rank),
                f"{row.final_rank_mean:.1f} ({row.final_rank_min}–{row.final_rank_max})",
                str(row.truncations),
                str(row.cuts),
                str(row.retained),
                "—" if np.isnan(row.median_last_cut) else f"{row.median_last_cut:,.0f}",
                f"{row.settled_seeds}/{row.seeds}",
            ]
            for row in table.itertuples()
        ],
    )
    return table, md


def bias_variance_section(fixed: list[Run], runs: list[Run], finals: dict, folder: Path) -> Section:
    if not fixed:
        return Section("Bias–variance", "No `sac-fixed-rank` runs.\n", empty=True)
    files, texts = [], []
    for task in sort_tasks(r.task for r in fixed):
        frames = []
        for r in (r for r in fixed if r.task == task):
            scores = finals[r.path][0]
            rank = config_value(r.config, "rank")
            if not scores.empty and rank is not None:
                frames.append(scores.assign(rank=int(rank)))
        if not frames:
            continue
        data = pd.concat(frames, ignore_index=True)
        adarl = [r for r in runs if r.task == task and r.label == REFERENCE]
        ranks, adarl_scores = [], []
        for r in adarl:
            final = collect.final_ranks(r)
            actor = final[final["layer"].str.startswith("actor")] if not final.empty else final
            ranks += (actor if not actor.empty else final)["rank"].astype(float).tolist()
            adarl_scores += finals[r.path][0]["score"].tolist()
        intrinsic = intrinsic_rank(next(r for r in fixed if r.task == task))
        fig = figures.bias_variance(
            data, ranks or None, adarl_scores or None, intrinsic, f"{task}: return against rank"
        )
        files += common.save_figure(folder, fig, f"bias_variance_{task}")
        table = tables.score_table(
            data.assign(task=task, method=data["rank"].map(lambda k: f"r={k}"))
        )
        rows = [[f"r={k}", table.cell(task, f"r={k}")] for k in sorted(data["rank"].unique())]
        md = tables.markdown_table(["rank", f"{task}: score"], rows)
        texts.append(md)
        files.append(write_file(folder, f"tables/fixed_rank_{slug(task)}.md", md))
        files.append(
            write_file(
                folder,
                f"tables/fixed_rank_{slug(task)}.csv",
                data.to_csv(index=False, float_format="%.6g"),
            )
        )
        if ranks:
            texts.append(
                f"AdaRL's converged actor rank on {task}: {', '.join(f'{v:g}' for v in ranks)} (per seed).\n"
            )
    text = (
        "Nominal score (Table 1's) of SAC with a fixed-rank bottleneck, against the rank (mean and 95% t "
        "interval over seeds); AdaRL's converged rank is marked.\n\n" + "\n".join(texts)
    )
    return Section("Bias–variance", text, files)


def ablation_section(runs: list[Run], folder: Path) -> Section:
    files, lines = [], []
    adarl = [r for r in runs if registry.role(r.algo, "adapts_rank")]
    for task in sort_tasks(r.task for r in adarl):
        histories: dict[str, list[pd.DataFrame]] = {}
        steps: set[int] = set()
        for r in (r for r in adarl if r.task == task):
            history = collect.rank_history(r)
            if not history.empty:  # one line per variant (rule, retain tolerance)
                histories.setdefault(r.label, []).append(history)
                steps.update(collect.truncation_steps(r))
        if len(histories) < 2:
            continue
        merged = {rule: pd.concat(h, ignore_index=True) for rule, h in sorted(histories.items())}
        fig = figures.rank_rule_ablation(
            merged, intrinsic_rank(next(r for r in adarl if r.task == task)), task, sorted(steps)
        )
        files += common.save_figure(folder, fig, f"rank_rule_ablation_{task}")
        for rule, h in merged.items():
            last = h.sort_values("step").groupby(["seed", "layer"])["rank"].last()
            per_layer = last.groupby("layer").mean()
            ranks = ", ".join(f"{layer} {value:.3g}" for layer, value in per_layer.items())
            lines.append(f"- {task}, {rule}: final rank (mean over seeds): {ranks}")
    if not files:
        return Section(
            "Rank-rule ablation",
            "Needs `adarl` runs with both rank rules on one task.\n",
            empty=True,
        )
    return Section(
        "Rank-rule ablation",
        "Rank over training under each rank rule (mean over seeds, 95% t band).\n\n"
        + "\n".join(lines)
        + "\n",
        files,
    )


def spectra_section(runs: list[Run], folder: Path) -> Section:
    files = []
    for r in runs:
        found = collect.spectra(r)
        if found:
            cuts = collect.read_table(r.path / TRUNCATIONS_CSV)  # each network's rank before
            fig = figures.singular_value_spectra(found, f"{r.task} {r.label}", cuts)
            files += common.save_figure(folder, fig, f"spectra_{r.task}_{r.label}")
    text = (
        "Singular values of each bottleneck at each truncation, up to its rank before the cut "
        "(mean over seeds).\n"
        if files
        else "No spectra recorded.\n"
    )
    return Section("Singular-value spectra", text, files, empty=not files)


def policy_size_section(runs: list[Run], folder: Path) -> Section:
    frames = [
        collect.policy_sizes(r).assign(run=str(r.path), task=r.task, method=r.label) for r in runs
    ]
    data = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    if data.empty:
        return Section("Policy size", "No policy files found.\n", empty=True)
    rows = []
    for (run, task, method), g in data.groupby(["run", "task", "method"], sort=False):
        after, before = g["n_params"].to_numpy(), g["n_params_full"].to_numpy()
        span = f"{after.min()}" if after.min() == after.max() else f"{after.min()}–{after.max()}"
        rows.append(
            [
                task,
                method,
                run,
                int(before.max()),
                span,
                f"{100 * after.mean() / before.mean():.1f}%",
            ]
        )
    md = tables.markdown_table(
        ["task", "method", "run", "full rank", "after adaptation", "kept"], rows
    )
    files = [
        write_file(folder, "tables/policy_size.csv", data.to_csv(index=False)),
        write_file(folder, "tables/policy_size.md", md),
    ]
    text = (
        "Parameters of the deterministic policy (as exported by `adarl export`) at full rank and at the "
        "final checkpoint, over seeds.\n\n" + md
    )
    return Section("Policy size", text, files)
