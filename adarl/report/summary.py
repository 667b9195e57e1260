"""The lines `adarl train` prints when a run ends: what it reached, where its files are and what to
run next. Built from the run folder alone, so it says the same after a resume as after one go."""

from __future__ import annotations

import os
import shlex
from pathlib import Path

import numpy as np

from adarl.report import behaviour
from adarl.results import collect
from adarl.results.runs import load_run


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


LAST_K = 5  # the summary's score: the mean of the last 5 evaluations, as `adarl report`'s default


def _mean_spread(values: np.ndarray) -> str:
    """`363.3`, or `612.0 ± 240.1` (sample SD) over several seeds."""
    spread = f" ± {np.std(values, ddof=1):.1f}" if len(values) > 1 else ""
    return f"{np.mean(values):.1f}{spread}"


def score_line(recent) -> str:
    """`nominal return: 363.3 (mean of the last 5 evaluations, steps 110,000–150,000, 5 episodes
    each; seed 0: 363.3)` from `collect.last_k_scores`: the score `adarl report` shows first."""
    values = recent["score"].to_numpy(float)
    counts = sorted(set(int(n) for n in recent["evaluations"]))
    first, last = int(recent["first_step"].min()), int(recent["last_step"].max())
    steps = f"step {last:,}" if first == last else f"steps {first:,}–{last:,}"
    episodes = int(recent["episodes"].min())
    per_seed = ", ".join(f"{int(s)}: {v:.1f}" for s, v in zip(recent["seed"], values))
    evals = "/".join(map(str, counts))
    return (
        f"nominal return: {_mean_spread(values)} (mean of the last {evals} evaluation(s), "
        f"{steps}, {episodes} episode(s) each; seed {per_seed})"
    )


def behaviour_line(table) -> str:
    """What the final policies do (`collect.final_behaviour`: `seed, length, distance,
    max_length`): mean episode length out of the limit, forward distance, and a word per seed
    (`behaviour.describe`) with what it means."""
    lengths, distances = table["length"].to_numpy(float), table["distance"].to_numpy(float)
    limit = int(table["max_length"].max())
    words = [
        behaviour.describe(length, limit_, distance)
        for length, limit_, distance in zip(lengths, table["max_length"], distances)
    ]
    several = len(table) > 1
    text = f"episodes last {np.mean(lengths):,.0f} of {limit:,} steps"
    text += " on average" if several else ""
    if np.isfinite(distances).all():
        text += f", forward distance {np.mean(distances):.2f} m"
    else:
        text += ", forward distance not recorded (`adarl evaluate` records it)"
    seeds: dict[str, list[str]] = {}
    for seed, word in zip(table["seed"], words):
        seeds.setdefault(word, []).append(str(int(seed)))
    if not several:
        text += f": {words[0]} ({behaviour.MEANING[words[0]]})"
    elif len(seeds) == 1:
        text += f": all {len(words)} seeds {words[0]} ({behaviour.MEANING[words[0]]})"
    else:
        text += "; " + "; ".join(
            f"{w} ({behaviour.MEANING[w]}): seed{'s' if len(s) > 1 else ''} {', '.join(s)}"
            for w, s in seeds.items()
        )
    return f"what the final {'policies do' if several else 'policy does'}: {text}"


def training_summary(
    run_dir: str | os.PathLike, wall_seconds: float, report_dir: Path | None = None
) -> str:
    """A few lines: the nominal return over the last evaluations and at the final checkpoint
    (mean ± std over seeds, per seed), what the final policies do (episode length, distance, one
    word), AdaRL's final ranks, wall time, where the files are, and the next commands."""
    run = load_run(run_dir)
    path = shlex.quote(str(run.path))
    steps = f"{run.total_steps:,}" if run.total_steps is not None else "?"
    lines = [
        f"done: {run.label} on {run.task}, {len(run.seeds)} seed(s) x {steps} steps, "
        f"wall time {duration(wall_seconds)}"
    ]
    recent, _ = collect.last_k_scores(run, LAST_K)
    if not recent.empty:
        lines.append(score_line(recent))
    scores, source = collect.final_scores(run)
    if not scores.empty:
        values = scores["score"].to_numpy(float)
        per_seed = ", ".join(f"{int(s)}: {v:.1f}" for s, v in zip(scores["seed"], values))
        lines.append(f"final checkpoint: {_mean_spread(values)} (seed {per_seed}; {source})")
    final_behaviour = collect.final_behaviour(run)
    if not final_behaviour.empty:
        lines.append(behaviour_line(final_behaviour))
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
    no_distance = final_behaviour.empty or final_behaviour["distance"].isna().any()
    lines += [
        "next:",
        *([] if report_dir else [f"  adarl report {path} --out {path}/report"]),
        *([f"  adarl evaluate {path}   # records forward distance"] if no_distance else []),
        *([f"  adarl evaluate {path} {sweep}"] if sweep else []),
        f"  adarl play {path} --seed {run.seeds[0]} --video {path}/seed{run.seeds[0]}.mp4",
        f"  tensorboard --logdir {path}/tb",
    ]
    return "\n".join(lines)
