"""The baselines' protocol choices made after training, as the paper reports them.

* **Parseval's coefficient.** The paper trains `sac-parseval` with each coefficient in
  {1e-3, 1e-4, 1e-5} and reports the best per task. `select_parseval` does the same on a
  report's long scores (`task, method, seed, score, run`): per task, the coefficient whose runs
  have the highest mean final return (the Table 1 cell), under one label.
* **RNAC's checkpoint.** RNAC's original reports its best checkpoint by evaluation; the RNAC
  trainer keeps it next to the final one (docs/rnac.md), and `collect.best_scores` reads it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from adarl.algos import registry
from adarl.evaluation import tables
from adarl.evaluation.runs import Run, config_value, differing_fields, sort_tasks

# the algorithm whose best setting per task the main table keeps, and that setting (the
# registry's `best_of` role; the notes below are worded for Parseval's coefficient, its one user)
((PARSEVAL, COEF),) = [(a.name, a.best_of) for a in registry.ALGORITHMS.values() if a.best_of]
PARSEVAL_NOTE = "best of {n} coefficients (selected on the reported metric, as in the paper)"
RNAC_CHECKPOINTS = ("final", "best")
RNAC_BEST_LABEL = "best checkpoint"
RNAC_BEST_NOTE = (
    "each seed's best checkpoint by mean nominal evaluation return during training (selected on "
    "the reported metric, as RNAC's original reports it); its score is that evaluation's return"
)


def coef_text(coef: float) -> str:
    """1e-3 for 0.001; exact for any coefficient."""
    return np.format_float_scientific(coef, trim="-", exp_digits=1)


def parseval_label(n: int) -> str:
    """The method label of the selected coefficient in the main table."""
    return f"{PARSEVAL} (best of {n})"


@dataclass
class ParsevalSelection:
    """What `select_parseval` did: the scores to report, every coefficient's cell, notes."""

    scores: pd.DataFrame
    cells: pd.DataFrame  # task, parseval_coef, seeds, mean, std, selected
    labels: dict[str, str] = field(default_factory=dict)  # task -> label in the main table
    notes: list[str] = field(default_factory=list)


def select_parseval(runs: Sequence[Run], scores: pd.DataFrame) -> ParsevalSelection:
    """Per task with `sac-parseval` runs at two or more coefficients that differ in nothing else,
    keep the coefficient with the highest mean final return (ties: the larger coefficient) and
    relabel its scores `sac-parseval (best of N)`; drop the other coefficients' scores."""
    cells, labels, notes = [], {}, []
    by_task: dict[str, list[Run]] = {}
    for run in runs:
        if run.algo == PARSEVAL and config_value(run.config, COEF) is not None:
            by_task.setdefault(run.task, []).append(run)
    out = scores
    for task in sort_tasks(by_task):
        group = by_task[task]
        coefs = {float(config_value(r.config, COEF)) for r in group}
        if len(coefs) < 2:
            continue
        other = _other_differences(group)
        if other:
            notes.append(
                f"{PARSEVAL} runs on {task} differ in {', '.join(other)} as well as {COEF}; "
                "no coefficient was selected (each is shown on its own)."
            )
            continue
        paths = {str(r.path): float(config_value(r.config, COEF)) for r in group}
        rows = scores[scores["run"].isin(paths)]
        if rows.empty:
            continue
        rows = rows.assign(coef=rows["run"].map(paths))
        task_cells = coefficient_cells(rows)
        cells.append(task_cells)
        best = float(task_cells.loc[task_cells["selected"], COEF].iloc[0])
        labels[task] = label = parseval_label(len(coefs))
        keep = rows.index[rows["coef"] == best]
        drop = rows.index.difference(keep)
        out = out.drop(index=drop)
        out.loc[keep, "method"] = label
    columns = [*("task", COEF, "seeds", "mean", "std"), "selected"]
    cells = pd.concat(cells, ignore_index=True) if cells else pd.DataFrame(columns=columns)
    return ParsevalSelection(out.reset_index(drop=True), cells, labels, notes)


def coefficient_cells(rows: pd.DataFrame) -> pd.DataFrame:
    """Per task and coefficient (`task, coef, seed, score` rows): seeds, mean, std over seeds
    and `selected`, true for the highest mean per task (ties: the larger coefficient)."""
    from adarl.evaluation.stats import mean_std

    out = []
    for task, per_task in rows.groupby("task", sort=False):
        cells = []
        for coef, g in per_task.groupby("coef"):
            m, s = mean_std(g["score"].to_numpy(float))
            cells.append({"task": task, COEF: float(coef), "seeds": len(g), "mean": m, "std": s})
        cells.sort(key=lambda c: -c[COEF])
        means = [c["mean"] if np.isfinite(c["mean"]) else -np.inf for c in cells]
        top = int(np.argmax(means))
        for i, c in enumerate(cells):
            c["selected"] = i == top
        out += cells
    return pd.DataFrame(out, columns=["task", COEF, "seeds", "mean", "std", "selected"])


def parseval_markdown(cells: pd.DataFrame) -> str:
    """Task rows × coefficient columns, mean ± std over seeds, the selected cell in bold."""
    coefs = sorted(set(cells[COEF]), reverse=True)
    body = []
    for task in sort_tasks(cells["task"]):
        row = [task]
        for coef in coefs:
            hit = cells[(cells["task"] == task) & (cells[COEF] == coef)]
            if hit.empty:
                row.append(tables.DASH)
                continue
            c = hit.iloc[0]
            text = tables.format_mean_std(c["mean"], c["std"], int(c["seeds"]))
            row.append(f"**{text}**" if c["selected"] and text != tables.DASH else text)
        chosen = cells[(cells["task"] == task) & cells["selected"]]
        row.append(coef_text(float(chosen[COEF].iloc[0])) if not chosen.empty else tables.DASH)
        body.append(row)
    header = ["task", *(f"{COEF}={coef_text(c)}" for c in coefs), "selected"]
    return tables.markdown_table(header, body)


def _other_differences(group: Sequence[Run]) -> list[str]:
    """Config fields (besides the coefficient and launch fields) that differ within `group`."""
    return differing_fields([r.config for r in group], ignore={COEF})
