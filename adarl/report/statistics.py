"""The statistics of the scores table: aggregate IQM/mean (rliable), per-task means,
differences from the reference with power, probability of improvement, performance
profiles."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from adarl.report import common, compare, figures, tables
from adarl.report.common import (
    PROFILE_TAUS,
    REFERENCE,
    ReportOptions,
    ScoreNote,
    Section,
    ci_text,
    csv_text,
    final_checkpoint_scores,
    number_text,
    rounded,
    write_file,
)
from adarl.results.runs import sort_methods


def statistics_sections(
    scores: pd.DataFrame,
    folder: Path,
    options: ReportOptions,
    notes: list[str],
    score_note: ScoreNote = ScoreNote(),
) -> list[Section]:
    """Aggregate IQM/mean, per-task means, per-task differences from the reference,
    probability of improvement, performance profiles: each only where it carries information
    (intervals need two seeds; aggregates, profiles and comparisons need two methods)."""
    if scores.empty:
        return []
    methods = sort_methods(scores["method"])
    several_seeds = bool(scores.groupby(["task", "method"]).size().max() >= 2)
    if not several_seeds:
        notes.append(
            "One seed per task and method: no intervals, no per-task statistics, aggregates, "
            "profiles or comparisons (they need at least two seeds)."
        )
        return []
    sections = []
    if len(methods) < 2:
        notes.append(
            "One method: no aggregate statistics, performance profiles, differences or "
            "probability of improvement (they compare methods)."
        )
        return [per_task_section(scores, folder, options, score_note)]
    normalised = compare.normalise(scores)
    if normalised.left_out:
        notes.append(
            "Aggregate statistics and performance profiles cover methods run on every task "
            f"({', '.join(normalised.tasks)}); left out: {', '.join(normalised.left_out)}."
        )
    for m in normalised.uneven:
        notes.append(
            f"{m}: tasks have different seed counts; aggregates use as many seeds per task as "
            "the task with the fewest."
        )
    if len(normalised.matrices) >= 2:
        sections.append(aggregate_section(scores, normalised, folder, options, score_note))
    sections.append(per_task_section(scores, folder, options, score_note))
    if REFERENCE in methods:
        differences = compare.difference_estimates(
            scores, REFERENCE, options.confidence, options.target_difference, options.power,
            options.alpha,
        )  # fmt: skip
        if not differences.empty:
            sections.append(differences_section(differences, folder, options))
        sections.append(improvement_section(scores, differences, folder, options))
    else:
        notes.append(
            f"No {REFERENCE!r} runs: differences and probability of improvement are not computed."
        )
    if len(normalised.matrices) >= 2:
        sections.append(profile_section(normalised, folder, options))
    return sections


def power_text(options: ReportOptions) -> str:
    level = f"{options.power:.0%}"
    return (
        f"**Power.** “detectable at {level}”: the smallest true difference of mean return that "
        f"a two-sided two-sample t-test at α = {options.alpha:g} detects with probability "
        f"{level} with the seeds at hand, given the pooled SD of the two arms (noncentral t; "
        "`stats.minimum_detectable_difference`); a real difference smaller than that is likely "
        f"to go unseen. “seeds for {options.target_difference:g}”: the seeds per arm a "
        f"difference of {options.target_difference:g} would need at that power and SD "
        "(`stats.seeds_per_arm`). p: exact two-sided permutation test of the difference of "
        "means (every split of the pooled seeds; with 3 seeds a side no p is below 0.1)."
    )


def aggregate_section(
    scores: pd.DataFrame,
    normalised: compare.Normalised,
    folder: Path,
    options: ReportOptions,
    score_note: ScoreNote = ScoreNote(),
) -> Section:
    reps, conf = options.bootstrap_reps, options.confidence
    estimates = compare.aggregate_estimates(normalised, reps, conf, options.seed)
    at_final = final_checkpoint_scores(scores)
    if not at_final.empty:
        final = compare.aggregate_estimates(compare.normalise(at_final), reps, conf, options.seed)
        final = final.rename(
            columns={"point": "final_point", "low": "final_low", "high": "final_high"}
        )
        estimates = estimates.merge(
            final[["method", "metric", "final_point", "final_low", "final_high"]],
            on=["method", "metric"], how="left",
        )  # fmt: skip
    title = "Aggregate statistics (rliable)"
    text = (
        "Scores min–max normalised per task over all methods and seeds (0 = the lowest, "
        f"1 = the highest seed's score on that task), then aggregated over "
        f"{len(normalised.tasks)} task(s) and their seeds. Intervals: {conf:.0%} stratified "
        f"bootstrap ({reps} resamples, seed {options.seed}).\n\n"
    )
    files = [write_file(folder, "tables/aggregate.csv", csv_text(estimates))]
    rows = []
    for method, matrix in normalised.matrices.items():
        by_metric = estimates[estimates["method"] == method].set_index("metric")
        cells = [method]
        for metric in ("IQM", "Mean"):
            point, low, high = by_metric.loc[metric, ["point", "low", "high"]]
            cells += [f"{point:.3f}", ci_text(low, high, 3) if matrix.shape[0] > 1 else tables.DASH]
        for metric in ("IQM", "Mean"):
            value = by_metric.loc[metric].get("final_point", np.nan)
            cells.append(f"{value:.3f}" if np.isfinite(value) else tables.DASH)
        rows.append([*cells, f"{matrix.shape[0]} × {matrix.shape[1]}"])
    header = ["method", "IQM", f"IQM {conf:.0%} CI", "mean", f"mean {conf:.0%} CI",
              "IQM, final checkpoint", "mean, final checkpoint", "seeds × tasks"]  # fmt: skip
    md = tables.markdown_table(header, rows)
    line = score_note.line("the columns “…, final checkpoint” (intervals in aggregate.csv)")
    line = f"\n{line}\n" if line else ""
    files.append(write_file(folder, "tables/aggregate.md", md + line))
    files += common.save_figure(
        folder, figures.aggregate_intervals(estimates), "aggregate_iqm_mean"
    )
    return Section(title, text + md + line, files)


def per_task_section(
    scores: pd.DataFrame, folder: Path, options: ReportOptions, score_note: ScoreNote = ScoreNote()
) -> Section:
    conf = options.confidence
    estimates = compare.per_task_estimates(scores, conf)
    has_final = "final_mean" in estimates
    rows = []
    for r in estimates.itertuples():
        final = (
            f"{r.final_mean:.1f} {ci_text(r.final_low, r.final_high, 1)}".replace(
                f" {tables.DASH}", ""
            )
            if has_final and np.isfinite(r.final_mean)
            else tables.DASH
        )
        rows.append(
            [r.task, r.method, r.seeds, f"{r.mean:.1f}", ci_text(r.mean_low, r.mean_high, 1),
             number_text(r.sd), f"{r.iqm:.1f}", final]
        )  # fmt: skip
    header = ["task", "method", "seeds", "mean", f"{conf:.0%} CI (t)", "sd", "IQM",
              f"final checkpoint [{conf:.0%} CI]"]  # fmt: skip
    md = tables.markdown_table(header, rows)
    line = score_note.line("the column “final checkpoint”")
    line = f"\n{line}\n" if line else ""
    files = [
        write_file(folder, "tables/per_task.csv", csv_text(estimates)),
        write_file(folder, "tables/per_task.md", md + line),
    ]
    text = (
        "Mean score over seeds per task and method with its Student-t interval "
        f"x̄ ± t · s/√n ({conf:.0%}; at 3–10 seeds a percentile bootstrap under-covers, "
        "docs/evaluation.md), the standard deviation and the interquartile mean (no interval: "
        "over a few seeds it has none worth giving).\n\n"
    )
    return Section("Per-task means (raw returns)", text + md + line, files)


def differences_section(differences: pd.DataFrame, folder: Path, options: ReportOptions) -> Section:
    """`REFERENCE` − each baseline per task, with Welch intervals, permutation p and power."""
    conf, level, target = options.confidence, f"{options.power:.0%}", options.target_difference
    rows = [
        [r.task, f"{REFERENCE} − {r.baseline}", r.seeds,
         f"{r.difference:.1f} {ci_text(r.low, r.high, 1)}".replace(f" {tables.DASH}", ""),
         tables.p_text(r.p_value), rounded(r.detectable), rounded(r.seeds_for_target)]
        for r in differences.itertuples()
    ]  # fmt: skip
    header = ["task", "comparison", "seeds", f"difference [{conf:.0%} CI, Welch]", "p",
              f"detectable at {level}", f"seeds for {target:g}"]  # fmt: skip
    md = tables.markdown_table(header, rows)
    files = [
        write_file(folder, "tables/differences.csv", csv_text(differences)),
        write_file(folder, "tables/differences.md", md),
    ]
    text = (
        f"Mean score of {REFERENCE} minus each baseline's on the same task, with Welch's t "
        "interval (each method's seeds independent; `stats.welch_difference_ci`). An interval "
        "that contains 0 shows no difference at these seeds.\n\n"
        + md + "\n" + power_text(options) + "\n"
    )  # fmt: skip
    return Section(f"Differences from {REFERENCE} per task", text, files)


def improvement_section(
    scores: pd.DataFrame, differences: pd.DataFrame, folder: Path, options: ReportOptions
) -> Section:
    conf = options.confidence
    estimates = compare.improvement_estimates(
        scores, REFERENCE, options.bootstrap_reps, conf, options.seed + 2000
    )
    title = "Probability of improvement"
    if estimates.empty:
        return Section(title, f"No baseline ran on a task {REFERENCE} ran.\n", empty=True)
    level, target = f"{options.power:.0%}", options.target_difference

    def per_task(baseline: str, column: str, fmt) -> str:
        rows = differences[differences["baseline"] == baseline]
        if len(rows) == 1:
            return fmt(rows[column].iloc[0])
        return ", ".join(f"{t} {fmt(v)}" for t, v in zip(rows["task"], rows[column]))

    rows = [
        [f"{REFERENCE} > {r.baseline}", r.tasks, r.seeds, f"{r.point:.3f}",
         ci_text(r.low, r.high, 3) if r.min_seeds > 1 else tables.DASH,
         per_task(r.baseline, "detectable", rounded),
         per_task(r.baseline, "seeds_for_target", rounded)]
        for r in estimates.itertuples()
    ]  # fmt: skip
    md = tables.markdown_table(
        ["comparison", "tasks", "seeds", "P(X > Y)", f"{conf:.0%} CI",
         f"detectable at {level} (per task)", f"seeds for {target:g} (per task)"],
        rows,
    )  # fmt: skip
    text = (
        f"Probability that a random seed of {REFERENCE} ends with a higher score than a random "
        "seed of the baseline on the same task (ties count ½), averaged over the tasks both ran; "
        "0.5 means no difference. Intervals: stratified bootstrap, each method resampled "
        "independently (none from one seed). Power per task: as in the differences above.\n\n"
        f"{md}"
    )
    files = [
        write_file(folder, "tables/probability_of_improvement.csv", csv_text(estimates)),
        write_file(folder, "tables/probability_of_improvement.md", md),
    ]
    fig = figures.probability_of_improvement(estimates, REFERENCE)
    return Section(
        title, text, files + common.save_figure(folder, fig, "probability_of_improvement")
    )


def profile_section(
    normalised: compare.Normalised, folder: Path, options: ReportOptions
) -> Section:
    taus = PROFILE_TAUS
    conf = options.confidence
    profiles = compare.profile_estimates(
        normalised, taus, options.bootstrap_reps, conf, options.seed + 3000
    )
    frame = pd.DataFrame({"tau": taus})
    for m, (p, lo, hi) in profiles.items():
        frame[m], frame[f"{m} low"], frame[f"{m} high"] = p, lo, hi
    files = [write_file(folder, "tables/performance_profiles.csv", csv_text(frame))]
    files += common.save_figure(
        folder, figures.performance_profiles(taus, profiles), "performance_profiles"
    )
    text = (
        "Fraction of runs (seeds × tasks) whose normalised score exceeds τ, with "
        f"{conf:.0%} stratified-bootstrap bands.\n"
    )
    return Section("Performance profiles", text, files)
