"""`adarl report`: everything a comparison needs from any set of run folders, in one folder.

`build_report(paths, out, options)` checks its input first (run folders, checkpoints, one
training setting per task), writes the whole report into a temporary folder next to `out` and
renames it into place at the end, so `out` is never half-written: on an error the previous
report (if any) stays as it was.

Layout of the report folder::

    index.md                 links everything; budget, seeds, the exact commands
    tables/scores.csv            every seed's score (mean of the last k evaluations) and final
                                 checkpoint score: everything the tables below are computed from
    tables/table1.{md,tex,csv}   nominal score per task × method (mean ± std over seeds)
    tables/aggregate.{md,csv}    IQM and mean with 95% stratified-bootstrap CIs
    tables/per_task.{md,csv}     mean per task and method with its 95% t interval
    tables/differences.{md,csv}  AdaRL − each baseline per task: Welch CI, permutation p, power
    tables/probability_of_improvement.{md,csv}
    tables/performance_profiles.csv
    tables/best-of-<algo>.{md,csv}  every value's cell of a best-of family (Table 1 keeps the
                                 best; today sac-parseval's coefficient)
    tables/contrast_FIELD.{md,csv}  with --contrast FIELD: differences along one setting, CIs
    tables/control_pairs.{md,csv}   AdaRL minus its schedule-matched control, seed by seed
    tables/fixed_rank.{md,csv}   score per fixed rank (bias–variance sweep)
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
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from adarl import __version__
from adarl.algos import registry
from adarl.errors import UsageError, check_choice, reason
from adarl.evaluation import behaviour, collect, compare, figures, selection, stats, tables
from adarl.evaluation.runs import (
    LAUNCH_KEYS,
    Run,
    config_value,
    differing_fields,
    find_runs,
    flatten_config,
    method_label,
    sort_methods,
    sort_tasks,
)
from adarl.files import process_temp_dir, remove_orphans
from adarl.runs import provenance
from adarl.runs.checkpoints import checkpoint_dirs, select_checkpoint
from adarl.runs.layout import EVAL_CSV
from adarl.train.guards import check_memory

REFERENCE = registry.REFERENCE
INDEX = "index.md"
MARKER = "<!-- adarl report -->"
PROFILE_TAUS = np.linspace(0.0, 1.0, 101)  # the performance profiles' thresholds


@dataclass
class ReportOptions:
    bootstrap_reps: int = 10_000
    confidence: float = 0.95
    seed: int = 0
    skip_incomplete: bool = False
    command: str = ""
    # algorithms that keep a best policy (RNAC): their final checkpoint, or their best by
    # evaluation (as RNAC's original reports)
    best_checkpoint: str = "final"
    contrasts: tuple[str, ...] = ()  # FIELD or FIELD=REFERENCE: differences along one setting
    last_k: int = 5  # a seed's score: the mean of its last k evaluations (eval.csv)
    power: float = 0.8  # power of the comparisons' "detectable difference" (two-sided t-test)
    alpha: float = 0.05  # its level
    target_difference: float = 300.0  # the difference whose seeds per arm each comparison gives


@dataclass
class Section:
    title: str
    text: str = ""
    files: list[Path] = field(default_factory=list)
    empty: bool = False  # nothing to show for these runs: left out of index.md (listed once)


@dataclass(frozen=True)
class ScoreNote:
    """The line under each table of scores: what the score is (`score_line`) and where the
    final-checkpoint scores came from (`final_sources`)."""

    text: str = ""
    final_from: str = ""

    def line(self, where: str) -> str:
        """`score: …; final checkpoint (<from>) in <where>.`; empty without a score."""
        if not self.text:
            return ""
        source = f" ({self.final_from})" if self.final_from else ""
        return f"{self.text}; final checkpoint{source} in {where}."


class Scored(NamedTuple):
    """A run's scores: `table` (`seed, score, final, evaluations, first_step, last_step,
    episodes`; `score` the primary score, `final` the final checkpoint's) and where each came
    from."""

    table: pd.DataFrame
    source: str
    final_source: str = ""


# ----------------------------------------------------------------------------- entry point
def build_report(
    paths: Sequence[str | os.PathLike], out: str | os.PathLike, options: ReportOptions
) -> Path:
    """Check the runs under `paths`, write the report to `out` atomically; returns `out`."""
    out = Path(out)
    check_output(out)
    if options.bootstrap_reps < 1:
        raise UsageError(f"--bootstrap-reps must be ≥ 1, got {options.bootstrap_reps}")
    check_memory(  # the largest bootstrap: a performance profile's points per resample
        stats.bootstrap_ci_bytes(options.bootstrap_reps, len(PROFILE_TAUS)),
        f"--bootstrap-reps {options.bootstrap_reps:,} (x {len(PROFILE_TAUS)} profile points)",
        "lower --bootstrap-reps (default 10,000)",
    )
    if options.last_k < 1:
        raise UsageError(f"--last-k must be ≥ 1, got {options.last_k}")
    check_choice("--best-checkpoint", options.best_checkpoint, selection.BEST_CHECKPOINTS)
    score_files = [scores_file(p) for p in paths]
    if any(score_files):
        return _build_from_scores(paths, score_files, out, options)
    runs, notes = usable_runs(find_runs(paths), options.skip_incomplete)
    check_rows(runs)
    for contrast in options.contrasts:
        contrast_groups(runs, contrast)  # a bad field or reference fails before anything is written
    tmp = _temp_folder(out)
    try:
        write_report(runs, tmp, options, notes)
        _swap_into_place(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def scores_file(path: str | os.PathLike) -> Path | None:
    """The `tables/scores.csv` that `path` names (the file itself, or an earlier report folder
    holding it); None for anything else (run folders)."""
    path = Path(path)
    if path.is_file() and path.name == SCORES_CSV:
        return path
    index, found = path / INDEX, path / "tables" / SCORES_CSV
    if index.is_file() and found.is_file() and MARKER in index.read_text(encoding="utf-8"):
        return found
    return None


def _build_from_scores(paths, score_files, out: Path, options: ReportOptions) -> Path:
    """Table 1 and the statistics recomputed from earlier reports' `tables/scores.csv`."""
    if not all(score_files):
        bad = next(p for p, f in zip(paths, score_files) if f is None)
        raise UsageError(
            f"{bad}: give either run folders or earlier reports (their tables/{SCORES_CSV}), "
            "not both"
        )
    if options.contrasts:
        raise UsageError("--contrast needs run folders (their configs), not scores.csv")
    scores = pd.concat([read_scores(f) for f in score_files], ignore_index=True)
    tmp = _temp_folder(out)
    try:
        write_scores_report(scores, [str(f) for f in score_files], tmp, options)
        _swap_into_place(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def read_scores(path: Path) -> pd.DataFrame:
    """An earlier report's scores.csv, checked for the columns a report needs and for numbers
    in its `seed` and `score` columns (one-line UsageErrors)."""
    try:
        scores = pd.read_csv(path, encoding="utf-8")
    except (UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise UsageError(f"{path} is not a report's scores.csv ({reason(exc)})") from None
    missing = [c for c in ("task", "method", "run", "seed", "score") if c not in scores]
    if missing:
        raise UsageError(f"{path} lacks the column(s) {', '.join(missing)} of a report's scores")
    for column in ("seed", "score"):
        bad = pd.to_numeric(scores[column], errors="coerce").isna() & scores[column].notna()
        if bad.any():
            line = int(np.flatnonzero(bad)[0]) + 2  # line 1: the header
            value = scores[column].iloc[line - 2]
            raise UsageError(f"{path} line {line}: {column} is {value!r}, not a number")
    return scores


def write_scores_report(
    scores: pd.DataFrame, sources: list[str], folder: Path, options: ReportOptions
) -> None:
    """The tables of scores (Table 1, aggregate, per task, differences, probability of
    improvement, profiles) from a scores table alone: the rows with a `table1_method` under
    that label (Parseval's selection and the fixed-rank sweep as the original report made
    them)."""
    (folder / "tables").mkdir(parents=True)
    (folder / "figures").mkdir()
    notes: list[str] = []
    if "table1_method" in scores:
        scores = scores[scores["table1_method"].notna()].assign(method=scores["table1_method"])
    scores = scores.reset_index(drop=True)
    k = int(scores["last_k"].max()) if "last_k" in scores and scores["last_k"].notna().any() else 0
    note = ScoreNote(
        score_line(scores, k) if k else "",
        " or ".join(dict.fromkeys(scores.get("final_from", pd.Series(dtype=str)).dropna())),
    )
    sections = [
        table1_section(scores, folder, (), note),
        *statistics_sections(scores, folder, options, notes, note),
    ]
    lines = [MARKER, "# adarl report", "", f"Made by adarl {__version__} from the per-seed scores "
             f"of {', '.join(f'`{s}`' for s in sources)} (no run folders: no curves, behaviour, "
             "robustness or contrasts)."]  # fmt: skip
    lines += _section_lines(folder, sections)
    lines += ["", "## Commands", "", "```sh", options.command or "adarl report …", "```"]
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    _write(folder, INDEX, "\n".join(lines) + "\n")


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
            select_checkpoint(run.path)  # raises the one-line error naming the folder
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


def _temp_folder(out: Path) -> Path:
    """The folder the report is written into before it replaces `out`; first removes those a
    report into `out` that was killed left behind (`adarl.files.remove_orphans`)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    for kind in ("tmp", "old"):
        remove_orphans(out.parent, f".{out.name}.{kind}-")
    return process_temp_dir(out.parent, f".{out.name}.tmp-")


def _swap_into_place(tmp: Path, out: Path) -> None:
    old = None
    if out.exists():
        old = process_temp_dir(out.parent, f".{out.name}.old-")
        os.rmdir(old)
        os.replace(out, old)
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


# ----------------------------------------------------------------------------- the report
def write_report(runs: list[Run], folder: Path, options: ReportOptions, notes: list[str]) -> None:
    (folder / "tables").mkdir(parents=True)
    (folder / "figures").mkdir()
    best = options.best_checkpoint == "best"
    if best:
        runs = [
            replace(r, label=f"{r.label} ({selection.BEST_CHECKPOINT_LABEL})")
            if registry.keeps_best_policy(r.algo)
            else r
            for r in runs
        ]
    tasks, methods = sort_tasks(r.task for r in runs), sort_methods(r.label for r in runs)
    runs = sorted(runs, key=lambda r: (tasks.index(r.task), methods.index(r.label), str(r.path)))
    fixed = [r for r in runs if registry.role(r.algo, "rank_sweep")]
    main = [r for r in runs if not registry.role(r.algo, "rank_sweep")] or fixed
    finals = {
        r.path: run_scores(r, options.last_k, best and registry.keeps_best_policy(r.algo))
        for r in runs
    }
    for r in runs:
        if finals[r.path][0].empty:
            notes.append(
                f"{r.path} has no nominal evaluation (neither `adarl evaluate --dynamics nominal` "
                "of its final checkpoint nor `nominal` rows in eval.csv); it is left out of the tables."
            )
    chosen = selection.select_best_of(main, _long_scores(main, finals))
    scores = chosen.scores
    notes += chosen.notes
    notes += few_evaluations_notes(_long_scores(runs, finals), options.last_k)
    colours = figures.method_colours([r.label for r in runs] + chosen.labels)
    score_note = ScoreNote(score_line(scores, options.last_k), final_sources(finals.values()))

    sections = [runs_section(runs, finals, folder)]
    sections.append(scores_section(_long_scores(runs, finals), scores, finals, options, folder))
    sections.append(
        table1_section(scores, folder, protocol_notes(runs, chosen, options), score_note)
    )
    sections += [best_of_section(family, folder) for family in chosen.families]
    sections.append(behaviour_section(main, folder))
    sections += statistics_sections(scores, folder, options, notes, score_note)
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


def run_scores(run: Run, k: int, best: bool = False) -> Scored:
    """Each seed's primary score and final-checkpoint score.

    Primary: the mean of the last `k` evaluations logged during training
    (`collect.last_k_scores`); `best` (RNAC's best checkpoint): that checkpoint's evaluation
    return (`collect.best_scores`); a run that logged no evaluation: its final checkpoint.
    Final checkpoint: `collect.final_scores` (`adarl evaluate` of it, else the last eval.csv
    evaluation)."""
    final, final_source = collect.final_scores(run)
    if best:
        primary, source = collect.best_scores(run)
    else:
        primary, source = collect.last_k_scores(run, k)
        if primary.empty and not final.empty:
            primary, source = final, f"final checkpoint ({final_source}; no evaluation logged)"
    if primary.empty:
        return Scored(pd.DataFrame(columns=SCORE_COLUMNS), source, final_source)
    table = primary.merge(final.rename(columns={"score": "final"}), on="seed", how="left")
    return Scored(table.reindex(columns=SCORE_COLUMNS), source, final_source)


SCORE_COLUMNS = ["seed", "score", "final", "evaluations", "first_step", "last_step", "episodes"]


def _long_scores(runs: Sequence[Run], finals: dict) -> pd.DataFrame:
    frames = [
        finals[r.path][0].assign(task=r.task, method=r.label, run=str(r.path))
        for r in runs
        if not finals[r.path][0].empty
    ]
    if not frames:
        return pd.DataFrame(columns=["seed", "score", "task", "method", "run"])
    return pd.concat(frames, ignore_index=True)


def _steps(first: float, last: float) -> str:
    return f"{first:,.0f}" if first == last else f"{first:,.0f}–{last:,.0f}"


def final_sources(scored) -> str:
    """Where the final-checkpoint scores came from, in a few words: `adarl evaluate` (with its
    episodes) and/or the last evaluation in eval.csv."""
    kinds = []
    for item in scored:
        source = item[2] if len(item) > 2 else ""
        if source.startswith("`adarl evaluate`"):
            kinds.append(source.split(",")[0].replace(" (", ", "))
        elif source.startswith(EVAL_CSV):
            kinds.append("the last evaluation in eval.csv")
    return " or ".join(dict.fromkeys(kinds))


def score_line(scores: pd.DataFrame, k: int) -> str:
    """What the tables' score is, for the line under each table: "score: mean of the last 5
    evaluations (steps 60,000–100,000), 5 episodes each", with the runs that had fewer
    evaluations and those scored otherwise (RNAC's best checkpoint, no evaluation logged)."""
    if scores.empty:
        return ""
    logged = scores.dropna(subset=["evaluations"]) if "evaluations" in scores else scores.iloc[0:0]
    parts = []
    if not logged.empty:
        spans = logged.groupby(["first_step", "last_step"], sort=True)
        if spans.ngroups == 1:
            (first, last), _ = next(iter(spans))
            where = f"steps {_steps(first, last)}"
        elif spans.ngroups <= 3:
            where = "steps " + "; ".join(
                f"{_steps(first, last)} for {', '.join(sorted(set(g['task'] + ' ' + g['method'])))}"
                for (first, last), g in spans
            )
        else:
            where = "steps per seed in tables/scores.csv"
        low, high = int(logged["episodes"].min()), int(logged["episodes"].max())
        episodes = (
            f"{low} episode{'s' if high > 1 else ''}" if low == high else f"{low}–{high} episodes"
        )
        parts.append(f"mean of the last {k} evaluations ({where}), {episodes} each")
        short = logged[logged["evaluations"] < k]
        if not short.empty:
            few = short.groupby(["task", "method"])["evaluations"].min()
            parts.append(
                "fewer evaluations than that, all of them used: "
                + ", ".join(f"{t} {m} ({n})" for (t, m), n in few.items())
            )
    others = scores[~scores.index.isin(logged.index)]
    if not others.empty:
        labels = sorted(set(others["task"] + " " + others["method"]))
        best = [lab for lab in labels if selection.BEST_CHECKPOINT_LABEL in lab]
        rest = [lab for lab in labels if lab not in best]
        if best:
            parts.append(f"{', '.join(best)}: the best checkpoint's evaluation return")
        if rest:
            parts.append(f"{', '.join(rest)}: the final checkpoint (no evaluation logged)")
    return "score: " + "; ".join(parts)


def few_evaluations_notes(scores: pd.DataFrame, k: int) -> list[str]:
    """One note per run whose seeds logged fewer than `k` evaluations."""
    if scores.empty or "evaluations" not in scores:
        return []
    short = scores[scores["evaluations"] < k]
    return [
        f"{run}: {int(g['evaluations'].min())} evaluation(s) logged, fewer than --last-k {k}; "
        "its score is the mean of those it has."
        for run, g in short.groupby("run", sort=False)
    ]


SCORES_CSV = "scores.csv"


def scores_section(
    scores: pd.DataFrame, table1: pd.DataFrame, finals: dict, options: ReportOptions, folder: Path
) -> Section:
    """`tables/scores.csv`: every seed's scores, the input of Table 1 and the statistics, with
    `table1_method` (its label in Table 1 and the statistics, empty for runs they leave out),
    `last_k` and where the scores came from: `adarl report tables/scores.csv` recomputes the
    tables from it alone."""
    if not scores.empty:
        by_run = {str(path): scored for path, scored in finals.items()}
        labels = table1[["run", "seed", "method"]].rename(columns={"method": "table1_method"})
        scores = scores.merge(labels, on=["run", "seed"], how="left").assign(
            last_k=options.last_k,
            score_from=lambda df: df["run"].map(lambda r: by_run[r][1]),
            final_from=lambda df: df["run"].map(lambda r: final_sources([by_run[r]])),
        )
    columns = ["task", "method", "run", *SCORE_COLUMNS, "table1_method", "last_k", "score_from",
               "final_from"]  # fmt: skip
    # full precision: a report recomputed from this file gives the same tables
    path = _write(
        folder, f"tables/{SCORES_CSV}", scores.reindex(columns=columns).to_csv(index=False)
    )
    text = (
        "Every seed's score (the tables' primary score, `score`) and final-checkpoint score "
        "(`final`), with the evaluations averaged: the input of Table 1, the statistics and the "
        "comparisons below (column `table1_method`: Parseval's selected coefficient, not the "
        "fixed-rank sweep). `adarl report <this report> --out DIR` recomputes those tables "
        "from this file alone.\n"
    )
    return Section("Scores per seed", text, [path], empty=scores.empty)


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
                "score from": finals[r.path][1],
                "final checkpoint from": finals[r.path][2] if len(finals[r.path]) > 2 else "",
            }
        )
    df = pd.DataFrame(rows)
    path = _write(folder, "tables/runs.csv", df.to_csv(index=False))
    text = tables.markdown_table(
        list(df.columns), df.astype(object).where(df.notna(), "—").values.tolist()
    )
    return Section("Runs", text, [path])


TABLE1 = "Table 1: return under nominal dynamics"


def _final_table(scores: pd.DataFrame) -> tables.ScoreTable | None:
    """The final-checkpoint scores (`final` column) as a `ScoreTable`; None without them."""
    if "final" not in scores or scores["final"].isna().all():
        return None
    return tables.score_table(scores.assign(score=scores["final"]).dropna(subset=["score"]))


def table1_section(
    scores: pd.DataFrame,
    folder: Path,
    labels: Sequence[str] = (),
    score_note: ScoreNote = ScoreNote(),
) -> Section:
    """Table 1 on the primary score, each task followed by a row of the final checkpoint's;
    `labels` explain method labels (Parseval's selection, RNAC's checkpoint) below the table, in
    the LaTeX caption and in the report text; `score_note` says what the score is."""
    if scores.empty:
        return Section(TABLE1, "No nominal evaluations found.\n")
    table, final = tables.score_table(scores), _final_table(scores)
    caption = "Return under nominal dynamics, mean ± standard deviation over seeds."
    score = score_note.line(f"the rows “<task>, {tables.FINAL_ROW}”")
    legend = "".join(f"\n{line}\n" for line in [score, *labels] if line)
    full_caption = " ".join(line for line in [caption, score, *labels] if line)
    full_caption = full_caption.replace("`", "")
    md = tables.table_markdown(table, second=final)
    files = [
        _write(folder, "tables/table1.md", md + legend),
        _write(
            folder,
            "tables/table1.tex",
            tables.table_latex(table, caption=full_caption, second=final),
        ),
        _write(folder, "tables/table1.csv", tables.table_csv(table, second=final)),
    ]
    text = (
        f"{caption} The best mean per task is in bold. Seeds per cell: "
        f"{_seed_counts(table)}.\n\n{md}{legend}"
    )
    return Section(TABLE1, text, files)


