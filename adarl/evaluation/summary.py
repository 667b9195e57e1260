"""The lines `adarl train` prints when a run ends: what it reached, where its files are and what to
run next. Built from the run folder alone, so it says the same after a resume as after one go."""

from __future__ import annotations

import os
import shlex
from pathlib import Path

import numpy as np

from adarl.evaluation import collect
from adarl.evaluation.runs import load_run


def duration(seconds: float) -> str:
    """`2h05m`, `3m07s`, `42s`."""
    seconds = int(max(0, round(seconds)))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    if hours:
        return f"{hours}h{minutes:02d}m"
    return f"{minutes}m{secs:02d}s" if minutes else f"{secs}s"


def sweep_example(task: str) -> str:
    """`--sweep P=LO:HI:9` over the training range of the first parameter `paper` dynamics vary;
    empty if the task is unknown."""
    from adarl.envs import get_task

    try:
        schedule = get_task(task).schedules["paper"]
    except Exception:  # noqa: BLE001 - a run of a task this version does not know
        return ""
    name, sinusoid = next(iter(schedule.items()))
    return f"--sweep {name}={sinusoid.low:.4g}:{sinusoid.high:.4g}:9"


def training_summary(
    run_dir: str | os.PathLike, wall_seconds: float, report_dir: Path | None = None
) -> str:
    """A few lines: final nominal return per seed (mean ± std), AdaRL's final ranks, wall time,
    where the files are, and the next commands."""
    run = load_run(run_dir)
    path = shlex.quote(str(run.path))
    steps = f"{run.total_steps:,}" if run.total_steps is not None else "?"
    lines = [
        f"done: {run.label} on {run.task}, {len(run.seeds)} seed(s) x {steps} steps, "
        f"wall time {duration(wall_seconds)}"
    ]
    scores, source = collect.final_scores(run)
    if not scores.empty:
        values = scores["score"].to_numpy(float)
        spread = f" ± {values.std(ddof=1):.1f}" if len(values) > 1 else ""
        per_seed = ", ".join(f"{int(s)}: {v:.1f}" for s, v in zip(scores["seed"], values))
        lines.append(
            f"final nominal return: {values.mean():.1f}{spread} (seed {per_seed}; {source})"
        )
    ranks = collect.final_ranks(run)
    if not ranks.empty:
        parts = []
        for layer, group in ranks.groupby("layer", sort=False):
            r = group["rank"].to_numpy(float)
            span = f" ({r.min():.0f}-{r.max():.0f})" if r.min() != r.max() else ""
            parts.append(f"{layer} {np.mean(r):.1f}{span}")
        lines.append("final ranks (mean over seeds): " + ", ".join(parts))
    lines.append(f"files: {run.path}/ (config.yaml, eval.csv, train.csv, checkpoints/, tb/)")
    if report_dir is not None:
        lines.append(f"report: {report_dir}/index.md")
    sweep = sweep_example(run.task)
    lines += [
        "next:",
        *([] if report_dir else [f"  adarl report {path} --out {path}/report"]),
        *([f"  adarl evaluate {path} {sweep}"] if sweep else []),
        f"  adarl play {path} --seed {run.seeds[0]} --video {path}/seed{run.seeds[0]}.mp4",
        f"  tensorboard --logdir {path}/tb",
    ]
    return "\n".join(lines)
