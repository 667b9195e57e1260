"""Tables for the report: Table 1 (final return per task × method, mean ± std over seeds, the
best per row in bold) as Markdown, LaTeX and CSV, and plain Markdown/CSV tables for the rest.

Pure functions from DataFrames to strings.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from adarl.results.runs import sort_methods, sort_tasks
from adarl.stats import mean_std

DASH = "—"
_NUMBER = re.compile(r"^(\*\*)?[-+]?[\d.,]+(%| ± [\d.,]+)?(\*\*)?$|^—$|^\[")


@dataclass(frozen=True)
class ScoreTable:
    """Mean, standard deviation and seed count per (row, column), and which cells are best."""

    rows: list[str]
    columns: list[str]
    mean: pd.DataFrame
    std: pd.DataFrame
    count: pd.DataFrame
    best: pd.DataFrame  # bool

    def cell(self, row: str, column: str, digits: int = 1) -> str:
        return format_mean_std(
            self.mean.at[row, column],
            self.std.at[row, column],
            int(self.count.at[row, column]),
            digits,
        )


def p_text(value: float, digits: int = 3) -> str:
    """A p-value to `digits` decimals; one that would print as 0.000 prints as `< 0.001`."""
    if not np.isfinite(value):
        return DASH
    smallest = 10.0**-digits
    return f"< {smallest:.{digits}f}" if value < smallest / 2 else f"{value:.{digits}f}"


def score_table(scores: pd.DataFrame, row: str = "task", column: str = "method") -> ScoreTable:
    """Aggregate a long table of `row, column, seed, score` into a `ScoreTable`.

    Each cell is the mean ± sample standard deviation over seeds of the per-seed scores. The
    best cell of a row is the one with the highest mean (all tied cells are best).
    """
    rows = sort_tasks(scores[row]) if row == "task" else sorted(set(scores[row]))
    columns = sort_methods(scores[column]) if column == "method" else sorted(set(scores[column]))
    mean = pd.DataFrame(np.nan, index=rows, columns=columns)
    std, count = mean.copy(), pd.DataFrame(0, index=rows, columns=columns)
    for (r, c), group in scores.groupby([row, column]):
        m, s = mean_std(group["score"].to_numpy(float))
        mean.at[r, c], std.at[r, c], count.at[r, c] = m, s, len(group)
    best = pd.DataFrame(False, index=rows, columns=columns)
    for r in rows:
        values = mean.loc[r]
        if values.notna().any():
            best.loc[r] = values == values.max()
    return ScoreTable(rows, columns, mean, std, count, best)


def format_mean_std(mean: float, std: float, count: int, digits: int = 1) -> str:
    """`1234.5 ± 67.8`; just the mean for one seed; a dash for no data."""
    if count == 0 or not math.isfinite(mean):
        return DASH
    if count == 1 or not math.isfinite(std):
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


FINAL_ROW = "final checkpoint"  # label of the rows that `second` adds to Table 1


def _second_cell(second: ScoreTable | None, r: str, c: str, digits: int) -> str:
    if second is None or r not in second.rows or c not in second.columns:
        return DASH
    return second.cell(r, c, digits)


def table_markdown(
    table: ScoreTable, corner: str = "task", digits: int = 1, second: ScoreTable | None = None
) -> str:
    """Rows × columns of mean ± std, the best per row in bold; `second` (the same runs scored
    another way, e.g. at the final checkpoint) adds a plain row `<row>, final checkpoint` under
    each row."""
    body = []
    for r in table.rows:
        cells = []
        for c in table.columns:
            text = table.cell(r, c, digits)
            cells.append(f"**{text}**" if table.best.at[r, c] and text != DASH else text)
        body.append([r, *cells])
        if second is not None:
            body.append(
                [f"{r}, {FINAL_ROW}", *(_second_cell(second, r, c, digits) for c in table.columns)]
            )
    return markdown_table([corner, *table.columns], body)


def table_latex(
    table: ScoreTable,
    corner: str = "task",
    digits: int = 1,
    caption: str = "",
    second: ScoreTable | None = None,
) -> str:
    """A booktabs `tabular` (inside a `table` float when a caption is given); `second` as in
    `table_markdown`."""
    spec = "l" + "r" * len(table.columns)
    lines = [
        rf"\begin{{tabular}}{{{spec}}}",
        r"\toprule",
        " & ".join(latex_escape(x) for x in [corner, *table.columns]) + r" \\",
        r"\midrule",
    ]

    def tex(text: str) -> str:
        return text.replace(" ± ", r" $\pm$ ").replace(DASH, "--")

    for r in table.rows:
        cells = []
        for c in table.columns:
            text = tex(table.cell(r, c, digits))
            cells.append(rf"\textbf{{{text}}}" if table.best.at[r, c] and text != "--" else text)
        lines.append(" & ".join([latex_escape(r), *cells]) + r" \\")
        if second is not None:
            cells = [tex(_second_cell(second, r, c, digits)) for c in table.columns]
            lines.append(" & ".join([latex_escape(f"{r}, {FINAL_ROW}"), *cells]) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}"]
    if caption:
        lines = [
            r"\begin{table}[t]",
            r"\centering",
            *lines,
            rf"\caption{{{latex_escape(caption)}}}",
            r"\end{table}",
        ]
    return "\n".join(lines) + "\n"


def table_csv(table: ScoreTable, corner: str = "task", second: ScoreTable | None = None) -> str:
    """Long form: one line per cell with `mean, std, seeds, best`, and with `second` its
    `final_mean, final_std, final_seeds`."""
    rows = []
    for r in table.rows:
        for c in table.columns:
            if table.count.at[r, c] == 0:
                continue
            row = {
                corner: r,
                "method": c,
                "mean": table.mean.at[r, c],
                "std": table.std.at[r, c],
                "seeds": int(table.count.at[r, c]),
                "best": bool(table.best.at[r, c]),
            }
            if second is not None:
                found = r in second.rows and c in second.columns
                row["final_mean"] = second.mean.at[r, c] if found else np.nan
                row["final_std"] = second.std.at[r, c] if found else np.nan
                row["final_seeds"] = int(second.count.at[r, c]) if found else 0
            rows.append(row)
    return pd.DataFrame(rows).to_csv(index=False, float_format="%.6g")


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A GitHub-flavoured Markdown table; the first column left-aligned, the rest right."""

    def text(x) -> str:
        if isinstance(x, float):
            return DASH if not math.isfinite(x) else f"{x:.4g}"
        return str(x).replace("|", r"\|")

    def numeric(x) -> bool:
        return isinstance(x, int | float) or bool(_NUMBER.match(str(x)))

    align = [":---"] + [
        "---:" if rows and all(numeric(r[i]) for r in rows) else ":---"
        for i in range(1, len(header))
    ]
    lines = ["| " + " | ".join(text(h) for h in header) + " |", "| " + " | ".join(align) + " |"]
    lines += ["| " + " | ".join(text(x) for x in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def latex_escape(text: str) -> str:
    for a, b in (
        ("\\", r"\textbackslash{}"),
        ("_", r"\_"),
        ("&", r"\&"),
        ("%", r"\%"),
        ("#", r"\#"),
    ):
        text = text.replace(a, b)
    return text