def behaviour_section(runs: list[Run], folder: Path) -> Section:
    """Episode length and forward distance of the final policies on nominal dynamics, and what
    each seed does in one word (`behaviour.describe`): a return of ~1,000 on Hopper can be a
    policy that stands still for 1,000 steps."""
    frames = [collect.final_behaviour(r).assign(task=r.task, method=r.label) for r in runs]
    df = pd.concat([f for f in frames if not f.empty] or [pd.DataFrame()], ignore_index=True)
    title = "What the final policies do"
    if df.empty:
        return Section(title, "No nominal evaluations found.\n")
    df["does"] = [
        behaviour.describe(length, limit, distance)
        for length, limit, distance in zip(df["length"], df["max_length"], df["distance"])
    ]
    rows = []
    for (task, method), group in df.groupby(["task", "method"], sort=False):
        cells = [task, method]
        for column, digits in (("length", 0), ("distance", 2)):
            values = group[column].dropna().to_numpy(float)
            mean, std = stats.mean_std(values) if len(values) else (np.nan, np.nan)
            cells.append(tables.format_mean_std(mean, std, len(values), digits))
        counts = group["does"].value_counts()
        cells.append(", ".join(f"{w} {counts[w]}" for w in behaviour.WORDS if w in counts))
        rows.append(cells)
    md = tables.markdown_table(
        ["task", "method", "episode length", "forward distance (m)", "seeds that …"], rows
    )
    columns = ["task", "method", "seed", "length", "max_length", "distance", "does"]
    path = _write(folder, "tables/behaviour.csv", _csv(df[columns]))
    limits = sorted({int(v) for v in df["max_length"]})
    text = (
        f"Mean episode length (steps, of at most {'/'.join(f'{v:,}' for v in limits)}) and "
        "forward distance of the root body (metres) of each seed's final policy on nominal "
        "dynamics, mean ± std over seeds, and how many seeds fall, stand or move "
        f"({behaviour.rule_text()}). A Hopper policy that only balances earns about 1,000 in "
        "1,000 steps while moving ~0 m; rank methods by return only together with this table. "
        "Distance is recorded by `adarl evaluate` (— where only the training log exists).\n\n" + md
    )
    return Section(title, text, [path])


