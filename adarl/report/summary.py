"""The lines `adarl train` prints when a run ends: what it reached, where its files are and what to
run next. Built from the run folder alone, so it says the same after a resume as after one go."""

from __future__ import annotations

import os
import shlex
from pathlib import Path

import numpy as np
import pandas as pd

from adarl.report import behaviour
from adarl.results import collect
from adarl.results.runs import config_value, load_run


def duration(seconds: float) -> str:
    """`2h05m`, `3m07s`, `42s`."""
    seconds = int(max(0, round(seconds)))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    if hours:
        return f"{hours}h{minutes:02d}m"
    return f"{minutes}m{secs:02d}s" if minutes else f"{secs}s"


#: The most `adarl evaluate --sweep` lines the summary suggests (one per varied parameter).
MAX_SWEEPS = 3


def sweep_examples(config: dict) -> list[str]:
    """`--sweep P=LO..HI:9`, one per parameter the run's own dynamics varied, over its training
    range (a run that varied nothing: the first parameter of its task's `paper` schedule); empty
    if the task cannot be read (a run of a task this version does not know)."""
    from adarl.envs import parse_dynamics
    from adarl.envs.tasks import task_of
    from adarl.evaluation.grid import DEFAULT_POINTS

    try:
        task = task_of(config)
        try:
            varied = dict(parse_dynamics(str(config.get("dynamics", "paper")), task).sinusoids)
        except Exception:  # noqa: BLE001 - a spec this version reads otherwise: the task's own
            varied = {}
        if not varied:
            varied = dict(list(task.schedules.get("paper", {}).items())[:1])
    except Exception:  # noqa: BLE001 - a run of a task this version does not know
        return []
    return [
        f"--sweep {name}={s.low:.4g}..{s.high:.4g}:{DEFAULT_POINTS}"
        for name, s in list(varied.items())[:MAX_SWEEPS]
    ]


def budget_words(config: dict) -> tuple[list[str], list[str]]:
    """What the run's budget gave (`schedule.budget_words`: AdaRL's cuts, the warm-up, the rules
    they followed) and its warnings (no cut, mostly random), from its config.yaml; none for a
    config that does not record the SAC family's schedule (`start_steps`) or does not read."""
    if "start_steps" not in config:
        return [], []
    from adarl.algos import registry, schedule

    try:
        _, resolved = registry.config_from_record(dict(config), "config.yaml")
    except Exception:  # noqa: BLE001 - a run this version reads otherwise: say nothing of it
        return [], []
    return schedule.budget_words(resolved)


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


#: `behaviour.WORDS` said of several policies
PLURAL = {"falls": "fall", "stands": "stand", "moves": "move", "stands or moves": "stand or move"}


def recent_evaluations(run, k: int = LAST_K):
    """The evaluations behind `score_line`'s return (`collect.last_k_scores`: each seed's last
    `k` in eval.csv under `collect.score_dynamics`), one row each: `seed, step, return, length,
    distance` (means over the evaluation's episodes; distance NaN where eval.csv has none) and
    `max_length`, the run's time limit."""
    from adarl.runs.layout import EVAL_CSV

    log = collect.read_table(run.path / EVAL_CSV)
    dynamics = collect.score_dynamics(log)
    columns = ["seed", "step", "return", "length", "distance", "max_length"]
    if dynamics is None:
        return pd.DataFrame(columns=columns)
    log = log[log["dynamics"] == dynamics]
    if "distance" not in log:
        log = log.assign(distance=np.nan)
    if "length" not in log:
        log = log.assign(length=np.nan)
    per_eval = log.groupby(["seed", "step"], as_index=False)[["return", "length", "distance"]]
    last = per_eval.mean().sort_values(["seed", "step"]).groupby("seed").tail(k)
    limit = config_value(run.config, "max_episode_steps") or collect.MAX_EPISODE_STEPS
    return last.assign(max_length=int(limit))[columns].reset_index(drop=True)


def _span(values: np.ndarray, digits: int) -> str:
    low, high = np.min(values), np.max(values)
    text = f"{low:,.{digits}f}"
    return text if f"{high:,.{digits}f}" == text else f"{text}–{high:,.{digits}f}"


