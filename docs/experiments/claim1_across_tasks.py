"""Claim 1 across tasks (docs/experiments/claim1-across-tasks.md): does AdaRL score higher than SAC,
on the nominal dynamics and over a grid of physics, across ten tasks at 100k steps? The
pre-registered analysis, from the runs' own rows only.

    python docs/experiments/claim1_across_tasks.py SWEEP_DIR [--out DIR]   # the report and figure
    python docs/experiments/claim1_across_tasks.py power [--sims N]        # the design's power
    python docs/experiments/claim1_across_tasks.py sweeps                  # write the sweep files
    python docs/experiments/claim1_across_tasks.py evaluate SWEEP_DIR [--code DIR]  # robustness grids
    python docs/experiments/claim1_across_tasks.py export SWEEP_DIR        # rows -> claim1-across-tasks/rows/
    python docs/experiments/claim1_across_tasks.py restore SWEEP_DIR [--rows DIR]  # rows -> SWEEP_DIR (new machine)

SWEEP_DIR is the sweep folder (or the exported rows: run folders without checkpoints or policies).

What it computes (the pre-registration's names):
- per seed: `nominal`, the mean of the nominal evaluations after the last cut (steps 90k and
  100k, 5 episodes each; `adarl.results.collect.last_evaluations`); `worst` and `average`, the
  lowest and the mean over the robustness grid's points of the mean return at each point (the
  final policy, `EPISODES` episodes a point); the random-action return (training episodes that
  ended within `start_steps`);
- per task t: r_t, the mean random-action return of the primary arms' seeds; S_t, SAC's mean
  nominal score; the scale D_t = max(S_t − r_t, FLOOR·(reference_t − r_t)); every score of every
  seed normalised as u = (score − r_t) / D_t, so 0 is random actions and 1 is SAC's nominal mean;
- primaries (one per score: nominal, worst, average; Holm over the three): Δ, the mean over the
  tasks of d_t = mean_AdaRL u − mean_SAC u, tested against 0 by the one-sample t test of the T task
  differences (T − 1 degrees of freedom), which for seeds nested in tasks with the same seeds per
  task and arm is the exact test of the arm effect in the mixed model with random task and
  task × arm effects;
- beside them (never called detected): the fixed-task (stratified) interval of Δ, the task-level
  bootstrap interval (tasks resampled, seeds within them, S_t recomputed), the probability of
  improvement and the IQM difference with rliable's stratified bootstrap intervals, each task's
  Welch interval, the primaries without the tasks at their ceiling or unlearned, and the secondary
  arms (the schedule-matched control, fixed-rank SAC, adarl's default rule) against SAC and AdaRL.
"""

from __future__ import annotations

import gzip
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy import stats as st

sys.path.insert(0, str(Path(__file__).resolve().parent))
import claim2_across_tasks as c2  # noqa: E402  (its CSV reader and task tables)

from adarl import stats  # noqa: E402
from adarl.errors import UsageError  # noqa: E402
from adarl.files import atomic_write_text  # noqa: E402
from adarl.results import collect  # noqa: E402
from adarl.results.runs import Run, config_value, find_runs  # noqa: E402

HERE = Path(__file__).resolve().parent
FOLDER = HERE / "claim1-across-tasks"
ROWS = FOLDER / "rows"

BUDGET, TRUNCATE_EVERY, CUTS = c2.BUDGET, c2.TRUNCATE_EVERY, c2.CUTS  # claim 2's schedule
ACTION_DIM = {**c2.ACTION_DIM, "InvertedDoublePendulum-v5": 1}
REFERENCE_RETURN = {**c2.REFERENCE_RETURN, "InvertedDoublePendulum-v5": 9100.0}  # Gymnasium's
TASKS = tuple(ACTION_DIM)
PAPER_TASKS = ("hopper", "walker2d", "ant", "humanoid")  # robustness: the `paper` suite's ranges
SEEDS = tuple(range(15))  # the primary arms: 15 blocks of one seed
SECONDARY_SEEDS = tuple(range(5))
# arm -> (algo, rank_rule or None); the first two are the primary pair
ARMS = {
    "adarl": ("adarl", "cumulative"),  # the paper's Eq. 5 at beta 0.98
    "sac": ("sac", None),
    "control": ("adarl-control", "cumulative"),  # the same resets and warm-ups, nothing removed
    "fixed": ("sac-fixed-rank", None),  # at the rank AdaRL ends at on the task
    "energy": ("adarl", "energy"),  # adarl's default rule
}
PRIMARY = ("adarl", "sac")
SCORES = ("nominal", "worst", "average")
ALPHA = 0.05
FLOOR = 0.05  # D_t never below 5% of the way from random to the reference return
SCORE_EVALUATIONS = c2.SCORE_EVALUATIONS
LEARNED_FRACTION = c2.LEARNED_FRACTION
CEILING = 0.98  # a task whose primary seeds all reach 98% of its reference is "at its ceiling"
# the robustness grids: the generic tasks' mass and friction scales, the paper suite on its four
GRID_VALUES = (0.5, 0.75, 1.0, 1.25, 1.5)
GENERIC_FLAGS = ["--sweep", "mass_scale=0.5:1.5:5", "--sweep", "friction_scale=0.5:1.5:5"]
GENERIC_FILE = "sweep-mass_scale-0.5-1.5-5_sweep-friction_scale-0.5-1.5-5.csv"
PAPER_FLAGS = ["--suite", "paper", "--points", "5"]
PAPER_FILE = "suite-paper.csv"
POINTS = 25
EPISODES = 10
FILES = ("eval.csv", "truncations.csv", "episodes.csv", "train.csv")
RUN_FILES = ("config.yaml", "DONE")


