"""The protocol choices the report makes after training, as the paper reports them.

* **Best of N.** An algorithm with a `best_of` field in the registry (today `sac-parseval`'s
  coefficient: the paper trains it at {1e-3, 1e-4, 1e-5} and reports the best per task) is
  reported at its best value of that field per task. `select_best_of` does this for every such
  family on a report's long scores (`task, method, seed, score, run`): per task, the value whose
  runs have the highest mean final return (the Table 1 cell), under one label.
* **Best checkpoint.** An algorithm whose original reports each seed's best checkpoint by
  evaluation (the registry's `best_checkpoint`: RNAC) is scored at its final checkpoint, or at its
  best with `adarl report --best-checkpoint best`; `collect.best_scores` reads the best policy
  the loop keeps for every run.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from adarl.algos import registry
from adarl.report import tables
from adarl.results.runs import Run, config_value, differing_fields, sort_tasks

BEST_OF_NOTE = "best of {n} values of {field} (selected on the reported metric, as in the paper)"
BEST_CHECKPOINTS = ("final", "best")
BEST_CHECKPOINT_LABEL = "best checkpoint"
BEST_CHECKPOINT_NOTE = (
    "each seed's best checkpoint by mean nominal evaluation return during training (selected on "
    "the reported metric, as RNAC's original reports it); its score is that evaluation's return"
)


def best_of_families() -> dict[str, str]:
    """Every algorithm reported at its best value of a field -> that field (registry order)."""
    return {a.name: a.best_of for a in registry.ALGORITHMS.values() if a.best_of}


def value_text(value: float) -> str:
    """A field value in labels and headers: 1e-3 for 0.001 (exact), 7 for 7.0, 0.5 for 0.5."""
    value = float(value)
    if value != 0 and not 1e-2 <= abs(value) < 1e4:
        return np.format_float_scientific(value, trim="-", exp_digits=1)
    return f"{value:g}"


def best_of_label(algo: str, n: int) -> str:
    """The method label of the selected value in the main table."""
    return f"{algo} (best of {n})"


@dataclass
class BestOf:
    """One family's selection: every value's cell per task, and the label per task where a
    value was selected."""

    algo: str
    field: str
    cells: pd.DataFrame  # task, <field>, seeds, mean, std, selected
    labels: dict[str, str] = field(default_factory=dict)  # task -> label in the main table

    @property
    def table_stem(self) -> str:
        """tables/<stem>.{md,csv} of the report: every value's cell."""
        return f"best-of-{self.algo}"


@dataclass
class Selection:
    """What `select_best_of` did: the scores to report, each family's cells, notes."""

    scores: pd.DataFrame
    families: list[BestOf] = field(default_factory=list)  # those with a selection
    notes: list[str] = field(default_factory=list)

    @property
    def labels(self) -> list[str]:
        return [label for f in self.families for label in f.labels.values()]


def select_best_of(runs: Sequence[Run], scores: pd.DataFrame) -> Selection:
    """For every best-of family and task whose runs span two or more values of its field and
    differ in nothing else, keep the value with the highest mean final return (ties: the larger
    value) and relabel its scores `<algo> (best of N)`; drop the other values' scores."""
    selection = Selection(scores)
    for algo, name in best_of_families().items():
        family = _select(algo, name, runs, selection)
        if family.labels:
            selection.families.append(family)
    selection.scores = selection.scores.reset_index(drop=True)
    return selection


def _select(algo: str, name: str, runs: Sequence[Run], selection: Selection) -> BestOf:
    cells, labels = [], {}
    by_task: dict[str, list[Run]] = {}
    for run in runs:
        if run.algo == algo and config_value(run.config, name) is not None:
            by_task.setdefault(run.task, []).append(run)
    out = selection.scores
    for task in sort_tasks(by_task):
        group = by_task[task]
        values = {float(config_value(r.config, name)) for r in group}
        if len(values) < 2:
            continue
        other = differing_fields([r.config for r in group], ignore={name})
        if other:
            selection.notes.append(
                f"{algo} runs on {task} differ in {', '.join(other)} as well as {name}; "
                "no value was selected (each is shown on its own)."
            )
            continue
        paths = {str(r.path): float(config_value(r.config, name)) for r in group}
        rows = out[out["run"].isin(paths)]
        if rows.empty:
            continue
        rows = rows.assign(value=rows["run"].map(paths))
        task_cells = value_cells(rows, name)
        cells.append(task_cells)
        best = float(task_cells.loc[task_cells["selected"], name].iloc[0])
        labels[task] = label = best_of_label(algo, len(values))
        keep = rows.index[rows["value"] == best]
        out = out.drop(index=rows.index.difference(keep))
        out.loc[keep, "method"] = label
    selection.scores = out
    columns = ["task", name, "seeds", "mean", "std", "selected"]
    cells = pd.concat(cells, ignore_index=True) if cells else pd.DataFrame(columns=columns)
    return BestOf(algo, name, cells, labels)


def value_cells(rows: pd.DataFrame, name: str) -> pd.DataFrame:
    """Per task and value of field `name` (`task, value, seed, score` rows): seeds, mean, std
    over seeds and `selected`, true for the highest mean per task (ties: the larger value)."""
    from adarl.stats import mean_std

    out = []
    for task, per_task in rows.groupby("task", sort=False):
        cells = []
        for value, g in per_task.groupby("value"):
            m, s = mean_std(g["score"].to_numpy(float))
            cells.append({"task": task, name: float(value), "seeds": len(g), "mean": m, "std": s})
        cells.sort(key=lambda c: -c[name])
        means = [c["mean"] if np.isfinite(c["mean"]) else -np.inf for c in cells]
        top = int(np.argmax(means))
        for i, c in enumerate(cells):
            c["selected"] = i == top
        out += cells
    return pd.DataFrame(out, columns=["task", name, "seeds", "mean", "std", "selected"])


def best_of_markdown(family: BestOf) -> str:
    """Task rows × value columns, mean ± std over seeds, the selected cell in bold."""
    cells, name = family.cells, family.field
    values = sorted(set(cells[name]), reverse=True)
    body = []
    for task in sort_tasks(cells["task"]):
        row = [task]
        for value in values:
            hit = cells[(cells["task"] == task) & (cells[name] == value)]
            if hit.empty:
                row.append(tables.DASH)
                continue
            c = hit.iloc[0]
            text = tables.format_mean_std(c["mean"], c["std"], int(c["seeds"]))
            row.append(f"**{text}**" if c["selected"] and text != tables.DASH else text)
        chosen = cells[(cells["task"] == task) & cells["selected"]]
        row.append(value_text(float(chosen[name].iloc[0])) if not chosen.empty else tables.DASH)
        body.append(row)
    header = ["task", *(f"{name}={value_text(v)}" for v in values), "selected"]
    return tables.markdown_table(header, body)
