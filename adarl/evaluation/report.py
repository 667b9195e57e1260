"""`adarl report`: everything a comparison needs from any set of run folders, in one folder.

`build_report(paths, out, options)` checks its input first (run folders, checkpoints, one
training setting per task), writes the whole report into a temporary folder next to `out` and
renames it into place at the end, so `out` is never half-written: on an error the previous
report (if any) stays as it was.

Layout of the report folder::

    index.md                 links everything; budget, seeds, the exact commands
    tables/table1.{md,tex,csv}   final nominal return per task × method (mean ± std over seeds)
    tables/aggregate.{md,csv}    IQM and mean with 95% stratified-bootstrap CIs
    tables/per_task.{md,csv}     the same per task, in raw returns
    tables/probability_of_improvement.{md,csv}
    tables/performance_profiles.csv
    tables/parseval.{md,csv}     every Parseval coefficient's cell (Table 1 keeps the best)
    tables/contrast_FIELD.{md,csv}  with --contrast FIELD: differences along one setting, CIs
    tables/control_pairs.{md,csv}   AdaRL minus its schedule-matched control, seed by seed
    tables/fixed_rank.{md,csv}   final return per fixed rank (bias–variance sweep)
    tables/policy_size.{md,csv}  policy parameters before/after rank adaptation
    tables/suites.{md,csv}       worst-case / average return over robustness suites' grids
    tables/robustness_size_<task>_<suite>.csv   return against the size of the perturbation
    tables/runs.csv
    tables/environments.csv      versions, CPU and XLA flags each run was made with
    figures/*.{png,pdf}
"""

from __future__ import annotations

import os
import re
import shutil
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from adarl import __version__
from adarl.algos import registry
from adarl.errors import UsageError, check_choice
from adarl.evaluation import collect, compare, figures, selection, stats, tables
from adarl.evaluation.runs import (
    LAUNCH_KEYS,
    Run,
    config_value,
    differing_fields,
    find_runs,
    flatten_config,
    method_label,
    select_checkpoint,
    sort_methods,
    sort_tasks,
)
from adarl.train import provenance
from adarl.train.run_folder import checkpoint_dirs

REFERENCE = registry.REFERENCE
INDEX = "index.md"
MARKER = "<!-- adarl report -->"


@dataclass
class ReportOptions:
    bootstrap_reps: int = 10_000
    confidence: float = 0.95
    seed: int = 0
    skip_incomplete: bool = False
    command: str = ""
    rnac_checkpoint: str = "final"  # final, or best (by evaluation, as RNAC's original reports)
    contrasts: tuple[str, ...] = ()  # FIELD or FIELD=REFERENCE: differences along one setting


@dataclass
class Section:
    title: str
    text: str = ""
    files: list[Path] = field(default_factory=list)