def canonical(task: str) -> str:
    """The design's name of `task` (case aside); another task is a one-line error."""
    for name in TASKS:
        if name.lower() == str(task).lower():
            return name
    raise UsageError(f"task {task!r} is not one of this experiment's: {', '.join(TASKS)}")


def robustness_file(task: str) -> str:
    """The file under a run's `evaluations/` that holds its robustness grid's episodes."""
    return PAPER_FILE if canonical(task) in PAPER_TASKS else GENERIC_FILE


def arm_of(config) -> str | None:
    """The design's arm of a run's config, or None."""
    algo, rule = str(config_value(config, "algo")), str(config_value(config, "rank_rule", ""))
    for arm, (a, r) in ARMS.items():
        if algo == a and (r is None or rule == r):
            return arm
    return None


# ----------------------------------------------------------------------------- reading runs
def grid_scores(episodes: pd.DataFrame) -> pd.DataFrame:
    """Per seed, from a robustness grid's episodes (`seed, dynamics, return`): `worst`, the lowest
    over the points of the point's mean return, `average`, the mean of those means, and `points`
    and `min_episodes` (the fewest episodes at any point)."""
    columns = ["seed", "worst", "average", "points", "min_episodes"]
    if episodes.empty:
        return pd.DataFrame(columns=columns)
    point = episodes.groupby(["seed", "dynamics"])["return"].agg(["mean", "size"]).reset_index()
    out = point.groupby("seed").agg(
        worst=("mean", "min"), average=("mean", "mean"), points=("mean", "size"),
        min_episodes=("size", "min"),
    ).reset_index()  # fmt: skip
    return out[columns]


def seed_rows(run: Run) -> list[dict]:
    """One record per seed of a finished run: arm, task, the three raw scores, the random-action
    return, the final actor rank (after cut 4; NaN without a bottleneck) and `excluded` (why a
    seed is off the design: its schedule, its cuts, an incomplete grid)."""
    config = run.config
    task = canonical(run.task)
    arm = arm_of(config)
    excluded = "" if arm else f"algo {config_value(config, 'algo')} is not an arm of the design"
    beta = config_value(config, "beta", None)
    if not excluded and run.total_steps != BUDGET:
        excluded = f"budget {run.total_steps:,}, not {BUDGET:,}"
    cut_every = int(config_value(config, "truncate_every", 0) or 0)
    if not excluded and arm in ("adarl", "control", "energy") and (cut_every, beta) != (TRUNCATE_EVERY, 0.98):  # fmt: skip
        excluded = f"d_t {cut_every:,} and beta {beta}, not the design's"
    evaluations = c2.table(run.path, "eval.csv")
    nominal = evaluations[evaluations["dynamics"] == collect.NOMINAL] if len(evaluations) else evaluations  # fmt: skip
    returns = collect.last_evaluations(nominal, SCORE_EVALUATIONS).set_index("seed")["score"]
    grid = grid_scores(c2.table(run.path / "evaluations", robustness_file(task))).set_index("seed")
    cuts = c2.table(run.path, "truncations.csv")
    episodes = c2.table(run.path, "episodes.csv")
    start = int(config_value(config, "start_steps", 0))
    records = []
    for seed in run.seeds:
        record = {"task": task, "arm": arm or "", "seed": int(seed), "run": str(run.path),
                  "excluded": excluded}  # fmt: skip
        mine = cuts[(cuts["seed"] == seed) & (cuts["layer"] == c2.ACTOR)] if len(cuts) else cuts
        if (
            arm in ("adarl", "control", "energy")
            and not excluded
            and mine["step"].nunique() != CUTS
        ):
            record["excluded"] = f"{mine['step'].nunique()} truncations, not {CUTS}"
        record["rank"] = float(mine.sort_values("step")["new_rank"].iloc[-1]) if len(mine) else np.nan  # fmt: skip
        record["nominal"] = float(returns.get(seed, np.nan))
        if seed in grid.index and grid.loc[seed, "points"] == POINTS and grid.loc[seed, "min_episodes"] >= EPISODES:  # fmt: skip
            record["worst"], record["average"] = (float(grid.loc[seed, k]) for k in ("worst", "average"))  # fmt: skip
        else:
            record["worst"] = record["average"] = np.nan
            if not record["excluded"]:
                record["excluded"] = "no complete robustness grid"
        phase = episodes[(episodes["seed"] == seed) & (episodes["step"] <= start)] if len(episodes) else episodes  # fmt: skip
        record["random_return"] = float(phase["return"].mean()) if len(phase) else np.nan
        records.append(record)
    return records


def load(paths) -> tuple[pd.DataFrame, list[str]]:
    """Every finished seed under `paths`, one row per seed, and the runs still training."""
    records, running = [], []
    for run in find_runs([Path(p) for p in paths]):
        if run.done_step is None:
            running.append(str(run.path))
            continue
        records += seed_rows(run)
    columns = ["task", "arm", "seed", "run", "excluded", "rank", "nominal", "worst", "average",
               "random_return"]  # fmt: skip
    return (pd.DataFrame(records) if records else pd.DataFrame(columns=columns)), running