def evaluations_line(evaluations) -> str:
    """What the policy did in the evaluations behind the headline return (`recent_evaluations`),
    in `behaviour.describe`'s words (from each evaluation's mean episode length and distance),
    the most frequent first (a tie: in `behaviour.WORDS`' order), with each group's episode
    lengths and returns, and, for one seed, the steps of a group of one or two: `  in those 5
    evaluations the policy stands or moves in 4 (1,000 of 1,000 steps, return 1,002.0–1,095.0)
    and falls in 1 (step 150,000: 136 of 1,000 steps, return 363.3); ...` (a mean over standing
    and falling is not a hopping policy's)."""
    lengths = evaluations["length"].to_numpy(float)
    if not np.isfinite(lengths).all():
        return "  (eval.csv records no episode lengths: what the policy did is not known)"
    limits = evaluations["max_length"].to_numpy(float)
    distances = evaluations["distance"].to_numpy(float)
    words = [behaviour.describe(n, m, d) for n, m, d in zip(lengths, limits, distances)]
    seeds = evaluations["seed"].nunique()
    several = seeds > 1
    groups = []
    found = [w for w in behaviour.WORDS if w in words]
    for word in sorted(found, key=words.count, reverse=True):  # the most frequent first
        chosen = np.array([w == word for w in words])
        returns = evaluations["return"].to_numpy(float)[chosen]
        facts = [f"{_span(lengths[chosen], 0)} of {int(limits.max()):,} steps"]
        if np.isfinite(distances[chosen]).all():
            facts.append(f"{_span(distances[chosen], 2)} m forward")
        facts.append(f"return {_span(returns, 1)}")
        steps = evaluations["step"].to_numpy()[chosen]
        when = f"step {', '.join(f'{int(t):,}' for t in steps)}: " if len(steps) <= 2 else ""
        verb = PLURAL[word] if several else word
        groups.append(
            f"{verb} in {int(chosen.sum())} ({when if not several else ''}{', '.join(facts)})"
        )
    count = len(evaluations)
    per_seed = f" ({count // seeds} per seed)" if several and count % seeds == 0 else ""
    subject = "the policies" if several else "the policy"
    text = f"  in those {count} evaluation{'s' if count > 1 else ''}{per_seed} {subject} "
    text += ", ".join(groups[:-1]) + (" and " if len(groups) > 1 else "") + groups[-1]
    if not np.isfinite(distances).all():
        text += "; forward distance not recorded during training (`adarl evaluate` records it)"
    return text


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
        every = "both seeds" if len(words) == 2 else f"all {len(words)} seeds"
        text += f": {every} {behaviour.plural(words[0])} ({behaviour.MEANING[words[0]]})"
    else:
        text += "; " + "; ".join(
            f"{w} ({behaviour.MEANING[w]}): seed{'s' if len(s) > 1 else ''} {', '.join(s)}"
            for w, s in seeds.items()
        )
    return f"what the final {'policies do' if several else 'policy does'}: {text}"


def training_summary(
    run_dir: str | os.PathLike, wall_seconds: float, report_dir: Path | None = None
) -> str:
    """A few lines: the nominal return over the last evaluations (and what the policy did in
    them: `evaluations_line`) and at the final checkpoint (mean ± std over seeds, per seed), what
    the final policies do (episode length, distance, one
    word), AdaRL's final ranks, wall time, where the files are, and the next commands."""
    run = load_run(run_dir)
    path = shlex.quote(str(run.path))
    steps = f"{run.total_steps:,}" if run.total_steps is not None else "?"
    budget, warnings = budget_words(run.config)
    lines = [
        f"done: {run.label} on {run.task}, {len(run.seeds)} seed(s) x {steps} steps, "
        f"wall time {duration(wall_seconds)}",
        *(f"warning: {w}" for w in warnings),
    ]
    recent, _ = collect.last_k_scores(run, LAST_K)
    if not recent.empty:
        lines.append(score_line(recent))
        lines.append(evaluations_line(recent_evaluations(run, LAST_K)))
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
    if budget:
        lines.append("budget: " + "; ".join(budget))
    lines.append(f"files: {run.path}/ (config.yaml, eval.csv, train.csv, checkpoints/, tb/)")
    if report_dir is not None:
        lines.append(f"report: {report_dir}/index.md")
    sweeps = sweep_examples(run.config)
    no_distance = final_behaviour.empty or final_behaviour["distance"].isna().any()
    lines += [
        "next:",
        *([] if report_dir else [f"  adarl report {path} --out {path}/report"]),
        *([f"  adarl evaluate {path}   # records forward distance"] if no_distance else []),
        *[f"  adarl evaluate {path} {sweep}" for sweep in sweeps],
        f"  adarl play {path} --seed {run.seeds[0]} --video {path}/seed{run.seeds[0]}.mp4",
        f"  tensorboard --logdir {path}/tb",
    ]
    return "\n".join(lines)