def protocol_notes(
    runs: Sequence[Run], chosen: selection.Selection, options: ReportOptions
) -> list[str]:
    """One line per method label that carries a protocol choice: the value a best-of family
    was selected at (Parseval's coefficient), a best-policy algorithm's final or best
    checkpoint (RNAC's)."""
    lines = []
    for family in chosen.families:
        for label in sorted(set(family.labels.values())):
            tasks = [t for t, lab in family.labels.items() if lab == label]
            cells = family.cells
            picked = cells[cells["selected"] & cells["task"].isin(tasks)]
            picks = ", ".join(
                f"{t} {selection.value_text(v)}"
                for t, v in zip(picked["task"], picked[family.field])
            )
            n = int(re.search(r"best of (\d+)", label).group(1))
            lines.append(
                f"{label}: {selection.BEST_OF_NOTE.format(n=n, field=family.field)}; chosen "
                f"{family.field}: {picks}; every value: tables/{family.table_stem}.md."
            )
    kept = ", ".join(sort_methods(r.label for r in runs if registry.keeps_best_policy(r.algo)))
    if kept and options.best_checkpoint == "best":
        lines.append(f"{kept}: {selection.BEST_CHECKPOINT_NOTE}.")
    elif kept:
        lines.append(
            f"{kept}: the final checkpoint (`--best-checkpoint best` shows the best checkpoint "
            "by evaluation, as RNAC's original reports)."
        )
    return lines