# ----------------------------------------------------------------------------- normalisation
def scales(seeds: pd.DataFrame) -> pd.DataFrame:
    """Per task: `random` r_t (the primary arms' seeds), `sac` S_t (SAC's mean nominal score),
    `scale` D_t = max(S_t − r_t, FLOOR·(reference − r_t)) and whether the floor set it."""
    used = seeds[(seeds["excluded"] == "") & seeds["arm"].isin(PRIMARY)]
    rows = []
    for task in TASKS:
        mine = used[used["task"] == task]
        if mine.empty:
            continue
        random = float(mine["random_return"].mean())
        sac = float(mine.loc[mine["arm"] == "sac", "nominal"].mean())
        floor = FLOOR * (REFERENCE_RETURN[task] - random)
        scale = max(sac - random, floor)
        if not scale > 0:  # a task whose SAC and reference are both below random: no scale
            scale = np.nan
        rows.append({"task": task, "random": random, "sac": sac, "scale": scale,
                     "floored": bool(not sac - random >= floor)})  # fmt: skip
    return pd.DataFrame(rows).set_index("task") if rows else pd.DataFrame()


def normalise(seeds: pd.DataFrame, scale: pd.DataFrame | None = None) -> pd.DataFrame:
    """`seeds` (the design's, none excluded) with u_nominal, u_worst, u_average added."""
    scale = scales(seeds) if scale is None else scale
    used = seeds[(seeds["excluded"] == "") & seeds["task"].isin(scale.index)].copy()
    for score in SCORES:
        r = used["task"].map(scale["random"])
        used[f"u_{score}"] = (used[score] - r) / used["task"].map(scale["scale"])
    return used


def matrix(used: pd.DataFrame, arm: str, score: str, tasks) -> np.ndarray:
    """(seeds, tasks) normalised scores of `arm`, the seeds in order; tasks lacking seeds (or
    with unequal counts) raise."""
    columns = []
    for task in tasks:
        values = used[(used["arm"] == arm) & (used["task"] == task)].sort_values("seed")
        columns.append(values[f"u_{score}"].to_numpy(float))
    if len({len(c) for c in columns}) != 1:
        raise UsageError(f"{arm}: unequal seeds per task ({[len(c) for c in columns]})")
    return np.stack(columns, axis=1)


# ----------------------------------------------------------------------------- tests
def task_differences(used: pd.DataFrame, score: str, a: str = "adarl", b: str = "sac", tasks=None) -> pd.Series:  # fmt: skip
    """d_t = mean_a u − mean_b u per task (tasks where both arms have seeds)."""
    tasks = [t for t in (tasks or TASKS) if t in set(used["task"])]
    col = f"u_{score}"
    means = used.groupby(["task", "arm"])[col].mean()
    out = {t: means.get((t, a), np.nan) - means.get((t, b), np.nan) for t in tasks}
    return pd.Series(out).dropna()


def mixed_test(d) -> dict:
    """Δ = mean(d) with its t interval and two-sided p over the tasks (len(d) − 1 df); a set of
    differences with no spread gives p 0 (or 1 at Δ = 0), its interval the point."""
    d = np.asarray(d, float)
    k = len(d)
    delta = float(d.mean()) if k else np.nan
    if k < 2:
        return {"delta": delta, "low": np.nan, "high": np.nan, "p": np.nan, "df": 0, "tasks": k}
    se = float(d.std(ddof=1) / np.sqrt(k))
    if se == 0:
        p = 1.0 if delta == 0 else 0.0
        return {"delta": delta, "low": delta, "high": delta, "p": p, "df": k - 1, "tasks": k}
    half = st.t.ppf(1 - ALPHA / 2, k - 1) * se
    p = float(2 * st.t.sf(abs(delta) / se, k - 1))
    return {"delta": delta, "low": delta - half, "high": delta + half, "p": p, "df": k - 1,
            "tasks": k, "se": se}  # fmt: skip


def stratified_interval(used: pd.DataFrame, score: str, a: str = "adarl", b: str = "sac") -> tuple[float, float]:  # fmt: skip
    """The fixed-task interval of Δ: its SE from the seeds' variances within each task and arm,
    normal 95% (these ten tasks as the population)."""
    col, var = f"u_{score}", 0.0
    tasks = task_differences(used, score, a, b).index
    for task in tasks:
        for arm in (a, b):
            x = used[(used["task"] == task) & (used["arm"] == arm)][col]
            var += x.var(ddof=1) / len(x) if len(x) > 1 else np.nan
    delta = task_differences(used, score, a, b).mean()
    half = st.norm.ppf(1 - ALPHA / 2) * np.sqrt(var) / len(tasks)
    return float(delta - half), float(delta + half)


def task_bootstrap(seeds: pd.DataFrame, score: str, reps: int = 10_000, seed: int = 0) -> tuple[float, float]:  # fmt: skip
    """Percentile 95% interval of Δ: tasks drawn with replacement, each drawn task's seeds redrawn
    within each arm, the task's r_t, S_t and D_t recomputed from the draw."""
    rng = np.random.default_rng(seed)
    used = seeds[(seeds["excluded"] == "") & seeds["arm"].isin(PRIMARY)]
    per_task = {}
    for task, g in used.groupby("task"):
        arrays = {arm: g[g["arm"] == arm] for arm in PRIMARY}
        if all(len(v) for v in arrays.values()):
            per_task[task] = {arm: (v[score].to_numpy(float), v["nominal"].to_numpy(float),
                                    v["random_return"].to_numpy(float)) for arm, v in arrays.items()}  # fmt: skip
    names = sorted(per_task)
    draws = np.empty(reps)
    for i in range(reps):
        ds = []
        for task in rng.choice(names, size=len(names)):
            cells = {}
            for arm, (score_v, nominal_v, random_v) in per_task[task].items():
                idx = rng.integers(0, len(score_v), len(score_v))
                cells[arm] = (score_v[idx], nominal_v[idx], random_v[idx])
            random = np.mean(np.concatenate([c[2] for c in cells.values()]))
            scale = max(cells["sac"][1].mean() - random, FLOOR * (REFERENCE_RETURN[task] - random))
            ds.append((cells["adarl"][0].mean() - cells["sac"][0].mean()) / scale)
        draws[i] = np.mean(ds)
    low, high = np.percentile(draws, [2.5, 97.5])
    return float(low), float(high)