# ----------------------------------------------------------------------------- entry point
def build_report(
    paths: Sequence[str | os.PathLike], out: str | os.PathLike, options: ReportOptions
) -> Path:
    """Check the runs under `paths`, write the report to `out` atomically; returns `out`."""
    out = Path(out)
    check_output(out)
    if options.bootstrap_reps < 1:
        raise UsageError(f"--bootstrap-reps must be ≥ 1, got {options.bootstrap_reps}")
    check_choice("--rnac-checkpoint", options.rnac_checkpoint, selection.RNAC_CHECKPOINTS)
    runs, notes = usable_runs(find_runs(paths), options.skip_incomplete)
    check_rows(runs)
    for contrast in options.contrasts:
        contrast_groups(runs, contrast)  # a bad field or reference fails before anything is written
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.tmp-"))
    try:
        write_report(runs, tmp, options, notes)
        _swap_into_place(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def check_output(out: Path) -> None:
    """`out` may be new, empty, or a previous report (replaced); anything else is refused."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} is a file; give a folder for the report")
    if out.is_dir() and any(out.iterdir()):
        index = out / INDEX
        if not (index.is_file() and MARKER in index.read_text(encoding="utf-8", errors="replace")):
            raise UsageError(
                f"--out {out} is a non-empty folder that is not an adarl report; "
                "choose a new or empty folder"
            )


def usable_runs(runs: list[Run], skip_incomplete: bool) -> tuple[list[Run], list[str]]:
    """Runs with at least one complete checkpoint; the others are an error, or skipped with a
    note when `skip_incomplete`."""
    kept, notes = [], []
    for run in runs:
        if checkpoint_dirs(run.path):
            kept.append(run)
        elif skip_incomplete:
            notes.append(f"Skipped {run.path}: no complete checkpoint yet.")
        else:
            select_checkpoint(run)  # raises the one-line error naming the folder
    if not kept:
        raise UsageError("no run with a complete checkpoint to report on")
    return kept, notes


def check_rows(runs: Sequence[Run]) -> None:
    """One table row is one task trained one way: runs of the same task must share the
    training dynamics, or the row would compare methods on different problems."""
    seen: dict[str, Run] = {}
    for run in runs:
        first = seen.setdefault(run.task, run)
        if first.dynamics != run.dynamics:
            raise UsageError(
                f"runs {first.path} ({run.task}, dynamics {first.dynamics}) and {run.path} "
                f"({run.task}, dynamics {run.dynamics}) would share the table row {run.task!r}; "
                "report them separately"
            )


def _swap_into_place(tmp: Path, out: Path) -> None:
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.old-"))
        os.rmdir(old)
        os.replace(out, old)
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


# ----------------------------------------------------------------------------- the report
def write_report(runs: list[Run], folder: Path, options: ReportOptions, notes: list[str]) -> None:
    (folder / "tables").mkdir(parents=True)
    (folder / "figures").mkdir()
    best_rnac = options.rnac_checkpoint == "best"
    if best_rnac:
        runs = [
            replace(r, label=f"{r.label} ({selection.RNAC_BEST_LABEL})")
            if registry.keeps_best_policy(r.algo)
            else r
            for r in runs
        ]
    tasks, methods = sort_tasks(r.task for r in runs), sort_methods(r.label for r in runs)
    runs = sorted(runs, key=lambda r: (tasks.index(r.task), methods.index(r.label), str(r.path)))
    fixed = [r for r in runs if registry.role(r.algo, "rank_sweep")]
    main = [r for r in runs if not registry.role(r.algo, "rank_sweep")] or fixed
    finals = {
        r.path: collect.best_scores(r)
        if best_rnac and registry.keeps_best_policy(r.algo)
        else collect.final_scores(r)
        for r in runs
    }
    for r in runs:
        if finals[r.path][0].empty:
            notes.append(
                f"{r.path} has no nominal evaluation (neither `adarl evaluate --dynamics nominal` "
                "of its final checkpoint nor `nominal` rows in eval.csv); it is left out of the tables."
            )
    parseval = selection.select_parseval(main, _long_scores(main, finals))
    scores = parseval.scores
    notes += parseval.notes
    colours = figures.method_colours([r.label for r in runs] + list(parseval.labels.values()))

    sections = [runs_section(runs, finals, folder)]
    sections.append(table1_section(scores, folder, protocol_notes(runs, parseval, options)))
    if not parseval.cells.empty:
        sections.append(parseval_section(parseval, folder))
    sections.append(behaviour_section(main, folder))
    sections += statistics_sections(scores, folder, options, notes)
    sections += [contrast_section(main, finals, c, folder, options) for c in options.contrasts]
    sections += [s for s in [control_section(main, finals, folder, options)] if s is not None]
    sections.append(training_section(main, folder, colours))
    sections.append(rank_section(runs, folder))
    sections.append(robustness_section(runs, folder, colours, notes))
    sections.append(suites_section(runs, folder, options, colours))
    sections.append(bias_variance_section(fixed, runs, finals, folder))
    sections.append(ablation_section(runs, folder))
    sections.append(spectra_section(runs, folder))
    sections.append(policy_size_section(runs, folder))
    sections.append(environment_section(runs, folder, notes))
    write_index(folder, runs, sections, options, notes)


def _long_scores(runs: Sequence[Run], finals: dict) -> pd.DataFrame:
    frames = [
        finals[r.path][0].assign(task=r.task, method=r.label, run=str(r.path))
        for r in runs
        if not finals[r.path][0].empty
    ]
    if not frames:
        return pd.DataFrame(columns=["seed", "score", "task", "method", "run"])
    return pd.concat(frames, ignore_index=True)


def _write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


def _figure(folder: Path, fig, stem: str) -> list[Path]:
    return figures.save_figure(fig, folder / "figures" / _slug(stem))


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-")


def intrinsic_rank(run: Run) -> int | None:
    """2·d_a+1 of the run's task (from `adarl.envs`, else the config), None if unknown."""
    try:
        from adarl.envs import get_task

        return int(get_task(run.task).intrinsic_rank)
    except (ImportError, AttributeError, KeyError, TypeError, UsageError):
        value = config_value(run.config, "intrinsic_rank")
        return None if value is None else int(value)


# ----------------------------------------------------------------------------- sections
def runs_section(runs: list[Run], finals: dict, folder: Path) -> Section:
    rows = []
    for r in runs:
        last = collect.final_step(r)
        rows.append(
            {
                "run": str(r.path),
                "task": r.task,
                "method": r.label,
                "training dynamics": r.dynamics,
                "seeds": " ".join(map(str, r.seeds)),
                "budget (steps per seed)": r.total_steps,
                "final checkpoint": last,
                "finished": "yes" if r.done_step is not None else "no",
                "final return from": finals[r.path][1],
            }
        )
    df = pd.DataFrame(rows)
    path = _write(folder, "tables/runs.csv", df.to_csv(index=False))
    text = tables.markdown_table(
        list(df.columns), df.astype(object).where(df.notna(), "—").values.tolist()
    )
    return Section("Runs", text, [path])


def table1_section(scores: pd.DataFrame, folder: Path, labels: Sequence[str] = ()) -> Section:
    """Table 1; `labels` explain method labels (Parseval's selection, RNAC's checkpoint) below
    the table, in the LaTeX caption and in the report text."""
    if scores.empty:
        return Section(
            "Table 1: final return under nominal dynamics", "No nominal evaluations found.\n"
        )
    table = tables.score_table(scores)
    caption = "Final return under nominal dynamics, mean ± standard deviation over seeds."
    legend = "".join(f"\n{line}\n" for line in labels)
    full_caption = " ".join([caption, *labels]).replace("`", "")
    files = [
        _write(folder, "tables/table1.md", tables.table_markdown(table) + legend),
        _write(folder, "tables/table1.tex", tables.table_latex(table, caption=full_caption)),
        _write(folder, "tables/table1.csv", tables.table_csv(table)),
    ]
    text = (
        f"{caption} The best mean per task is in bold. Seeds per cell: "
        f"{_seed_counts(table)}.\n\n{tables.table_markdown(table)}{legend}"
    )
    return Section("Table 1: final return under nominal dynamics", text, files)


def behaviour_section(runs: list[Run], folder: Path) -> Section:
    """Episode length and forward distance of the final policies on nominal dynamics: a return
    of ~1,000 on Hopper can be a policy that stands still for 1,000 steps."""
    frames = [collect.final_behaviour(r).assign(task=r.task, method=r.label) for r in runs]
    df = pd.concat([f for f in frames if not f.empty] or [pd.DataFrame()], ignore_index=True)
    title = "What the final policies do"
    if df.empty:
        return Section(title, "No nominal evaluations found.\n")
    rows = []
    for (task, method), group in df.groupby(["task", "method"], sort=False):
        cells = [task, method]
        for column, digits in (("length", 0), ("distance", 2)):
            values = group[column].dropna().to_numpy(float)
            mean, std = stats.mean_std(values) if len(values) else (np.nan, np.nan)
            cells.append(tables.format_mean_std(mean, std, len(values), digits))
        rows.append(cells)
    md = tables.markdown_table(["task", "method", "episode length", "forward distance (m)"], rows)
    path = _write(
        folder, "tables/behaviour.csv", _csv(df[["task", "method", "seed", "length", "distance"]])
    )
    text = (
        "Mean episode length (steps, of at most 1,000) and forward distance of the root body "
        "(metres) of each seed's final policy on nominal dynamics, mean ± std over seeds. A "
        "Hopper policy that only balances earns about 1,000 in 1,000 steps while moving ~0 m; "
        "rank methods by return only together with this table. Distance is recorded by "
        "`adarl evaluate` (— where only the training log exists).\n\n" + md
    )
    return Section(title, text, [path])


def protocol_notes(
    runs: Sequence[Run], parseval: selection.ParsevalSelection, options: ReportOptions
) -> list[str]:
    """One line per method label that carries a protocol choice: Parseval's selected
    coefficient, RNAC's final or best checkpoint."""
    lines = []
    for label in sorted(set(parseval.labels.values())):
        tasks = [t for t, lab in parseval.labels.items() if lab == label]
        chosen = parseval.cells[parseval.cells["selected"] & parseval.cells["task"].isin(tasks)]
        picks = ", ".join(
            f"{t} {selection.coef_text(c)}" for t, c in zip(chosen["task"], chosen[selection.COEF])
        )
        n = int(re.search(r"best of (\d+)", label).group(1))
        lines.append(
            f"{label}: {selection.PARSEVAL_NOTE.format(n=n)}; chosen coefficient: {picks}; "
            "every coefficient: tables/parseval.md."
        )
    rnac = ", ".join(sort_methods(r.label for r in runs if registry.keeps_best_policy(r.algo)))
    if rnac and options.rnac_checkpoint == "best":
        lines.append(f"{rnac}: {selection.RNAC_BEST_NOTE}.")
    elif rnac:
        lines.append(
            f"{rnac}: the final checkpoint (`--rnac-checkpoint best` shows RNAC's best "
            "checkpoint by evaluation, as its original reports)."
        )
    return lines


def parseval_section(parseval: selection.ParsevalSelection, folder: Path) -> Section:
    md = selection.parseval_markdown(parseval.cells)
    files = [
        _write(folder, "tables/parseval.md", md),
        _write(folder, "tables/parseval.csv", _csv(parseval.cells)),
    ]
    text = (
        "Final return under nominal dynamics of `sac-parseval` at each coefficient, mean ± "
        "standard deviation over seeds. As in the paper, Table 1 and the statistics report, per "
        "task, the coefficient with the highest mean (in bold; ties: the larger coefficient), "
        "chosen on the same metric it reports, so that cell is optimistic.\n\n" + md
    )
    return Section("Supplementary: Parseval coefficients", text, files)


def contrast_groups(runs: Sequence[Run], contrast: str) -> tuple[str, str, dict]:
    """Split `FIELD[=REFERENCE]` and group the runs that differ only in FIELD.

    Returns `(field, reference, groups)`, groups mapping `(task, method, other settings)` to
    `{value: [runs]}`; "other settings" names the fields (seeds and launch details aside) that
    differ between groups of the same task and method. The reference defaults to the first value
    in sorted order. Raises `UsageError` when no run has FIELD or no run has REFERENCE.
    """
    field, _, reference = contrast.partition("=")
    keyed = []
    for r in runs:
        flat = flatten_config(r.config)
        keys = [k for k in flat if k.split(".")[-1] == field]
        if not keys:
            continue
        keyed.append((r, str(flat[keys[0]])))
    if not keyed:
        raise UsageError(f"--contrast {contrast!r}: no run has a config field {field!r}")
    values = sorted({value for _, value in keyed})
    reference = reference or values[0]
    if reference not in values:
        raise UsageError(
            f"--contrast {contrast!r}: no run has {field}={reference}; the runs have "
            f"{', '.join(values)}"
        )
    by_method: dict[tuple[str, str], list] = {}
    for r, value in keyed:
        by_method.setdefault((r.task, method_label(r.config)), []).append((r, value))
    groups: dict[tuple[str, str, str], dict[str, list[Run]]] = {}
    for (task, method), members in by_method.items():
        varying = differing_fields([r.config for r, _ in members], ignore={field})
        for r, value in members:
            flat = flatten_config(r.config)
            others = ", ".join(f"{k.split('.')[-1]}={flat[k]}" for k in varying if k in flat)
            groups.setdefault((task, method, others), {}).setdefault(value, []).append(r)
    return field, reference, groups


def _seed_scores(finals: dict, runs: list[Run]) -> np.ndarray:
    """The final scores of every seed of `runs`, pooled."""
    return np.concatenate([finals[r.path][0]["score"].to_numpy(float) for r in runs])


def contrast_section(
    runs: list[Run], finals: dict, contrast: str, folder: Path, options: ReportOptions
) -> Section:
    """Final nominal return of each value of one setting minus the reference value's, among runs
    that agree on everything else, with a bootstrap CI over seeds (`stats.difference_ci`)."""
    field, reference, groups = contrast_groups(runs, contrast)
    rows = []
    for (task, method, others), by_value in groups.items():
        if reference not in by_value:
            continue
        base = _seed_scores(finals, by_value[reference])
        for value in sorted(v for v in by_value if v != reference):
            other = _seed_scores(finals, by_value[value])
            if not len(base) or not len(other):
                continue
            ci = stats.difference_ci(
                other, base, options.bootstrap_reps, options.confidence, options.seed
            )
            rows.append(
                {
                    "task": task,
                    "method": method,
                    "held fixed": others or "—",
                    "contrast": f"{field}: {value} − {reference}",
                    f"mean ({reference})": base.mean(),
                    "mean (other)": other.mean(),
                    "difference": ci.point,
                    "ci low": ci.low,
                    "ci high": ci.high,
                    "seeds": f"{len(other)} vs {len(base)}",
                }
            )
    df = pd.DataFrame(rows)
    stem = f"tables/contrast_{_slug(field)}"
    files = [_write(folder, f"{stem}.csv", _csv(df))]
    if df.empty:
        return Section(f"Contrast: {field}", f"No pair of runs differs only in `{field}`.", files)
    pct = int(round(100 * options.confidence))
    md = tables.markdown_table(
        ["task", "method", "held fixed", "contrast", f"mean ({reference})", "mean (other)",
         f"difference [{pct}% CI]", "seeds"],
        [
            [r["task"], r["method"], r["held fixed"], r["contrast"], f"{r[f'mean ({reference})']:.1f}",
             f"{r['mean (other)']:.1f}", f"{r['difference']:.1f} [{r['ci low']:.1f}, {r['ci high']:.1f}]",
             r["seeds"]]
            for r in rows
        ],
    )  # fmt: skip
    files.append(_write(folder, f"{stem}.md", md))
    text = (
        f"Final nominal return with `{field}` set to each value minus the same runs' setting at "
        f"`{reference}`, everything else equal; {pct}% percentile-bootstrap interval over seeds "
        "(each side resampled independently). An interval that contains 0 shows no difference "
        "at this number of seeds.\n\n" + md
    )
    return Section(f"Contrast: {field}", text, files)


# fields in which a control may differ from the AdaRL run it is paired with (a fork may also
# change how it is logged and checkpointed)
CONTROL_PAIR_IGNORED = {
    "algo",
    "apply_cuts",
    "keep_checkpoints",
    "checkpoint_every",
    "checkpoint_before_truncation",
    "log_every",
    "eval_every",
    "on_divergence",
}


def control_section(
    runs: list[Run], finals: dict, folder: Path, options: ReportOptions
) -> Section | None:
    """AdaRL minus its schedule-matched control (`control_of` in the registry), seed by seed:
    runs of the two that agree on everything else are paired on their common seeds, and the mean
    per-seed difference of final nominal return gets a Student-t interval
    (`stats.paired_difference_ci`). None without control runs."""
    arms = {r.algo: registry.role(r.algo, "control_of") for r in runs}
    arms = {control: arm for control, arm in arms.items() if arm}
    if not arms:
        return None

    def setting(r: Run) -> tuple:
        ignored = LAUNCH_KEYS | CONTROL_PAIR_IGNORED
        flat = flatten_config(r.config).items()
        return r.task, sorted(
            (k, repr(v)) for k, v in flat if k.split(".")[0] != "fork" and k not in ignored
        )

    groups: dict[str, dict[str, list[Run]]] = {}
    for r in runs:
        side = "control" if r.algo in arms else "method" if r.algo in arms.values() else None
        if side:
            groups.setdefault(repr(setting(r)), {}).setdefault(side, []).append(r)
    rows, summary, forks = [], [], []
    pct = int(round(100 * options.confidence))
    for group in groups.values():
        by_seed = {
            side: {int(seed): float(score) for r in group.get(side, [])
                   for seed, score in finals[r.path][0][["seed", "score"]].itertuples(index=False)}
            for side in ("method", "control")
        }  # fmt: skip
        seeds = sorted(set(by_seed["method"]) & set(by_seed["control"]))
        if not seeds:
            continue
        method, control = group["method"][0], group["control"][0]
        x = np.array([by_seed["method"][s] for s in seeds])
        y = np.array([by_seed["control"][s] for s in seeds])
        rows += [
            {"task": method.task, "method": method.label, "control": control.label, "seed": s,
             "method score": a, "control score": b, "difference": a - b}
            for s, a, b in zip(seeds, x, y)
        ]  # fmt: skip
        ci = stats.paired_difference_ci(x, y, options.confidence)
        summary.append(
            [method.task, method.label, control.label, str(len(seeds)), f"{x.mean():.1f}",
             f"{y.mean():.1f}", f"{ci.point:.1f} [{ci.low:.1f}, {ci.high:.1f}]"]
        )  # fmt: skip
        forks += [
            f"- {r.path}: forked from {r.config['fork'].get('from')} at step "
            f"{r.config['fork'].get('step')}"
            for r in group["control"]
            if isinstance(r.config.get("fork"), dict)
        ]
    title = "AdaRL against its control"
    if not summary:
        return Section(title, "No control run has an AdaRL run with the same settings and seeds.\n")
    files = [_write(folder, "tables/control_pairs.csv", _csv(pd.DataFrame(rows)))]
    md = tables.markdown_table(
        ["task", "method", "control", "paired seeds", "mean (method)", "mean (control)",
         f"method − control [{pct}% t CI]"],
        summary,
    )  # fmt: skip
    files.append(_write(folder, "tables/control_pairs.md", md))
    text = (
        "Final nominal return of AdaRL minus its schedule-matched control (the same truncations, "
        "resets and warm-ups, no component removed), seed by seed: a control seed is paired with "
        f"the AdaRL seed of the same number; {pct}% Student-t interval of the mean per-seed "
        "difference. Per-seed rows: tables/control_pairs.csv.\n\n" + md
    )
    if forks:
        text = (
            text.rstrip("\n")
            + "\n\nForked controls (they share AdaRL's training up to that step):\n"
        )
        text += "\n".join(forks) + "\n"
    return Section(title, text, files)


def _seed_counts(table: tables.ScoreTable) -> str:
    counts = sorted({int(c) for c in table.count.to_numpy().ravel() if c > 0})
    return ", ".join(map(str, counts))


def _interval(point: float, low: float, high: float, digits: int) -> tuple[str, str]:
    return f"{point:.{digits}f}", f"[{low:.{digits}f}, {high:.{digits}f}]"


def statistics_sections(
    scores: pd.DataFrame, folder: Path, options: ReportOptions, notes: list[str]
) -> list[Section]:
    """Aggregate IQM/mean, per-task IQM/mean, probability of improvement, performance profiles."""
    if scores.empty:
        return []
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
    sections = [
        aggregate_section(normalised, folder, options),
        per_task_section(scores, folder, options),
    ]
    if REFERENCE in set(scores["method"]):
        sections.append(improvement_section(scores, folder, options))
    else:
        notes.append(f"No {REFERENCE!r} runs: probability of improvement is not computed.")
    if normalised.matrices:
        sections.append(profile_section(normalised, folder, options))
    return sections


def aggregate_section(
    normalised: compare.Normalised, folder: Path, options: ReportOptions
) -> Section:
    reps, conf = options.bootstrap_reps, options.confidence
    estimates = compare.aggregate_estimates(normalised, reps, conf, options.seed)
    title = "Aggregate statistics (rliable)"
    text = (
        "Final returns min–max normalised per task over all methods and seeds (0 = the lowest, "
        f"1 = the highest seed's return on that task), then aggregated over "
        f"{len(normalised.tasks)} task(s) and their seeds. Intervals: {conf:.0%} stratified "
        f"bootstrap ({reps} resamples, seed {options.seed}).\n\n"
    )
    files = [_write(folder, "tables/aggregate.csv", _csv(estimates))]
    if estimates.empty:
        return Section(title, text + "No method ran on every task.\n", files)
    rows = []
    for method, matrix in normalised.matrices.items():
        by_metric = estimates[estimates["method"] == method].set_index("metric")
        iqm = _interval(*by_metric.loc["IQM", ["point", "low", "high"]], 3)
        mean = _interval(*by_metric.loc["Mean", ["point", "low", "high"]], 3)
        rows.append([method, *iqm, *mean, f"{matrix.shape[0]} × {matrix.shape[1]}"])
    header = ["method", "IQM", f"IQM {conf:.0%} CI", "mean", f"mean {conf:.0%} CI"]
    md = tables.markdown_table([*header, "seeds × tasks"], rows)
    files.append(_write(folder, "tables/aggregate.md", md))
    files += _figure(folder, figures.aggregate_intervals(estimates), "aggregate_iqm_mean")
    return Section(title, text + md, files)


def per_task_section(scores: pd.DataFrame, folder: Path, options: ReportOptions) -> Section:
    conf = options.confidence
    estimates = compare.per_task_estimates(
        scores, options.bootstrap_reps, conf, options.seed + 1000
    )
    rows = [
        [r.task, r.method, r.seeds, *_interval(r.iqm, r.iqm_low, r.iqm_high, 1),
         *_interval(r.mean, r.mean_low, r.mean_high, 1)]
        for r in estimates.itertuples()
    ]  # fmt: skip
    header = ["task", "method", "seeds", "IQM", f"IQM {conf:.0%} CI", "mean", f"mean {conf:.0%} CI"]
    md = tables.markdown_table(header, rows)
    files = [
        _write(folder, "tables/per_task.csv", _csv(estimates)),
        _write(folder, "tables/per_task.md", md),
    ]
    return Section("Per-task IQM and mean (raw returns)", md, files)


def improvement_section(scores: pd.DataFrame, folder: Path, options: ReportOptions) -> Section:
    conf = options.confidence
    estimates = compare.improvement_estimates(
        scores, REFERENCE, options.bootstrap_reps, conf, options.seed + 2000
    )
    title = "Probability of improvement"
    if estimates.empty:
        return Section(title, f"No baseline ran on a task {REFERENCE} ran.\n")
    rows = [
        [f"{REFERENCE} > {r.baseline}", r.tasks, *_interval(r.point, r.low, r.high, 3)]
        for r in estimates.itertuples()
    ]
    md = tables.markdown_table(["comparison", "tasks", "P(X > Y)", f"{conf:.0%} CI"], rows)
    text = (
        f"Probability that a random seed of {REFERENCE} ends with a higher return than a random "
        "seed of the baseline on the same task (ties count ½), averaged over the tasks both ran; "
        "0.5 means no difference. Intervals: stratified bootstrap, each method resampled "
        f"independently.\n\n{md}"
    )
    files = [
        _write(folder, "tables/probability_of_improvement.csv", _csv(estimates)),
        _write(folder, "tables/probability_of_improvement.md", md),
    ]
    fig = figures.probability_of_improvement(estimates, REFERENCE)
    return Section(title, text, files + _figure(folder, fig, "probability_of_improvement"))


def profile_section(
    normalised: compare.Normalised, folder: Path, options: ReportOptions
) -> Section:
    taus = np.linspace(0.0, 1.0, 101)
    conf = options.confidence
    profiles = compare.profile_estimates(
        normalised, taus, options.bootstrap_reps, conf, options.seed + 3000
    )
    frame = pd.DataFrame({"tau": taus})
    for m, (p, lo, hi) in profiles.items():
        frame[m], frame[f"{m} low"], frame[f"{m} high"] = p, lo, hi
    files = [_write(folder, "tables/performance_profiles.csv", _csv(frame))]
    files += _figure(folder, figures.performance_profiles(taus, profiles), "performance_profiles")
    text = (
        "Fraction of runs (seeds × tasks) whose normalised final return exceeds τ, with "
        f"{conf:.0%} stratified-bootstrap bands.\n"
    )
    return Section("Performance profiles", text, files)


def _csv(df: pd.DataFrame) -> str:
    return df.to_csv(index=False, float_format="%.6g")


def training_section(runs: list[Run], folder: Path, colours) -> Section:
    curves: dict[str, dict[str, list[pd.DataFrame]]] = {}
    truncations: dict[str, set[int]] = {}
    sources = set()
    for r in runs:
        curve, source = collect.training_curve(r)
        if curve.empty:
            continue
        sources.add(source)
        curves.setdefault(r.task, {}).setdefault(r.label, []).append(curve)
        truncations.setdefault(r.task, set()).update(collect.truncation_steps(r))
    if not curves:
        return Section("Training curves", "No evaluation or episode logs found.\n")
    tasks = sort_tasks(curves)
    merged = {t: {m: pd.concat(frames) for m, frames in curves[t].items()} for t in tasks}
    fig = figures.training_curves(
        merged, {t: sorted(truncations.get(t, ())) for t in tasks}, colours
    )
    files = _figure(folder, fig, "training_curves")
    text = (
        "Return over training (source: " + "; ".join(sorted(sources)) + "), mean over seeds with a "
        "95% t band; red dashed lines mark the steps at which rank-adaptive runs truncated.\n"
    )
    return Section("Training curves", text, files)


def rank_section(runs: list[Run], folder: Path) -> Section:
    files, lines = [], []
    for r in runs:
        history, steps = collect.rank_history(r), collect.truncation_steps(r)
        if history.empty or not steps:
            continue
        fig = figures.rank_trajectories(history, intrinsic_rank(r), f"{r.task} {r.label}", steps)
        files += _figure(folder, fig, f"ranks_{r.task}_{r.label}")
        final = collect.final_ranks(r)
        per_layer = final.groupby("layer")["rank"].agg(lambda s: " ".join(str(int(v)) for v in s))
        lines.append(
            f"- {r.task} {r.label} ({r.path}): final rank per seed — "
            + "; ".join(f"{layer}: {ranks}" for layer, ranks in per_layer.items())
            + f"; intrinsic rank 2·d_a+1 = {intrinsic_rank(r)}"
        )
    if not files:
        return Section("Rank over training", "No rank-adaptive runs.\n")
    table, md = settling_table(runs)
    files.append(_write(folder, "tables/rank_settling.md", md))
    files.append(_write(folder, "tables/rank_settling.csv", _csv(table)))
    text = (
        "Estimated rank of each bottleneck, per seed; dotted line: 2·d_a+1.\n\n"
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


def robustness_section(runs: list[Run], folder: Path, colours, notes: list[str]) -> Section:
    groups: dict[tuple[str, str, str], list[pd.DataFrame]] = {}
    held: dict[tuple[str, str, str], str] = {}
    nominal: dict[tuple[str, str], float] = {}
    for r in runs:
        for ev in collect.evaluations(r):
            swept = ev.swept
            if not swept:
                for c in ev.table.columns:
                    if (
                        c.startswith("p_")
                        and ev.meta.get("dynamics") == "nominal"
                        and not ev.meta.get("hold")
                    ):
                        nominal[(r.task, c[2:])] = float(ev.table[c].iloc[0])
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
            held[key] = ", ".join(f"{k}={v:g}" for k, v in (ev.meta.get("hold") or {}).items())
    if not groups:
        return Section(
            "Robustness",
            "No sweeps found; run `adarl evaluate RUN --sweep P=LO:HI:N` to add them.\n",
        )
    files, lines = [], []
    order = sort_tasks(k[0] for k in groups)
    for key in sorted(groups, key=lambda k: (order.index(k[0]), k[1], k[2])):
        task, name, param = key
        data = pd.concat(groups[key], ignore_index=True)
        title = f"{task}: {param}" + (f" (held: {held[key]})" if held[key] else "")
        fig = figures.robustness_curve(data, param, title, nominal.get((task, param)), colours)
        files += _figure(folder, fig, f"robustness_{task}_{name}")
        lines.append(f"- {title}: {', '.join(sort_methods(data['method'].unique()))}")
    text = (
        "Return against each swept parameter (mean over seeds of each seed's mean over episodes, "
        "95% t band); grey dotted line: the nominal value.\n\n" + "\n".join(lines) + "\n"
    )
    return Section("Robustness", text, files)


def suites_section(runs: list[Run], folder: Path, options: ReportOptions, colours=None) -> Section:
    """Worst-case and average return over each robustness suite's grid (`adarl evaluate
    --suite`), mean over seeds with bootstrap intervals; a heatmap per two-parameter suite and,
    for suites over the training parameters, return against the size of the perturbation."""
    from adarl.evaluation import suites

    found: dict[tuple[str, str, str], list[tuple[pd.DataFrame, pd.DataFrame]]] = {}
    for r in runs:
        for ev in collect.evaluations(r):
            name = ev.meta.get("suite")
            if name and ev.meta.get("final_checkpoint", True):
                summary = suites.seed_summary(ev.table, name)
                found.setdefault((r.task, name, r.label), []).append((summary, ev.table))
    title = "Robustness suites"
    if not found:
        return Section(
            title,
            "No suite evaluations found; run `adarl evaluate RUN --suite NAME` to add them.\n",
        )
    reps, conf = options.bootstrap_reps, options.confidence
    order = sort_tasks(k[0] for k in found)
    methods = sort_methods(k[2] for k in found)
    keys = sorted(found, key=lambda k: (order.index(k[0]), k[1], methods.index(k[2])))
    rows, files = [], []
    for task, name, method in keys:
        summary = pd.concat([s for s, _ in found[(task, name, method)]], ignore_index=True)
        estimate = suites.aggregate(summary, reps, conf, options.seed)
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
                *suites.heatmap_grid(table, x, y), x, y, f"{task}, {name}: {method}"
            )
            files += _figure(folder, fig, f"suite_{task}_{name}_{method}")
    size_files, size_text = size_curves(found, keys, folder, options, colours)
    files += size_files
    df = pd.DataFrame(rows)
    files.insert(0, _write(folder, "tables/suites.csv", _csv(df)))
    md = tables.markdown_table(
        ["task", "suite", "method", "seeds", "points × episodes", "worst-case", f"{conf:.0%} CI",
         "average", f"{conf:.0%} CI"],
        [
            [row.task, row.suite, row.method, row.seeds, f"{row.points} × {row.episodes}",
             *_interval(row.worst_mean, row.worst_low, row.worst_high, 1),
             *_interval(row.average_mean, row.average_low, row.average_high, 1)]
            for row in df.itertuples()
        ],
    )  # fmt: skip
    files.insert(1, _write(folder, "tables/suites.md", md))
    text = (
        "Per seed, the worst-case return is the lowest and the average return the mean, over "
        "the suite's grid points, of the mean return over each point's episodes (as M2TD3 and "
        "RRLS report them; suites and sources: docs/evaluation.md). Shown: the mean over seeds "
        f"with a {conf:.0%} percentile bootstrap interval over seeds ({reps} resamples). "
        "Heatmaps: two-parameter suites, mean over seeds, the worst point circled.\n\n"
    )
    return Section(title, text + md + size_text, files)


def size_curves(
    found: dict, keys: list, folder: Path, options: ReportOptions, colours=None
) -> tuple[list[Path], str]:
    """Return against the size of the perturbation (`adarl.evaluation.perturbation`) for every
    task × suite whose parameters all have a training range: one figure and one table each,
    `figures/robustness_size_<task>_<suite>`, `tables/robustness_size_<task>_<suite>.csv`."""
    from adarl.evaluation import perturbation, suites

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
        fig = figures.robustness_size_curve(data, f"{task}, suite {name}", colours)
        files += _figure(folder, fig, stem)
        summary = perturbation.ring_summary(data, options.confidence)
        order = sort_methods(summary["method"].unique())
        summary = summary.sort_values(
            ["method", "ring"], key=lambda c: c.map(order.index) if c.name == "method" else c
        )
        files.append(_write(folder, f"tables/{_slug(stem)}.csv", _csv(summary)))
        rings = perturbation.describe_rings(data)
        sizes = ", ".join(f"{ring:.3g} ({count})" for ring, count in rings.items())
        lines.append(f"{task}, {name}: rings (grid points) {sizes}; `figures/{_slug(stem)}`\n")
        cells = summary.pivot(index="method", columns="ring", values="mean_mean").loc[order]
        worst = summary.groupby("method")["worst_within_mean"].last().loc[order]
        lines.append(
            tables.markdown_table(
                ["mean return at size", *(f"{ring:.3g}" for ring in cells.columns),
                 f"worst within {cells.columns[-1]:.3g}"],
                [[m, *(_number(v) for v in cells.loc[m]), _number(worst[m])] for m in order],
            )
        )  # fmt: skip
    if not lines:
        return files, ""
    text = (
        "\n\n**Return against the size of the perturbation.** The size of a grid point is "
        "max_i |p_i − c_i| / a_i, its distance from the nominal point c in units of each "
        "parameter's training half-range a (1 = the edge of the training range; "
        "docs/evaluation.md). Left: per seed, the mean return over the points of each size "
        "(a ring); right: the worst point of size ≤ r, the worst-case return of the training box "
        f"scaled by r. Mean over seeds with a {options.confidence:.0%} t band; intervals in "
        "`tables/robustness_size_<task>_<suite>.csv`.\n\n" + "\n".join(lines) + "\n"
    )
    return files, text


def _number(value: float) -> str:
    """One decimal, or a dash where a method lacks the ring (runs evaluated on other grids)."""
    return f"{value:.1f}" if np.isfinite(value) else tables.DASH


def _swept_values(table: pd.DataFrame, param: str) -> np.ndarray:
    column = f"p_{param}"
    if column in table:
        return table[column].to_numpy(float).round(9)
    pattern = re.compile(rf"(?:^|[:,]){re.escape(param)}=([^,]+)")
    return np.array([float(pattern.search(str(label)).group(1)) for label in table["dynamics"]])


def bias_variance_section(fixed: list[Run], runs: list[Run], finals: dict, folder: Path) -> Section:
    if not fixed:
        return Section("Bias–variance", "No `sac-fixed-rank` runs.\n")
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
        files += _figure(folder, fig, f"bias_variance_{task}")
        table = tables.score_table(
            data.assign(task=task, method=data["rank"].map(lambda k: f"r={k}"))
        )
        rows = [[f"r={k}", table.cell(task, f"r={k}")] for k in sorted(data["rank"].unique())]
        md = tables.markdown_table(["rank", f"{task}: final return"], rows)
        texts.append(md)
        files.append(_write(folder, f"tables/fixed_rank_{_slug(task)}.md", md))
        files.append(
            _write(
                folder,
                f"tables/fixed_rank_{_slug(task)}.csv",
                data.to_csv(index=False, float_format="%.6g"),
            )
        )
        if ranks:
            texts.append(
                f"AdaRL's converged actor rank on {task}: {', '.join(f'{v:g}' for v in ranks)} (per seed).\n"
            )
    text = (
        "Final nominal return of SAC with a fixed-rank bottleneck, against the rank (mean and 95% t "
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
        files += _figure(folder, fig, f"rank_rule_ablation_{task}")
        for rule, h in merged.items():
            last = h.sort_values("step").groupby(["seed", "layer"])["rank"].last()
            per_layer = last.groupby("layer").mean()
            ranks = ", ".join(f"{layer} {value:.3g}" for layer, value in per_layer.items())
            lines.append(f"- {task}, {rule}: final rank (mean over seeds): {ranks}")
    if not files:
        return Section(
            "Rank-rule ablation", "Needs `adarl` runs with both rank rules on one task.\n"
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
            fig = figures.singular_value_spectra(found, f"{r.task} {r.label}")
            files += _figure(folder, fig, f"spectra_{r.task}_{r.label}")
    text = (
        "Singular values of each bottleneck at each truncation (mean over seeds).\n"
        if files
        else "No spectra recorded.\n"
    )
    return Section("Singular-value spectra", text, files)


def policy_size_section(runs: list[Run], folder: Path) -> Section:
    frames = [
        collect.policy_sizes(r).assign(run=str(r.path), task=r.task, method=r.label) for r in runs
    ]
    data = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    if data.empty:
        return Section("Policy size", "No policy files found.\n")
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
        _write(folder, "tables/policy_size.csv", data.to_csv(index=False)),
        _write(folder, "tables/policy_size.md", md),
    ]
    text = (
        "Parameters of the deterministic policy (as exported by `adarl export`) at full rank and at the "
        "final checkpoint, over seeds.\n\n" + md
    )
    return Section("Policy size", text, files)


def environment_section(runs: list[Run], folder: Path, notes: list[str]) -> Section:
    """What produced each run (its environment.json; "unknown" without one), and one warning per
    package of `provenance.COMPARED` whose version differs between runs, in the notes and on
    stderr."""
    records = {str(r.path): provenance.read_environment(r.path) for r in runs}
    df = pd.DataFrame([{"run": run, **provenance.summary(rec)} for run, rec in records.items()])
    path = _write(folder, "tables/environments.csv", df.to_csv(index=False))
    for line in provenance.mismatches(records):
        notes.append(f"Warning: {line}.")
        print(f"adarl: warning: {line}", file=sys.stderr)
    text = tables.markdown_table(list(df.columns), df.values.tolist())
    return Section("Environments", text, [path])


# ----------------------------------------------------------------------------- index.md
def write_index(
    folder: Path, runs: list[Run], sections: list[Section], options: ReportOptions, notes: list[str]
) -> None:
    order = sort_tasks(r.task for r in runs)
    methods = sort_methods(r.label for r in runs)
    budgets = sorted(
        {(r.task, r.label, r.total_steps, " ".join(map(str, r.seeds))) for r in runs},
        key=lambda b: (order.index(b[0]), methods.index(b[1]), str(b[2]), b[3]),
    )
    lines = [
        MARKER,
        "# adarl report",
        "",
        f"Made by adarl {__version__} from {len(runs)} run folder(s).",
        "",
        "## Budget and seeds",
        "",
        tables.markdown_table(
            ["task", "method", "steps per seed", "seeds"],
            [[t, m, f"{s:,}" if s is not None else "—", seeds] for t, m, s, seeds in budgets],
        ),
    ]
    for section in sections:
        lines += ["", f"## {section.title}", "", section.text.rstrip()]
        pngs = [f for f in section.files if f.suffix == ".png"]
        others = [f for f in section.files if f.suffix not in (".png", ".pdf")]
        for png in pngs:
            rel = png.relative_to(folder).as_posix()
            lines += [
                "",
                f"![{png.stem}]({rel}) ([PDF]({Path(rel).with_suffix('.pdf').as_posix()}))",
            ]
        if others:
            lines += [
                "",
                "Files: "
                + ", ".join(f"[{f.name}]({f.relative_to(folder).as_posix()})" for f in others),
            ]
    lines += ["", "## Commands", "", "Training:", "", "```sh"]
    lines += [r.command or f"# {r.path}: no command recorded in config.yaml" for r in runs]
    lines += ["```"]
    evaluations = [ev.meta.get("command") for r in runs for ev in collect.evaluations(r)]
    evaluations = list(dict.fromkeys(c for c in evaluations if c))
    if evaluations:
        lines += ["", "Evaluation:", "", "```sh", *evaluations, "```"]
    lines += ["", "This report:", "", "```sh", options.command or "adarl report …", "```"]
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    _write(folder, INDEX, "\n".join(lines) + "\n")