def best_of_section(family: selection.BestOf, folder: Path) -> Section:
    md = selection.best_of_markdown(family)
    files = [
        _write(folder, f"tables/{family.table_stem}.md", md),
        _write(folder, f"tables/{family.table_stem}.csv", _csv(family.cells)),
    ]
    text = (
        f"Score under nominal dynamics (Table 1's) of `{family.algo}` at each value of "
        f"{family.field}, mean ± standard deviation over seeds. As in the paper, Table 1 and the "
        "statistics report, per task, the value with the highest mean (in bold; ties: the larger "
        "value), chosen on the same metric it reports, so that cell is optimistic.\n\n" + md
    )
    return Section(f"Supplementary: {family.algo} at each {family.field}", text, files)


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
    """The scores of every seed of `runs`, pooled."""
    return np.concatenate([finals[r.path][0]["score"].to_numpy(float) for r in runs])


def contrast_section(
    runs: list[Run], finals: dict, contrast: str, folder: Path, options: ReportOptions
) -> Section:
    """Score of each value of one setting minus the reference value's, among runs that agree on
    everything else: Welch interval, exact permutation p and power (`stats.compare_groups`)."""
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
            comparison = stats.compare_groups(
                other, base, options.target_difference, options.confidence, options.power,
                options.alpha,
            )  # fmt: skip
            rows.append(
                {
                    "task": task,
                    "method": method,
                    "held fixed": others or "—",
                    "contrast": f"{field}: {value} − {reference}",
                    f"mean ({reference})": base.mean(),
                    "mean (other)": other.mean(),
                    **compare.comparison_row(comparison),
                }
            )
    df = pd.DataFrame(rows)
    if not df.empty:
        df = df.rename(columns={"low": "ci low", "high": "ci high", "p_value": "p"})
    stem = f"tables/contrast_{_slug(field)}"
    files = [_write(folder, f"{stem}.csv", _csv(df))]
    if df.empty:
        return Section(f"Contrast: {field}", f"No pair of runs differs only in `{field}`.", files)
    pct, level = int(round(100 * options.confidence)), f"{options.power:.0%}"
    md = tables.markdown_table(
        ["task", "method", "held fixed", "contrast", f"mean ({reference})", "mean (other)",
         f"difference [{pct}% CI, Welch]", "p", "seeds", f"detectable at {level}",
         f"seeds for {options.target_difference:g}"],
        [
            [r["task"], r["method"], r["held fixed"], r["contrast"],
             f"{r[f'mean ({reference})']:.1f}", f"{r['mean (other)']:.1f}",
             f"{r['difference']:.1f} {_ci(r['ci low'], r['ci high'], 1)}".replace(f" {tables.DASH}", ""),
             _p(r["p"]), r["seeds"], _detectable(r["detectable"]), _seeds_for(r["seeds_for_target"])]
            for r in df.to_dict("records")
        ],
    )  # fmt: skip
    files.append(_write(folder, f"{stem}.md", md))
    text = (
        f"Score with `{field}` set to each value minus the same runs' setting at `{reference}`, "
        f"everything else equal; {pct}% Welch t interval over seeds (each side's seeds "
        "independent). An interval that contains 0 shows no difference at this number of "
        "seeds.\n\n" + md + "\n" + _power_text(options) + "\n"
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
    per-seed difference of the score (as Table 1's: the mean of the last k evaluations) gets a
    Student-t interval (`stats.paired_difference_ci`). None without control runs."""
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
        sd_diff = float(np.std(x - y, ddof=1)) if len(seeds) > 1 else float("nan")
        detectable = stats.paired_minimum_detectable_difference(sd_diff, len(seeds), options.power)
        needed = stats.paired_seeds_needed(options.target_difference, sd_diff, options.power)
        summary.append(
            [method.task, method.label, control.label, str(len(seeds)), f"{x.mean():.1f}",
             f"{y.mean():.1f}", f"{ci.point:.1f} [{ci.low:.1f}, {ci.high:.1f}]",
             f"{stats.paired_permutation_p_value(x, y):.3g}", f"{detectable:.0f}",
             f"{needed:.0f}"]
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
         f"method − control [{pct}% t CI]", "sign-flip p",
         f"detectable at {options.power:.0%} power (paired)",
         f"pairs for {options.target_difference:g}"],
        summary,
    )  # fmt: skip
    files.append(_write(folder, "tables/control_pairs.md", md))
    text = (
        "The score (as Table 1) of AdaRL minus its schedule-matched control (the same "
        "truncations, resets and warm-ups, no component removed), seed by seed: a control seed is "
        f"paired with the AdaRL seed of the same number; {pct}% Student-t interval of the mean "
        "per-seed difference, the exact sign-flip permutation p-value, the smallest difference "
        "the paired t-test detects at that power with these pairs and their spread, and the pairs "
        "a difference of the target size would need. Per-seed rows: tables/control_pairs.csv."
        "\n\n" + md
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
    return f"{point:.{digits}f}", _ci(low, high, digits)


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


def _final_scores(scores: pd.DataFrame) -> pd.DataFrame:
    """`scores` with the final checkpoint's score as `score` (seeds without one dropped)."""
    if "final" not in scores:
        return scores.iloc[0:0]
    return scores.assign(score=scores["final"]).dropna(subset=["score"])


def _ci(low: float, high: float, digits: int) -> str:
    """`[low, high]`, or a dash where there is no interval (one seed)."""
    if not (np.isfinite(low) and np.isfinite(high)):
        return tables.DASH
    return f"[{low:.{digits}f}, {high:.{digits}f}]"


def _power_text(options: ReportOptions) -> str:
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


def _seeds_for(value: float) -> str:
    return f"{value:,.0f}" if np.isfinite(value) else tables.DASH


def _detectable(value: float) -> str:
    return f"{value:,.0f}" if np.isfinite(value) else tables.DASH


def _p(value: float) -> str:
    return f"{value:.3f}" if np.isfinite(value) else tables.DASH


def aggregate_section(
    scores: pd.DataFrame,
    normalised: compare.Normalised,
    folder: Path,
    options: ReportOptions,
    score_note: ScoreNote = ScoreNote(),
) -> Section:
    reps, conf = options.bootstrap_reps, options.confidence
    estimates = compare.aggregate_estimates(normalised, reps, conf, options.seed)
    final_scores = _final_scores(scores)
    if not final_scores.empty:
        final = compare.aggregate_estimates(
            compare.normalise(final_scores), reps, conf, options.seed
        )
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
    files = [_write(folder, "tables/aggregate.csv", _csv(estimates))]
    rows = []
    for method, matrix in normalised.matrices.items():
        by_metric = estimates[estimates["method"] == method].set_index("metric")
        cells = [method]
        for metric in ("IQM", "Mean"):
            point, low, high = by_metric.loc[metric, ["point", "low", "high"]]
            cells += [f"{point:.3f}", _ci(low, high, 3) if matrix.shape[0] > 1 else tables.DASH]
        for metric in ("IQM", "Mean"):
            value = by_metric.loc[metric].get("final_point", np.nan)
            cells.append(f"{value:.3f}" if np.isfinite(value) else tables.DASH)
        rows.append([*cells, f"{matrix.shape[0]} × {matrix.shape[1]}"])
    header = ["method", "IQM", f"IQM {conf:.0%} CI", "mean", f"mean {conf:.0%} CI",
              "IQM, final checkpoint", "mean, final checkpoint", "seeds × tasks"]  # fmt: skip
    md = tables.markdown_table(header, rows)
    line = score_note.line("the columns “…, final checkpoint” (intervals in aggregate.csv)")
    line = f"\n{line}\n" if line else ""
    files.append(_write(folder, "tables/aggregate.md", md + line))
    files += _figure(folder, figures.aggregate_intervals(estimates), "aggregate_iqm_mean")
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
            f"{r.final_mean:.1f} {_ci(r.final_low, r.final_high, 1)}".replace(f" {tables.DASH}", "")
            if has_final and np.isfinite(r.final_mean)
            else tables.DASH
        )
        rows.append(
            [r.task, r.method, r.seeds, f"{r.mean:.1f}", _ci(r.mean_low, r.mean_high, 1),
             _number(r.sd), f"{r.iqm:.1f}", final]
        )  # fmt: skip
    header = ["task", "method", "seeds", "mean", f"{conf:.0%} CI (t)", "sd", "IQM",
              f"final checkpoint [{conf:.0%} CI]"]  # fmt: skip
    md = tables.markdown_table(header, rows)
    line = score_note.line("the column “final checkpoint”")
    line = f"\n{line}\n" if line else ""
    files = [
        _write(folder, "tables/per_task.csv", _csv(estimates)),
        _write(folder, "tables/per_task.md", md + line),
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
         f"{r.difference:.1f} {_ci(r.low, r.high, 1)}".replace(f" {tables.DASH}", ""),
         _p(r.p_value), _detectable(r.detectable), _seeds_for(r.seeds_for_target)]
        for r in differences.itertuples()
    ]  # fmt: skip
    header = ["task", "comparison", "seeds", f"difference [{conf:.0%} CI, Welch]", "p",
              f"detectable at {level}", f"seeds for {target:g}"]  # fmt: skip
    md = tables.markdown_table(header, rows)
    files = [
        _write(folder, "tables/differences.csv", _csv(differences)),
        _write(folder, "tables/differences.md", md),
    ]
    text = (
        f"Mean score of {REFERENCE} minus each baseline's on the same task, with Welch's t "
        "interval (each method's seeds independent; `stats.welch_difference_ci`). An interval "
        "that contains 0 shows no difference at these seeds.\n\n"
        + md + "\n" + _power_text(options) + "\n"
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
         _ci(r.low, r.high, 3) if r.min_seeds > 1 else tables.DASH,
         per_task(r.baseline, "detectable", _detectable),
         per_task(r.baseline, "seeds_for_target", _seeds_for)]
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
        _write(folder, "tables/probability_of_improvement.csv", _csv(estimates)),
        _write(folder, "tables/probability_of_improvement.md", md),
    ]
    fig = figures.probability_of_improvement(estimates, REFERENCE)
    return Section(title, text, files + _figure(folder, fig, "probability_of_improvement"))


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
    files = [_write(folder, "tables/performance_profiles.csv", _csv(frame))]
    files += _figure(folder, figures.performance_profiles(taus, profiles), "performance_profiles")
    text = (
        "Fraction of runs (seeds × tasks) whose normalised score exceeds τ, with "
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
        return Section("Training curves", "No evaluation or episode logs found.\n", empty=True)
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
        return Section("Rank over training", "No rank-adaptive runs.\n", empty=True)
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
    conf = options.confidence
    order = sort_tasks(k[0] for k in found)
    methods = sort_methods(k[2] for k in found)
    keys = sorted(found, key=lambda k: (order.index(k[0]), k[1], methods.index(k[2])))
    rows, files = [], []
    for task, name, method in keys:
        summary = pd.concat([s for s, _ in found[(task, name, method)]], ignore_index=True)
        estimate = suites.aggregate(summary, conf)
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
        f"with a {conf:.0%} Student-t interval over seeds (none from one seed). "
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
        files += _figure(folder, fig, f"bias_variance_{task}")
        table = tables.score_table(
            data.assign(task=task, method=data["rank"].map(lambda k: f"r={k}"))
        )
        rows = [[f"r={k}", table.cell(task, f"r={k}")] for k in sorted(data["rank"].unique())]
        md = tables.markdown_table(["rank", f"{task}: score"], rows)
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
        files += _figure(folder, fig, f"rank_rule_ablation_{task}")
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
            fig = figures.singular_value_spectra(found, f"{r.task} {r.label}")
            files += _figure(folder, fig, f"spectra_{r.task}_{r.label}")
    text = (
        "Singular values of each bottleneck at each truncation (mean over seeds).\n"
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
    lines += _section_lines(folder, sections)
    lines += ["", "## Commands", "", "Training:", "", "```sh"]
    lines += [r.command or f"# {r.path}: no command recorded in config.yaml" for r in runs]
    lines += ["```"]
    evaluations = [ev.meta.get("command") for r in runs for ev in collect.evaluations(r)]
    evaluations = list(dict.fromkeys(c for c in evaluations if c))
    if evaluations:
        lines += ["", "Evaluation:", "", "```sh", *evaluations, "```"]
    lines += ["", "This report:", "", "```sh", options.command or "adarl report …", "```"]
    hidden = [s.title for s in sections if s.empty]
    if hidden:
        notes = [*notes, f"Not shown (nothing to show for these runs): {', '.join(hidden)}."]
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    _write(folder, INDEX, "\n".join(lines) + "\n")


def _section_lines(folder: Path, sections: list[Section]) -> list[str]:
    """index.md's lines for `sections` (those with something to show): text, figures, files."""
    lines = []
    for section in (s for s in sections if not s.empty):
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
    return lines