def aggregates(used: pd.DataFrame, score: str, tasks, reps: int = 10_000) -> dict:
    """rliable's: P(AdaRL > SAC) and IQM(AdaRL) − IQM(SAC), with stratified bootstrap intervals
    (each arm resampled on its own within tasks)."""
    x, y = matrix(used, "adarl", score, tasks), matrix(used, "sac", score, tasks)
    poi = stats.probability_of_improvement_ci(x, y, reps=reps)
    rng = np.random.default_rng(0)
    samples = np.concatenate([
        stats.iqm(stats.stratified_resample(x, n, rng)) - stats.iqm(stats.stratified_resample(y, n, rng))
        for n in stats._chunks(reps)
    ])  # fmt: skip
    low, high = np.percentile(samples, [2.5, 97.5])
    iqm = stats.Interval(float(stats.iqm(x) - stats.iqm(y)), float(low), float(high))
    return {"poi": poi, "iqm": iqm, "iqm_adarl": float(stats.iqm(x)), "iqm_sac": float(stats.iqm(y))}  # fmt: skip


def primaries(seeds: pd.DataFrame) -> list[dict]:
    """The three primary tests (nominal, worst, average) with Holm-adjusted p."""
    used = normalise(seeds)
    tests = [dict(mixed_test(task_differences(used, score).to_numpy()), score=score) for score in SCORES]  # fmt: skip
    for test, adjusted in zip(tests, stats.holm([t["p"] for t in tests]), strict=True):
        test["holm"] = adjusted
        test["rejected"] = bool(adjusted < ALPHA)
    return tests


def decision(tests: list[dict]) -> str:
    """The pre-registered reading of the three primaries."""
    up = [t["score"] for t in tests if t["rejected"] and t["delta"] > 0]
    down = [t["score"] for t in tests if t["rejected"] and t["delta"] < 0]
    if down:
        return f"**AdaRL scores lower than SAC** ({', '.join(down)}): claim 1 is contradicted at this budget"  # fmt: skip
    if "nominal" in up or "worst" in up:
        return f"**AdaRL scores higher than SAC** ({', '.join(up)}): claim 1 is supported at this budget"  # fmt: skip
    if up:
        return f"AdaRL's average over the grid is higher ({', '.join(up)}), its nominal and worst-case scores not detectably: claim 1 is not supported on its own scores"  # fmt: skip
    bounded = [t["score"] for t in tests if -0.10 < t["low"] and t["high"] < 0.10]
    if len(bounded) == len(tests):
        return "no difference detected, and every interval excludes ±0.10: **AdaRL and SAC are within 10% of SAC's score** at this budget"  # fmt: skip
    return "no difference detected (not evidence of absence: read each interval against ±0.10 and the power table)"  # fmt: skip


def complete(seeds: pd.DataFrame, arms=PRIMARY, seed_list=SEEDS) -> bool:
    """Every task × arm × seed of the design present and not excluded."""
    used = seeds[seeds["excluded"] == ""]
    have = set(zip(used["task"], used["arm"], used["seed"], strict=True))
    return all((t, a, s) in have for t in TASKS for a in arms for s in seed_list)


# ----------------------------------------------------------------------------- report
def _p(p: float) -> str:
    return "—" if not np.isfinite(p) else ("< 0.001" if p < 0.001 else f"{p:.3f}")


def _signed(x: float) -> str:
    return f"{x:+.3f}" if np.isfinite(x) else "—"


