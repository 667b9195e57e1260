"""What every part of `adarl report` shares: its options, the `Section` each builder returns,
the score types, the constants, and the helpers that write a table or figure file and format
a number or interval."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from adarl.algos import registry
from adarl.errors import UsageError
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


# ----------------------------------------------------------------------------- the run's task
def _task_spec(run):
    """The run's `TaskSpec` (`adarl.envs.tasks.task_of`), or None where it cannot be made here
    (an env-module this process cannot import, a task since renamed)."""
    try:
        from adarl.envs.tasks import task_of

        return task_of({**dict(run.config), "task": run.task})
    except (ImportError, AttributeError, KeyError, TypeError, UsageError):
        return None


def return_bounds(run, max_steps: int | None = None) -> tuple[float, float]:
    """The lowest and highest return an episode of `run`'s task can have
    (`adarl.envs.tasks.return_bounds`) in episodes of at most `max_steps` steps (default: the
    run's time limit); (-inf, inf) where unknown."""
    spec = _task_spec(run)
    if spec is None:
        return -math.inf, math.inf
    from adarl.envs.tasks import return_bounds as bounds

    limit = max_steps or run.config.get("max_episode_steps") or spec.max_episode_steps
    return bounds(spec, int(limit))


def nominal_value(run, param: str) -> float | None:
    """`param`'s value under `run`'s task's `nominal` dynamics: the centre of its schedule, a
    Gymnasium default, or the model's own value of an addressed parameter (`body:bob.mass`);
    None where the task cannot be made or has no such parameter."""
    spec = _task_spec(run)
    if spec is None:
        return None
    try:
        from adarl.envs.dynamics import parse_dynamics, xml_path
        from adarl.envs.elements import address_default
        from adarl.envs.params import is_addressed

        centroid = parse_dynamics("nominal", spec).centroid()
        if param in centroid:
            return float(centroid[param])
        if param in spec.all_params:
            return float(spec.all_params[param])
        return address_default(xml_path(spec), param) if is_addressed(param) else None
    except (ImportError, AttributeError, KeyError, TypeError, ValueError, UsageError):
        return None


def widest_bounds(a: tuple[float, float] | None, b: tuple[float, float]) -> tuple[float, float]:
    """Return bounds that hold for the runs or evaluations of both `a` and `b` (their time
    limits may differ); `a` None: `b`."""
    return b if a is None else (min(a[0], b[0]), max(a[1], b[1]))


def band_text(bounds: Mapping[str, tuple[float, float]], confidence: float = 0.95) -> str:
    """What a curve's band over seeds is, for `bounds[task]`, the returns each task drawn can
    give: a Student-t interval of the mean (normal theory), clipped to them where known
    (`figures.clip_band`), else said to possibly reach past them."""
    known = {t: b for t, b in bounds.items() if math.isfinite(b[0]) or math.isfinite(b[1])}
    band = f"{confidence:.0%} Student-t band (normal theory"
    if not known:
        return f"{band}: from few seeds it is wide and may reach returns the task cannot give)"
    ranges = "; ".join(f"{task}: {_range_text(*b)}" for task, b in known.items())
    rest = "" if len(known) == len(bounds) else "; other tasks' bands not clipped"
    return f"{band}, clipped to the returns the task can give, {ranges}{rest})"


def _range_text(low: float, high: float) -> str:
    if math.isfinite(low) and math.isfinite(high):
        return f"{low:,.0f} to {high:,.0f}"
    return f"at least {low:,.0f}" if math.isfinite(low) else f"at most {high:,.0f}"


def seed_ids(seeds: Iterable[int]) -> str:
    """Seed ids as text, runs of three or more consecutive ids as a range: `0`, `10, 11`,
    `0–4, 7`."""
    ids = sorted({int(s) for s in seeds})
    parts, start = [], 0
    for i in range(1, len(ids) + 1):
        if i == len(ids) or ids[i] != ids[i - 1] + 1:
            run = ids[start:i]
            parts += [f"{run[0]}–{run[-1]}"] if len(run) >= 3 else [str(v) for v in run]
            start = i
    return ", ".join(parts)
