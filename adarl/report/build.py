"""`build_report`: checks the input, writes the report into a temporary folder and swaps it
into place; `write_report` runs every section builder in the report's order, `write_index`
writes index.md; `write_scores_report` rebuilds the tables from earlier reports'
scores.csv."""

from __future__ import annotations

import os
import shutil
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from adarl import __version__, stats
from adarl.algos import registry
from adarl.errors import UsageError, check_choice, reason
from adarl.files import process_temp_dir, read_bytes, remove_orphans
from adarl.report import figures, selection, tables
from adarl.report.common import (
    INDEX,
    MARKER,
    PROFILE_TAUS,
    ReportOptions,
    ScoreNote,
    Section,
    seed_ids,
    write_file,
)
from adarl.report.comparisons import contrast_groups, contrast_section, control_section
from adarl.report.ranks import (
    ablation_section,
    bias_variance_section,
    policy_size_section,
    rank_section,
    spectra_section,
    training_section,
)
from adarl.report.robustness import robustness_section, suites_section
from adarl.report.scores import (
    SCORES_CSV,
    behaviour_section,
    best_of_section,
    environment_section,
    few_evaluations_notes,
    final_sources,
    long_scores,
    protocol_notes,
    run_scores,
    runs_section,
    score_line,
    scores_section,
    table1_section,
)
from adarl.report.statistics import statistics_sections
from adarl.results import collect
from adarl.results.runs import Run, find_runs, sort_methods, sort_tasks
from adarl.runs.checkpoints import checkpoint_dirs, select_checkpoint
from adarl.train.guards import check_memory


# ----------------------------------------------------------------------------- entry point
def build_report(
    paths: Sequence[str | os.PathLike], out: str | os.PathLike, options: ReportOptions
) -> Path:
    """Check the runs under `paths`, write the report to `out` atomically; returns `out`."""
    out = Path(out)
    if out.is_symlink():  # the report goes where the link points; the link stays
        out = Path(os.path.realpath(out))
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
    if index.is_file() and found.is_file() and MARKER in _head(index):
        return found
    return None


def _head(index: Path) -> str:
    """The start of a report's index.md (where its marker is), any bytes; "" if unreadable or
    not a regular file."""
    try:
        return read_bytes(index, 4096, head=True).decode("utf-8", errors="replace")
    except UsageError:
        return ""


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
    write_file(folder, INDEX, "\n".join(lines) + "\n")


def check_output(out: Path) -> None:
    """`out` may be new, empty, or a previous report (replaced); anything else is refused."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} is a file; give a folder for the report")
    if out.is_dir() and any(out.iterdir()):
        index = out / INDEX
        if not (index.is_file() and MARKER in _head(index)):
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
    training dynamics, or the row would compare methods on different problems; and one report
    holds one physics (MuJoCo C, MJX, MJX with a capped solver differ: docs/envs.md), whatever
    the task."""
    backends = {run.backend: run for run in runs}
    if len(backends) > 1:
        (a, first), (b, other) = sorted(backends.items())[:2]
        raise UsageError(
            f"runs {first.path} (backend {a}) and {other.path} (backend {b}) ran on different "
            "physics (host: MuJoCo C; device: MJX, with the XML's solver or a capped one); "
            "report them separately"
        )
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
            if registry.reports_best_checkpoint(r.algo)
            else r
            for r in runs
        ]
    tasks, methods = sort_tasks(r.task for r in runs), sort_methods(r.label for r in runs)
    runs = sorted(runs, key=lambda r: (tasks.index(r.task), methods.index(r.label), str(r.path)))
    fixed = [r for r in runs if registry.role(r.algo, "rank_sweep")]
    main = [r for r in runs if not registry.role(r.algo, "rank_sweep")] or fixed
    finals = {
        r.path: run_scores(r, options.last_k, best and registry.reports_best_checkpoint(r.algo))
        for r in runs
    }
    for r in runs:
        if finals[r.path][0].empty:
            notes.append(
                f"{r.path} has no nominal evaluation (neither `adarl evaluate --dynamics nominal` "
                "of its final checkpoint nor `nominal` rows in eval.csv); it is left out of the tables."
            )
    chosen = selection.select_best_of(main, long_scores(main, finals))
    scores = chosen.scores
    notes += chosen.notes
    notes += few_evaluations_notes(long_scores(runs, finals), options.last_k)
    colours = figures.method_colours([r.label for r in runs] + chosen.labels)
    score_note = ScoreNote(score_line(scores, options.last_k), final_sources(finals.values()))

    sections = [runs_section(runs, finals, folder)]
    sections.append(scores_section(long_scores(runs, finals), scores, finals, options, folder))
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


# ----------------------------------------------------------------------------- index.md
def write_index(
    folder: Path, runs: list[Run], sections: list[Section], options: ReportOptions, notes: list[str]
) -> None:
    order = sort_tasks(r.task for r in runs)
    methods = sort_methods(r.label for r in runs)
    budgets = sorted(
        {(r.task, r.label, r.total_steps, tuple(sorted(map(int, r.seeds)))) for r in runs},
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
        tables.markdown_table(  # how many seeds, then which: a lone seed 0 is not "0 seeds"
            ["task", "method", "steps per seed", "seeds", "seed ids"],
            [
                [t, m, f"{s:,}" if s is not None else "—", str(len(seeds)), seed_ids(seeds)]
                for t, m, s, seeds in budgets
            ],
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
    write_file(folder, INDEX, "\n".join(lines) + "\n")


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