def report(seeds: pd.DataFrame, running: list[str] = ()) -> list[str]:
    """The report's tables (markdown lines)."""
    used = normalise(seeds)
    done = complete(seeds)
    lines = ["### Runs", ""]
    counts = used.groupby(["arm"]).size().to_dict()
    lines.append(f"{len(used)} seeds in the design ({', '.join(f'{a} {n}' for a, n in sorted(counts.items()))}), "  # fmt: skip
                 f"{len(running)} runs still training; "
                 + ("every seed of the primary arms has finished." if done else "**interim: the primary arms are not complete, no decision is read.**"))  # fmt: skip
    for _, row in seeds[seeds["excluded"] != ""].iterrows():
        lines.append(f"- left out: {row['run']} seed {row['seed']}: {row['excluded']}")
    lines += ["", "### Normalisation per task (u = (score − r_t) / D_t)", "",
              "| task | random r_t | SAC nominal S_t | reference | D_t | floored |",
              "| --- | ---: | ---: | ---: | ---: | --- |"]  # fmt: skip
    scale = scales(seeds)
    for task, row in scale.iterrows():
        lines.append(f"| {task} | {row['random']:,.1f} | {row['sac']:,.1f} | {REFERENCE_RETURN[task]:,.1f} | {row['scale']:,.1f} | {'yes' if row['floored'] else 'no'} |")  # fmt: skip
    tests = primaries(seeds)
    lines += ["", "### Primary tests (Holm over the three)" + ("" if done else " — interim"), "",
              "| score | Δ (mean over tasks of d_t) | 95% t interval | tasks | p | Holm p | rejected |",
              "| --- | ---: | --- | ---: | ---: | ---: | --- |"]  # fmt: skip
    for t in tests:
        lines.append(f"| {t['score']} | {_signed(t['delta'])} | [{_signed(t['low'])}, {_signed(t['high'])}] | {t['tasks']} | {_p(t['p'])} | {_p(t['holm'])} | {'**yes**' if t['rejected'] else 'no'} |")  # fmt: skip
    lines += ["", "Decision (the pre-registered rule): " + (decision(tests) if done else "none yet (interim)"), ""]  # fmt: skip
    lines += ["### Beside the primaries (uncorrected, never called detected)", "",
              "| score | fixed-task 95% | task bootstrap 95% | P(AdaRL > SAC) [95%] | IQM AdaRL − SAC [95%] |",
              "| --- | --- | --- | --- | --- |"]  # fmt: skip
    tasks = list(task_differences(used, "nominal").index)
    for score in SCORES:
        low, high = stratified_interval(used, score)
        blow, bhigh = task_bootstrap(seeds, score, reps=2_000)
        try:
            agg = aggregates(used, score, tasks)
            poi, iqm = agg["poi"], agg["iqm"]
            agg_text = f"{poi.point:.3f} [{poi.low:.3f}, {poi.high:.3f}] | {_signed(iqm.point)} [{_signed(iqm.low)}, {_signed(iqm.high)}]"  # fmt: skip
        except UsageError as exc:
            agg_text = f"— ({exc}) | —"
        lines.append(f"| {score} | [{_signed(low)}, {_signed(high)}] | [{_signed(blow)}, {_signed(bhigh)}] | {agg_text} |")  # fmt: skip
    lines += ["", "### Per task (normalised; mean ± SD over seeds; AdaRL − SAC with Welch's 95%)", "",
              "| task | score | AdaRL | SAC | d_t [Welch 95%] | seeds |", "| --- | --- | --- | --- | --- | --- |"]  # fmt: skip
    for task in tasks:
        for score in SCORES:
            a = used[(used["task"] == task) & (used["arm"] == "adarl")][f"u_{score}"].to_numpy(
                float
            )
            b = used[(used["task"] == task) & (used["arm"] == "sac")][f"u_{score}"].to_numpy(float)
            ci = stats.welch_difference_ci(a, b) if min(len(a), len(b)) > 1 else None
            w = f"[{_signed(ci.low)}, {_signed(ci.high)}]" if ci and np.isfinite(ci.low) else ""
            lines.append(f"| {task} | {score} | {a.mean():.3f} ± {a.std(ddof=1) if len(a) > 1 else 0:.3f} | {b.mean():.3f} ± {b.std(ddof=1) if len(b) > 1 else 0:.3f} | {_signed(a.mean() - b.mean())} {w} | {len(a)}, {len(b)} |")  # fmt: skip
    lines += ["", "### Sensitivity: without the tasks at their ceiling or unlearned", ""]
    ceiling, unlearned = special_tasks(used)
    kept = [t for t in tasks if t not in ceiling + unlearned]
    lines.append(f"At their ceiling (every primary seed's nominal ≥ {CEILING:.0%} of the reference): {', '.join(ceiling) or 'none'}; "  # fmt: skip
                 f"unlearned (both arms' mean nominal u_ref < {LEARNED_FRACTION}): {', '.join(unlearned) or 'none'}.")  # fmt: skip
    lines += [
        "",
        "| score | tasks | Δ | 95% t interval | p |",
        "| --- | ---: | ---: | --- | ---: |",
    ]
    for score in SCORES:
        t = mixed_test(task_differences(used, score, tasks=kept).to_numpy())
        lines.append(f"| {score} | {t['tasks']} | {_signed(t['delta'])} | [{_signed(t['low'])}, {_signed(t['high'])}] | {_p(t['p'])} |")  # fmt: skip
    lines += ["", "### Secondary arms (normalised by the primary pair's r_t and S_t; uncorrected)", "",
              "| comparison | score | Δ | 95% t interval | tasks | p |", "| --- | --- | ---: | --- | ---: | ---: |"]  # fmt: skip
    for a, b in (("control", "sac"), ("fixed", "sac"), ("energy", "sac"), ("adarl", "control"), ("adarl", "fixed")):  # fmt: skip
        for score in SCORES:
            d = task_differences(used, score, a, b)
            if len(d) < 2:
                continue
            t = mixed_test(d.to_numpy())
            lines.append(f"| {a} − {b} | {score} | {_signed(t['delta'])} | [{_signed(t['low'])}, {_signed(t['high'])}] | {t['tasks']} | {_p(t['p'])} |")  # fmt: skip
    return lines


def special_tasks(used: pd.DataFrame) -> tuple[list[str], list[str]]:
    """Tasks at their ceiling (every primary seed's nominal ≥ CEILING of the reference, in
    random-to-reference units) and tasks unlearned (both primary arms' mean below
    LEARNED_FRACTION of that way)."""
    ceiling, unlearned = [], []
    for task, g in used[used["arm"].isin(PRIMARY)].groupby("task"):
        r = g["random_return"].mean()
        u_ref = (g["nominal"] - r) / (REFERENCE_RETURN[task] - r)
        if (u_ref >= CEILING).all():
            ceiling.append(task)
        if g.assign(u=u_ref).groupby("arm")["u"].mean().max() < LEARNED_FRACTION:
            unlearned.append(task)
    return sorted(ceiling), sorted(unlearned)


