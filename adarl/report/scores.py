"""Each seed's score (`run_scores`) and the sections that list runs and scores: runs,
scores.csv, Table 1, what the final policies do, best-of families, environments."""

from __future__ import annotations

import re
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from adarl import stats
from adarl.algos import registry
from adarl.report import behaviour, selection, tables
from adarl.report.common import (
    ReportOptions,
    Scored,
    ScoreNote,
    Section,
    csv_text,
    final_checkpoint_scores,
    write_file,
)
from adarl.results import collect
from adarl.results.runs import Run, sort_methods
from adarl.runs import provenance
from adarl.runs.layout import EVAL_CSV


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


def long_scores(runs: Sequence[Run], finals: dict) -> pd.DataFrame:
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


def final_sources(scored: list[Scored]) -> str:
    """Where the final-checkpoint scores came from, in a few words: `adarl evaluate` (with its
    episodes) and/or the last evaluation in eval.csv."""
    kinds = []
    for item in scored:
        source = item.final_source
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
    path = write_file(
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
                "seed ids": " ".join(map(str, r.seeds)),  # ids, not a count
                "budget (steps per seed)": r.total_steps,
                "final checkpoint": last,
                "finished": "yes" if r.done_step is not None else "no",
                "score from": finals[r.path].source,
                "final checkpoint from": finals[r.path].final_source,
            }
        )
    df = pd.DataFrame(rows)
    path = write_file(folder, "tables/runs.csv", df.to_csv(index=False))
    text = tables.markdown_table(
        list(df.columns), df.astype(object).where(df.notna(), "—").values.tolist()
    )
    return Section("Runs", text, [path])


TABLE1 = "Table 1: return under nominal dynamics"


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
    table, final = tables.score_table(scores), final_checkpoint_scores(scores)
    final = None if final.empty else tables.score_table(final)
    caption = "Return under nominal dynamics, mean ± standard deviation over seeds."
    score = score_note.line(f"the rows “<task>, {tables.FINAL_ROW}”")
    legend = "".join(f"\n{line}\n" for line in [score, *labels] if line)
    full_caption = " ".join(line for line in [caption, score, *labels] if line)
    full_caption = full_caption.replace("`", "")
    md = tables.table_markdown(table, second=final)
    files = [
        write_file(folder, "tables/table1.md", md + legend),
        write_file(
            folder,
            "tables/table1.tex",
            tables.table_latex(table, caption=full_caption, second=final),
        ),
        write_file(folder, "tables/table1.csv", tables.table_csv(table, second=final)),
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
        cells.append(  # seeds that … fall 2, stand 1
            ", ".join(f"{behaviour.plural(w)} {counts[w]}" for w in behaviour.WORDS if w in counts)
        )
        rows.append(cells)
    md = tables.markdown_table(
        ["task", "method", "episode length", "forward distance (m)", "seeds that …"], rows
    )
    columns = ["task", "method", "seed", "length", "max_length", "distance", "does"]
    path = write_file(folder, "tables/behaviour.csv", csv_text(df[columns]))
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
    kept = ", ".join(
        sort_methods(r.label for r in runs if registry.reports_best_checkpoint(r.algo))
    )
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
        write_file(folder, f"tables/{family.table_stem}.md", md),
        write_file(folder, f"tables/{family.table_stem}.csv", csv_text(family.cells)),
    ]
    text = (
        f"Score under nominal dynamics (Table 1's) of `{family.algo}` at each value of "
        f"{family.field}, mean ± standard deviation over seeds. As in the paper, Table 1 and the "
        "statistics report, per task, the value with the highest mean (in bold; ties: the larger "
        "value), chosen on the same metric it reports, so that cell is optimistic.\n\n" + md
    )
    return Section(f"Supplementary: {family.algo} at each {family.field}", text, files)


def _seed_counts(table: tables.ScoreTable) -> str:
    counts = sorted({int(c) for c in table.count.to_numpy().ravel() if c > 0})
    return ", ".join(map(str, counts))


def environment_section(runs: list[Run], folder: Path, notes: list[str]) -> Section:
    """What produced each run (its environment.json; "unknown" without one), and one warning per
    package of `provenance.COMPARED` whose version differs between runs and per run resumed with
    other code (`provenance.code_changes`), in the notes and on stderr."""
    records = {str(r.path): provenance.read_environment(r.path) for r in runs}
    df = pd.DataFrame([{"run": run, **provenance.summary(rec)} for run, rec in records.items()])
    path = write_file(folder, "tables/environments.csv", df.to_csv(index=False))
    resumed = [
        f"run {run} was resumed with other code: {'; '.join(changes)}"
        for run, record in records.items()
        if (changes := provenance.code_changes(record))
    ]
    for line in provenance.mismatches(records) + resumed:
        notes.append(f"Warning: {line}.")
        print(f"adarl: warning: {line}", file=sys.stderr)
    text = tables.markdown_table(list(df.columns), df.values.tolist())
    return Section("Environments", text, [path])
