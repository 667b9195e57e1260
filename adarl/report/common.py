"""What every part of `adarl report` shares: its options, the `Section` each builder returns,
the score types, the constants, and the helpers that write a table or figure file and format
a number or interval."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from adarl.algos import registry
from adarl.report import figures, tables

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


def final_checkpoint_scores(scores: pd.DataFrame) -> pd.DataFrame:
    """`scores` with the final checkpoint's score as `score` (seeds without one dropped)."""
    if "final" not in scores:
        return scores.iloc[0:0]
    return scores.assign(score=scores["final"]).dropna(subset=["score"])


def write_file(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


def save_figure(folder: Path, fig, stem: str) -> list[Path]:
    """`fig` saved as figures/<stem>.{png,pdf}. The sections call it as `common.save_figure`, so a
    test can skip drawing by replacing it here."""
    return figures.save_figure(fig, folder / "figures" / slug(stem))


def slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-")


def csv_text(df: pd.DataFrame) -> str:
    return df.to_csv(index=False, float_format="%.6g")


def ci_text(low: float, high: float, digits: int) -> str:
    """`[low, high]`, or a dash where there is no interval (one seed)."""
    if not (np.isfinite(low) and np.isfinite(high)):
        return tables.DASH
    return f"[{low:.{digits}f}, {high:.{digits}f}]"


def interval_text(point: float, low: float, high: float, digits: int) -> tuple[str, str]:
    return f"{point:.{digits}f}", ci_text(low, high, digits)


def rounded(value: float) -> str:
    """A whole number with thousands separators (a detectable difference, seeds needed), or a
    dash where there is none."""
    return f"{value:,.0f}" if np.isfinite(value) else tables.DASH


def number_text(value: float) -> str:
    """One decimal, or a dash where a method lacks the ring (runs evaluated on other grids)."""
    return f"{value:.1f}" if np.isfinite(value) else tables.DASH