def figure(seeds: pd.DataFrame, stem: Path) -> list[Path]:
    """Per task, each primary arm's normalised nominal and worst-case score per seed (two
    panels), and the aggregate intervals (Δ's t interval, the IQM difference, P(AdaRL > SAC))."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    used = normalise(seeds)
    tasks = list(task_differences(used, "nominal").index)
    fig, axes = plt.subplots(1, 3, figsize=(14, 0.45 * len(tasks) + 2.2), gridspec_kw={"width_ratios": [2, 2, 1.6]})  # fmt: skip
    colours = {"adarl": "tab:blue", "sac": "tab:orange"}
    for ax, score, title in ((axes[0], "nominal", "nominal dynamics"), (axes[1], "worst", "worst case over the grid")):  # fmt: skip
        for i, task in enumerate(tasks):
            for j, arm in enumerate(PRIMARY):
                v = used[(used["task"] == task) & (used["arm"] == arm)][f"u_{score}"].to_numpy(
                    float
                )
                y = i + (j - 0.5) * 0.3 + np.linspace(-0.08, 0.08, len(v)) if len(v) else []
                ax.scatter(v, y, s=14, color=colours[arm], alpha=0.7, label=arm if i == 0 else None)  # fmt: skip
                if len(v):
                    ax.plot([v.mean()] * 2, [i + (j - 0.5) * 0.3 - 0.14, i + (j - 0.5) * 0.3 + 0.14], color=colours[arm], lw=2.5)  # fmt: skip
        ax.axvline(1.0, color="grey", ls=":", lw=1)
        ax.axvline(0.0, color="grey", ls="-", lw=0.5)
        ax.set_yticks(range(len(tasks)), tasks if ax is axes[0] else [""] * len(tasks))
        ax.set_ylim(len(tasks) - 0.5, -0.5)
        ax.set_title(f"per seed, {title}")
    fig.supxlabel(
        "normalised score u (0: random actions, 1: SAC's nominal mean)", x=0.33, fontsize=10
    )
    axes[0].legend(loc="lower left", bbox_to_anchor=(0, 1.06), ncol=2, frameon=False, fontsize=8)
    ax = axes[2]
    rows = []
    for score in SCORES:
        t = mixed_test(task_differences(used, score).to_numpy())
        rows.append((f"Δ {score}", t["delta"], t["low"], t["high"]))
        try:
            agg = aggregates(used, score, tasks, reps=2_000)
            rows.append((f"IQM diff {score}", agg["iqm"].point, agg["iqm"].low, agg["iqm"].high))
            rows.append((f"P(A>S) − ½ {score}", agg["poi"].point - 0.5, agg["poi"].low - 0.5, agg["poi"].high - 0.5))  # fmt: skip
        except UsageError:
            pass
    for i, (_label, point, low, high) in enumerate(rows):
        ax.plot([low, high], [i, i], color="k", lw=1.5)
        ax.plot([point], [i], "o", color="k", ms=4)
    ax.axvline(0, color="grey", lw=0.8)
    for x in (-0.1, 0.1):
        ax.axvline(x, color="grey", ls=":", lw=0.8)
    ax.set_yticks(range(len(rows)), [r[0] for r in rows], fontsize=8)
    ax.yaxis.tick_right()
    ax.set_ylim(len(rows) - 0.5, -0.5)
    ax.set_title("AdaRL − SAC, 95% intervals")
    ax.set_xlabel("difference (dotted: ±0.10)")
    fig.tight_layout()
    paths = [stem.with_suffix(".png"), stem.with_suffix(".pdf")]
    for path in paths:
        fig.savefig(path, dpi=130)
    plt.close(fig)
    return paths


# ----------------------------------------------------------------------------- power
# the claim-2 rows' seed SD of the nominal return over SAC's gap above random (S − r), per task
# (pooled over the two rules, 5 seeds each; InvertedDoublePendulum has none: 0.3 assumed)
CLAIM2_SPREAD = {
    "InvertedPendulum-v5": 0.000, "Reacher-v5": 0.012, "Swimmer-v5": 0.076, "hopper": 0.557,
    "HalfCheetah-v5": 0.123, "walker2d": 0.553, "Pusher-v5": 0.008, "ant": 0.218,
    "humanoid": 0.227, "InvertedDoublePendulum-v5": 0.300,
}  # fmt: skip


def simulated_p(delta: float, spread: np.ndarray, tau: float, n: int, noise, level: float) -> float:
    """Power of the primary test: each task's SAC seeds score 1 + σ_t·e, AdaRL's 1 + Δ + v_t +
    σ_t·e (raw units of SAC's gap above random), v_t ~ N(0, τ²) the task's own effect; both
    divided by SAC's sample mean (the estimated D_t); the t test of the task differences at
    `level`. `noise` = (e_sac, e_adarl, v) standard normals of shapes (sims, n, T) ×2, (sims, T)."""
    e_s, e_a, v = noise
    sac = 1 + spread * e_s[:, :n]
    ada = 1 + delta + tau * v[:, None, :] + spread * e_a[:, :n]
    scale = sac.mean(axis=1)
    d = (ada.mean(axis=1) - sac.mean(axis=1)) / scale
    k = d.shape[1]
    se = d.std(axis=1, ddof=1) / np.sqrt(k)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = 2 * st.t.sf(np.abs(d.mean(axis=1)) / se, k - 1)
    return float(np.mean(p < level))


def detectable(power_of, high: float = 1.0, target: float = 0.8, steps: int = 18) -> float:
    """The smallest Δ with power ≥ target, by bisection on [0, high]."""
    low = 0.0
    if power_of(high) < target:
        return float("inf")
    for _ in range(steps):
        mid = (low + high) / 2
        low, high = (mid, high) if power_of(mid) < target else (low, mid)
    return high


def power_table(sims: int = 4_000, seed: int = 1) -> list[str]:
    """Power of the primary test at Δ = 0.10 and the smallest Δ it detects with 80% power, at
    Holm's strictest level α/3, for seeds per arm n and task effects' SD τ: the nominal score with
    the claim-2 spreads, and robustness scores with one spread σ_u on every task."""
    n_max, T = max(SEED_OPTIONS), len(TASKS)
    rng = np.random.default_rng(seed)
    noise = (rng.standard_normal((sims, n_max, T)), rng.standard_normal((sims, n_max, T)), rng.standard_normal((sims, T)))  # fmt: skip
    level = ALPHA / len(SCORES)
    scenarios = [("nominal: claim-2 spreads", np.array([CLAIM2_SPREAD[t] for t in TASKS]))]
    scenarios += [(f"σ_u = {s} on every task", np.full(T, s)) for s in (0.2, 0.3, 0.5)]
    lines = [f"{sims:,} simulated designs per cell (the same draws in every cell), T = {T} tasks, level α/3 = {level:.4f}", "",  # fmt: skip
             "| spreads | τ | " + " | ".join(f"n = {n}: power at 0.10 / detectable Δ" for n in SEED_OPTIONS) + " |",  # fmt: skip
             "| --- | ---: | " + " | ".join("---" for _ in SEED_OPTIONS) + " |"]  # fmt: skip
    for name, spread in scenarios:
        for tau in (0.0, 0.05, 0.10):
            cells = []
            for n in SEED_OPTIONS:
                power = simulated_p(0.10, spread, tau, n, noise, level)
                d = detectable(lambda x, n=n, spread=spread, tau=tau: simulated_p(x, spread, tau, n, noise, level))  # fmt: skip
                cells.append(f"{power:.2f} / {d:.3f}")
            lines.append(f"| {name} | {tau:.2f} | " + " | ".join(cells) + " |")
    null = simulated_p(0.0, scenarios[0][1], 0.0, 10, noise, ALPHA)
    lines += [
        "",
        f"Type I error at α = 0.05, Δ = 0, τ = 0, the claim-2 spreads, n = 10: {null:.3f}",
    ]
    return lines


SEED_OPTIONS = (5, 10, 15, 20)


# ----------------------------------------------------------------------------- the campaign's files
def sweep_file(block: str, arms, seeds, tasks_rank: dict | None = None) -> dict:
    """One sweep file of the design: `arms` on the ten tasks, `seeds`, one seed per unit, the
    claim-2 schedule. The fixed-rank arm's `rank` per task comes from `tasks_rank`."""
    tasks = {}
    for task in TASKS:
        entry = {}
        if task == "Reacher-v5":
            entry["max_episode_steps"] = 50
        if task == "Pusher-v5":
            entry["max_episode_steps"] = 100
        tasks[task] = entry
    algos = []
    for arm in arms:
        algo, rule = ARMS[arm]
        entry = {"algo": algo}
        if rule:
            entry["grid"] = {"rank_rule": [rule]}
        algos.append(entry)
    file = {
        "name": "claim1-across-tasks",
        "description": f"claim 1 across tasks, {block}: {', '.join(arms)}, seeds {seeds[0]}-{seeds[-1]}, 10 tasks, 100k steps, the claim-2 schedule",  # fmt: skip
        "tasks": tasks,
        "algos": algos,
        "seeds": f"{seeds[0]}-{seeds[-1]}" if len(seeds) > 1 else seeds[0],
        "seeds_per_unit": 1,
        "budget": BUDGET,
        "dynamics": "paper",
        "preset": "paper",
        "evaluation": {"eval_every": 10_000, "eval_episodes": 5, "eval_dynamics": ["nominal"]},
        "overrides": {
            "truncate_every": TRUNCATE_EVERY,
            "start_steps": 5_000,
            "buffer_size": 100_000,
            "beta": 0.98,
            "hidden": [64, 64],
            "log_every": 5_000,
            "checkpoint_every": 20_000,
            "keep_checkpoints": 1,
            "checkpoint_before_truncation": False,
        },  # fmt: skip
    }
    if tasks_rank:
        for task, rank in tasks_rank.items():
            file["tasks"][task]["rank"] = int(rank)
    return file


def write_sweeps(folder: Path = FOLDER) -> list[Path]:
    """The primary pair's files, one per seed (each a balanced block of 20 units)."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    header = ("# Claim 1 across tasks (issue 65 §1), pre-registered in docs/experiments/claim1-across-tasks.md\n"  # fmt: skip
              "# before its first row; written by `python docs/experiments/claim1_across_tasks.py sweeps`.\n")  # fmt: skip
    for seed in SEEDS:
        path = folder / f"primary-seed-{seed}.yaml"
        text = header + yaml.safe_dump(sweep_file(f"primary block {seed}", PRIMARY, [seed]), sort_keys=False)  # fmt: skip
        atomic_write_text(path, text)
        paths.append(path)
    return paths


def evaluate(sweep: Path, code: Path | None = None, python: str = sys.executable) -> tuple[list[list[str]], int]:  # fmt: skip
    """Run the robustness grid (`adarl evaluate`, the final policy, `EPISODES` a point, 2 workers)
    on every finished run under `sweep` that has none yet: the generic grid on the generic tasks,
    the `paper` suite at 5 points a parameter on the paper's four, with the adarl of `code` (the
    campaign's frozen worktree; default this checkout's). Returns the commands run and the first
    non-zero exit status (0 if none); a failed command stops the rest."""
    generic, paper = [], []
    for run in find_runs([sweep]):
        if run.done_step is None or (run.path / "evaluations" / robustness_file(run.task)).is_file():  # fmt: skip
            continue
        (paper if canonical(run.task) in PAPER_TASKS else generic).append(str(run.path))
    commands = []
    for runs, flags in ((generic, GENERIC_FLAGS), (paper, PAPER_FLAGS)):
        if runs:
            command = [python, "-m", "adarl.cli.main", "evaluate", *runs, *flags,
                       "--episodes", str(EPISODES), "--workers", "2", "--no-progress"]  # fmt: skip
            commands.append(command)
            status = subprocess.run(command, cwd=code).returncode
            if status:
                return commands, status
    return commands, 0


def export(sweep: Path, rows: Path | None = None) -> tuple[list[Path], list[Path]]:
    """Copy every finished run under `sweep` whose robustness grid is done (config.yaml and DONE
    as they are; its CSVs and the grid's episodes gzipped; never checkpoints or policies) to the
    same place under `rows`. Returns the files written and the runs left."""
    rows = ROWS if rows is None else rows
    written, left = [], []
    for run in find_runs([sweep]):
        grid = Path("evaluations") / robustness_file(run.task)
        if run.done_step is None or not (run.path / grid).is_file():
            left.append(run.path)
            continue
        target = rows / run.path.relative_to(sweep)
        (target / "evaluations").mkdir(parents=True, exist_ok=True)
        for name in RUN_FILES:
            shutil.copyfile(run.path / name, target / name)
            written.append(target / name)
        for name in (*FILES, str(grid)):
            if (run.path / name).is_file():
                with (run.path / name).open("rb") as f, gzip.GzipFile(target / f"{name}.gz", "wb", mtime=0) as g:  # fmt: skip
                    shutil.copyfileobj(f, g)
                written.append(target / f"{name}.gz")
    return written, left


def restore(sweep: Path, rows: Path | None = None) -> list[Path]:
    """The committed rows back into a sweep folder (gunzipped), so that a new machine's sweep
    skips their units and `evaluate` their grids. Existing files are kept."""
    rows = ROWS if rows is None else rows
    restored = []
    for source in sorted(p for p in rows.rglob("*") if p.is_file()):
        relative = source.relative_to(rows)
        target = sweep / (relative.with_suffix("") if source.suffix == ".gz" else relative)
        if target.exists():
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(gzip.decompress(source.read_bytes()) if source.suffix == ".gz" else source.read_bytes())  # fmt: skip
        restored.append(target)
    return restored


# ----------------------------------------------------------------------------- command line
def main(argv: list[str]) -> int:
    try:
        return _main(argv)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def _folder(argv: list[str], verb: str) -> Path:
    if len(argv) != 2 or not Path(argv[1]).is_dir():
        raise UsageError(f"{verb} takes one sweep folder, got {' '.join(argv[1:]) or 'none'}")
    return Path(argv[1])


def _main(argv: list[str]) -> int:
    usage = "usage: claim1_across_tasks.py SWEEP_DIR [--out DIR] | power [--sims N] | sweeps | evaluate SWEEP_DIR [--code DIR] | export SWEEP_DIR | restore SWEEP_DIR [--rows DIR]"  # fmt: skip
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__)
        return 0
    verb = argv[0] if argv else ""
    if verb == "power":
        sims = 4_000
        if argv[1:2] == ["--sims"] and len(argv) == 3 and argv[2].isdigit() and int(argv[2]) > 0:
            sims = int(argv[2])
        elif len(argv) != 1:
            raise UsageError(f"power takes --sims N (a whole number > 0), got {' '.join(argv[1:])!r}")  # fmt: skip
        print("\n".join(power_table(sims)))
        return 0
    if verb == "sweeps":
        for path in write_sweeps():
            print(f"wrote {path}")
        return 0
    if verb == "evaluate":
        code = None
        if argv[2:3] == ["--code"] and len(argv) == 4 and Path(argv[3]).is_dir():
            code, argv = Path(argv[3]), argv[:2]
        commands, status = evaluate(_folder(argv, verb), code)
        for command in commands:
            print(" ".join(command))
        return status
    if verb == "export":
        written, left = export(_folder(argv, verb))
        print(f"wrote {len(written)} files under {ROWS}; {len(left)} runs left (training or no grid yet)")  # fmt: skip
        return 0
    if verb == "restore":  # also another design's rows: restore SWEEP_DIR --rows ROWS
        rows = None
        if argv[2:3] == ["--rows"] and len(argv) == 4:
            rows, argv = Path(argv[3]), argv[:2]
        if len(argv) != 2:
            raise UsageError("restore takes one sweep folder (and --rows DIR)")
        sweep = Path(argv[1])
        print(f"restored {len(restore(sweep, rows))} files into {sweep}")
        return 0
    if not argv or verb.startswith("-"):
        print(usage, file=sys.stderr)
        return 2
    out = None
    if argv[1:2] == ["--out"] and len(argv) == 3:
        out = Path(argv[2])
    elif len(argv) != 1:
        print(usage, file=sys.stderr)
        return 2
    seeds, running = load([argv[0]])
    lines = report(seeds, running)
    print("\n".join(lines))
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / "report.md", "\n".join(lines) + "\n")
        for path in figure(seeds, out / "claim1"):
            print(f"wrote {path}")
        print(f"wrote {out / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
