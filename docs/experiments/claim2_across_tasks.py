"""Claim 2 across tasks (docs/experiments/claim2-across-tasks.md): does the rank AdaRL keeps follow
2·d_a + 1? The pre-registered analysis, from the runs' own rows only.

    python docs/experiments/claim2_across_tasks.py SWEEP_DIR --out docs/experiments/claim2-across-tasks
    python docs/experiments/claim2_across_tasks.py export SWEEP_DIR   # raw rows -> claim2-across-tasks/rows/
    python docs/experiments/claim2_across_tasks.py power [--sims N]   # the design's power table

SWEEP_DIR is the sweep folder (or the exported rows, which are run folders without checkpoints).
The first form prints the report's tables and writes them to OUT/report.md, with the figures
OUT/ranks.png/.pdf (kept actor rank per seed per cut against 2·d_a + 1 with the identity line, one
panel per rule, and rank against cut index) and OUT/width-beta.png/.pdf (the width and β arm).

What it computes (the pre-registration's names):
- per seed: the kept rank of each bottleneck after each of the 4 cuts (truncations.csv
  `new_rank`), the final actor rank (after cut 4) and the final critic rank (the mean of the two
  critics'); the return, the mean of the nominal evaluations after the last cut
  (`adarl.results.collect.last_evaluations`, the last 2: 90k and 100k); the random-action return,
  the mean return of the training episodes that ended within `start_steps`; the normalised score
  u = (return − random) / (reference − random) and "learned" = u ≥ 0.1;
- primaries (main arm: 64 wide, β = 0.98, one fit per rule): the final actor rank's task means
  regressed on x = 2·d_a + 1 (ordinary least squares on the task means, which for seeds nested in
  tasks with the same seeds per task is the random-intercept mixed model's estimate and exact test,
  K − 2 degrees of freedom): the paper's line, (intercept, slope) = (0, 1), by its F test with
  (2, K − 2) degrees of freedom, and slope 0 by its t test; and, in the width and β arm, the
  effect of width 128 against 64 on log final actor rank (cell fixed effects: task × β), one per
  rule. Holm over the six;
- beside them (never called detected): the task-level bootstrap interval of the slope (tasks
  resampled, and seeds within them), the slope with each task left out, the critics' fits, the
  fits on the seeds that learned, the effect of β and of the task in the arm.
"""

from __future__ import annotations

import gzip
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats as st

from adarl import stats
from adarl.errors import UsageError
from adarl.files import atomic_write_text
from adarl.results import collect
from adarl.results.runs import Run, config_value, find_runs

HERE = Path(__file__).resolve().parent
FOLDER = HERE / "claim2-across-tasks"
ROWS = FOLDER / "rows"
FILES = ("eval.csv", "truncations.csv", "episodes.csv", "train.csv")
RUN_FILES = ("config.yaml", "DONE")

BUDGET = 100_000  # environment steps per seed
TRUNCATE_EVERY = 20_000  # d_t, gradient steps: the paper's budget/d_t ratio 5 (5M / 10^6)
CUTS = 4  # truncations in BUDGET steps: after 20k, 40k, 60k and 80k updates
RULES = ("cumulative", "energy")  # Eq. 5 (the paper's), adarl's default
MAIN_WIDTH, MAIN_BETA = 64, 0.98
ARM_TASKS = ("InvertedPendulum-v5", "walker2d")
ARM_WIDTHS = (64, 128)
ARM_BETAS = (0.98, 0.9)
SEEDS = (0, 1, 2, 3, 4)  # main arm; the arm's other cells: 0-2
ARM_SEEDS = (0, 1, 2)
ACTOR, CRITICS = "actor_1", ("q1_1", "q2_1")
ALPHA = 0.05
SCORE_EVALUATIONS = 2  # the nominal evaluations after the last cut (steps 90k and 100k)
LEARNED_FRACTION = 0.1
# task -> d_a (Gymnasium's action sizes), in the order of 2·d_a + 1
ACTION_DIM = {
    "InvertedPendulum-v5": 1,
    "Reacher-v5": 2,
    "Swimmer-v5": 2,
    "hopper": 3,
    "HalfCheetah-v5": 6,
    "walker2d": 6,
    "Pusher-v5": 7,
    "ant": 8,
    "humanoid": 17,
}
TASKS = tuple(ACTION_DIM)
# the return a policy that learned the task reaches: the paper's AdaRL (its Table 1) on its four
# tasks, Gymnasium's `reward_threshold` on the others (Pusher's 0 is its reward's supremum)
REFERENCE_RETURN = {
    "InvertedPendulum-v5": 950.0,
    "Reacher-v5": -3.75,
    "Swimmer-v5": 360.0,
    "hopper": 2109.8,
    "HalfCheetah-v5": 4800.0,
    "walker2d": 3991.9,
    "Pusher-v5": 0.0,
    "ant": 3067.13,
    "humanoid": 5428.72,
}


def canonical(task: str) -> str:
    """The design's name of `task` (matched without regard to case); a task outside it is a
    one-line error naming it and the tasks allowed."""
    for name in TASKS:
        if name.lower() == str(task).lower():
            return name
    raise UsageError(f"task {task!r} is not one of this experiment's: {', '.join(TASKS)}")


def intrinsic(task: str) -> int:
    """2·d_a + 1 (Tiwari et al.'s bound, the paper's intrinsic rank)."""
    return 2 * ACTION_DIM[canonical(task)] + 1


# ----------------------------------------------------------------------------- reading runs
def table(folder: Path, name: str) -> pd.DataFrame:
    """A run CSV read and checked by `adarl.results.collect.read_table`, plain or gzipped (as
    `export` writes it); empty when the run has neither."""
    plain = Path(folder) / name
    if plain.is_file():
        return collect.read_table(plain)
    packed = plain.with_name(name + ".gz")
    if not packed.is_file():
        return pd.DataFrame()
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / name  # read_table checks columns by the file's name
        copy.write_bytes(gzip.decompress(packed.read_bytes()))
        try:
            return collect.read_table(copy)
        except UsageError as exc:
            raise UsageError(str(exc).replace(str(copy), str(packed))) from None


def seed_rows(run: Run) -> list[dict]:
    """One record per seed of a finished run: its arm's settings, its kept ranks after each cut
    (`<layer>_cuts`, in cut order), final actor and critic rank, return, random-action return,
    normalised score and whether it learned. A run whose schedule is not the design's, or that
    did not truncate `CUTS` times, gives records with `excluded` saying why."""
    config = run.config
    task = canonical(run.task)
    width = int(list(config_value(config, "hidden", [0]))[0])
    base = {
        "task": task,
        "x": intrinsic(task),
        "rule": str(config_value(config, "rank_rule")),
        "beta": float(config_value(config, "beta")),
        "width": width,
        "run": str(run.path),
        "excluded": "",
    }
    schedule = (run.total_steps, int(config_value(config, "truncate_every", 0)))
    if schedule != (BUDGET, TRUNCATE_EVERY):
        base["excluded"] = f"schedule {schedule[0]:,} steps, d_t {schedule[1]:,}, not the design's"
    cuts = table(run.path, "truncations.csv")
    evaluations = table(run.path, "eval.csv")
    episodes = table(run.path, "episodes.csv")
    nominal = evaluations[evaluations["dynamics"] == collect.NOMINAL] if len(evaluations) else evaluations  # fmt: skip
    returns = collect.last_evaluations(nominal, SCORE_EVALUATIONS).set_index("seed")["score"]
    start = int(config_value(config, "start_steps", 0))
    records = []
    for seed in run.seeds:
        record = dict(base, seed=int(seed))
        mine = cuts[cuts["seed"] == seed] if len(cuts) else cuts
        steps = sorted(int(s) for s in mine["step"].unique()) if len(mine) else []
        if not record["excluded"] and len(steps) != CUTS:
            record["excluded"] = f"{len(steps)} truncations, not {CUTS}"
        for layer in (ACTOR, *CRITICS):
            rows = mine[mine["layer"] == layer].sort_values("step") if len(mine) else mine
            record[f"{layer}_cuts"] = tuple(int(r) for r in rows["new_rank"]) if len(rows) else ()
        record["actor"] = record[f"{ACTOR}_cuts"][-1] if record[f"{ACTOR}_cuts"] else np.nan
        finals = [record[f"{c}_cuts"][-1] for c in CRITICS if record[f"{c}_cuts"]]
        record["critic"] = float(np.mean(finals)) if len(finals) == len(CRITICS) else np.nan
        record["return"] = float(returns.get(seed, np.nan))
        random_phase = episodes[(episodes["seed"] == seed) & (episodes["step"] <= start)] if len(episodes) else episodes  # fmt: skip
        record["random_return"] = float(random_phase["return"].mean()) if len(random_phase) else np.nan  # fmt: skip
        record["normalised"] = normalised(task, record["return"], record["random_return"])
        record["learned"] = bool(record["normalised"] >= LEARNED_FRACTION)
        records.append(record)
    return records


def normalised(task: str, score: float, random_return: float) -> float:
    """u = (score − random) / (reference − random): 0 at the random-action return, 1 at the
    task's `REFERENCE_RETURN`; NaN where the reference is not above random."""
    span = REFERENCE_RETURN[canonical(task)] - random_return
    return float((score - random_return) / span) if span > 0 else float("nan")


def load(paths) -> tuple[pd.DataFrame, list[str]]:
    """Every finished seed of the runs under `paths` (sweep folders or exported rows), one row per
    seed (`seed_rows`), and the runs left out as still training."""
    runs = find_runs([Path(p) for p in paths])
    records, running = [], []
    for run in runs:
        if run.done_step is None:
            running.append(str(run.path))
            continue
        records += seed_rows(run)
    columns = ["task", "x", "rule", "beta", "width", "seed", "actor", "critic", "return",
               "random_return", "normalised", "learned", "excluded", "run"]  # fmt: skip
    seeds = pd.DataFrame(records) if records else pd.DataFrame(columns=columns)
    return seeds, running


def main_arm(seeds: pd.DataFrame, rule: str) -> pd.DataFrame:
    """The seeds of the main arm under `rule`: 64 wide, β = 0.98, kept by the design."""
    keep = (seeds["rule"] == rule) & (seeds["width"] == MAIN_WIDTH) & np.isclose(seeds["beta"], MAIN_BETA)  # fmt: skip
    return seeds[keep & (seeds["excluded"] == "")]


def width_arm(seeds: pd.DataFrame, rule: str) -> pd.DataFrame:
    """The seeds of the width and β arm under `rule`: its two tasks, every width and β (the cell
    64 wide at β = 0.98 is the main arm's)."""
    keep = (seeds["rule"] == rule) & seeds["task"].isin(ARM_TASKS) & (seeds["excluded"] == "")
    return seeds[keep]


# ----------------------------------------------------------------------------- the tests
def line_tests(x, y) -> dict:
    """Ordinary least squares of task means `y` (..., K) on `x` (K,), vectorised over leading
    axes: intercept a, slope b, their standard errors and 95% t intervals (K − 2 degrees of
    freedom), the residual SD s, the two-sided t test of slope 0 (`p_flat`) and the F test of
    the paper's line (a, b) = (0, 1): F = δᵀ XᵀX δ / (2 s²), δ = (a, b − 1), (2, K − 2) degrees of
    freedom (`p_paper`). With no residual variance (every mean on the line) a test's p is 1 when
    its statistic's numerator is 0 and 0 otherwise."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    k = x.size
    df = k - 2
    if df < 1 or np.ptp(x) == 0:
        raise ValueError(f"a line needs at least 3 tasks with different x, got x = {x.tolist()}")
    x_mean, sxx = x.mean(), ((x - x.mean()) ** 2).sum()
    y_mean = y.mean(axis=-1)
    b = ((x - x_mean) * (y - y_mean[..., None])).sum(axis=-1) / sxx
    a = y_mean - b * x_mean
    rss = ((y - a[..., None] - b[..., None] * x) ** 2).sum(axis=-1)
    s2 = rss / df
    se_b, se_a = np.sqrt(s2 / sxx), np.sqrt(s2 * (1 / k + x_mean**2 / sxx))
    tol = 1e-12 * (1.0 + (y**2).sum(axis=-1))
    d_a, d_b = a, b - 1.0
    wald = k * d_a**2 + 2 * x.sum() * d_a * d_b + (x**2).sum() * d_b**2
    with np.errstate(divide="ignore", invalid="ignore"):
        t_flat = b / se_b
        f_paper = wald / 2 / s2
        p_flat = np.where(rss > tol, 2 * st.t.sf(np.abs(t_flat), df), np.where(np.abs(b) * sxx > tol, 0.0, 1.0))  # fmt: skip
        p_paper = np.where(rss > tol, st.f.sf(f_paper, 2, df), np.where(wald > tol, 0.0, 1.0))
    q = st.t.ppf(1 - ALPHA / 2, df)
    return {
        "intercept": a, "slope": b, "se_intercept": se_a, "se_slope": se_b, "s": np.sqrt(s2),
        "df": df, "slope_ci": (b - q * se_b, b + q * se_b),
        "intercept_ci": (a - q * se_a, a + q * se_a),
        "t_flat": t_flat, "p_flat": p_flat, "f_paper": f_paper, "p_paper": p_paper,
    }  # fmt: skip


def task_means(arm: pd.DataFrame, column: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """x, the mean of `column` over each task's seeds, and the tasks, in the design's order."""
    tasks = [t for t in TASKS if t in set(arm["task"])]
    means = np.array([arm.loc[arm["task"] == t, column].mean() for t in tasks])
    return np.array([intrinsic(t) for t in tasks], float), means, tasks


def bootstrap_slope(arm: pd.DataFrame, column: str, reps: int = 10_000, seed: int = 0) -> tuple:
    """The slope's task-level bootstrap: tasks drawn with replacement, each drawn task's seeds
    drawn with replacement, the slope refitted on the drawn task means; the 2.5% and 97.5%
    percentiles, and how many draws were dropped because every drawn task had the same x."""
    x, _, tasks = task_means(arm, column)
    values = [arm.loc[arm["task"] == t, column].to_numpy(float) for t in tasks]
    rng = np.random.default_rng(seed)
    k = len(tasks)
    drawn = rng.integers(0, k, (reps, k))
    # a fresh within-task draw for every (task, position) pair
    means = np.empty((k, k, reps))
    for i, v in enumerate(values):
        means[i] = v[rng.integers(0, v.size, (k, reps, v.size))].mean(axis=-1)
    y = means[drawn, np.arange(k)[None, :], np.arange(reps)[:, None]]
    xs = x[drawn]
    xc = xs - xs.mean(axis=1, keepdims=True)
    sxx = (xc**2).sum(axis=1)
    ok = sxx > 0
    slopes = (xc[ok] * (y[ok] - y[ok].mean(axis=1, keepdims=True))).sum(axis=1) / sxx[ok]
    low, high = np.percentile(slopes, [100 * ALPHA / 2, 100 * (1 - ALPHA / 2)])
    return float(low), float(high), int((~ok).sum())


def leave_one_out(arm: pd.DataFrame, column: str) -> dict[str, float]:
    """The slope refitted with each task left out in turn: task -> slope."""
    x, y, tasks = task_means(arm, column)
    return {
        t: float(line_tests(np.delete(x, i), np.delete(y, i))["slope"]) for i, t in enumerate(tasks)
    }


def effect_design(arm: pd.DataFrame, factor: str = "width") -> np.ndarray:
    """The design matrix of `width_effect`: one indicator column per cell (task × β for the width
    effect, task × width for β's), then the indicator of width 128 (or of β = 0.9)."""
    other = "beta" if factor == "width" else "width"
    cells = sorted({(t, v) for t, v in zip(arm["task"], arm[other], strict=True)})
    high = (arm["width"] == max(ARM_WIDTHS)) if factor == "width" else np.isclose(arm["beta"], min(ARM_BETAS))  # fmt: skip
    return np.column_stack(
        [((arm["task"] == t) & np.isclose(arm[other], v)).to_numpy(float) for t, v in cells]
        + [np.asarray(high, float)]
    )


def effect_test(design: np.ndarray, y) -> dict:
    """Ordinary least squares of `y` (..., N) on `design` (N × p), vectorised over leading axes:
    the last coefficient with its 95% t interval and two-sided p (N − p degrees of freedom); NaN
    where the design cannot estimate it. With no residual variance (every seed on its cell's
    value) p is 1 for an effect of 0 and 0 otherwise."""
    y = np.asarray(y, float)
    n, k = design.shape
    df = n - k
    nan = np.full(y.shape[:-1], np.nan)
    if df < 1 or np.linalg.matrix_rank(design) < k:
        return {"effect": nan, "ci": (nan, nan), "p": nan, "df": df, "n": n}
    inverse = np.linalg.inv(design.T @ design)
    coef = y @ (design @ inverse)  # (..., p): (XᵀX)⁻¹ Xᵀ y
    rss = ((y - coef @ design.T) ** 2).sum(axis=-1)
    w, se = coef[..., -1], np.sqrt(rss / df * inverse[-1, -1])
    scale = 1.0 + np.abs(y).max(axis=-1)  # below these, rounding: an exact fit, an effect of 0
    exact, zero = rss <= 1e-20 * scale**2 * n, np.abs(w) <= 1e-9 * scale
    with np.errstate(divide="ignore", invalid="ignore"):
        p = np.where(exact, np.where(zero, 1.0, 0.0), 2 * st.t.sf(np.abs(w / se), df))
    q = st.t.ppf(1 - ALPHA / 2, df)
    return {"effect": w, "ci": (w - q * se, w + q * se), "p": p, "df": df, "n": n}


def width_effect(arm: pd.DataFrame, column: str = "actor", factor: str = "width") -> dict:
    """log(final rank) = cell + w·[width 128] (cells: task × β), ordinary least squares over the
    seeds: w with its 95% t interval and two-sided p (N − cells − 1 degrees of freedom); w / log 2
    is the rank's elasticity to the width (0: the rank does not follow the width, 1: it doubles
    with it). `factor="beta"` fits the effect of β = 0.9 against 0.98 the same way, cells task ×
    width."""
    arm = arm.dropna(subset=[column])
    if arm.empty:
        return {"effect": np.nan, "ci": (np.nan, np.nan), "p": np.nan, "df": 0, "n": 0}
    out = effect_test(effect_design(arm, factor), np.log(arm[column].to_numpy(float)))
    return {k: (tuple(float(v) for v in out[k]) if k == "ci" else float(out[k]) if k in ("effect", "p") else out[k]) for k in out}  # fmt: skip


def primaries(seeds: pd.DataFrame) -> list[dict]:
    """The six pre-registered tests, with Holm's adjusted p over them: per rule, the paper's line
    and slope 0 for the final actor rank (main arm), and the width effect (arm). A test whose data
    are not there yet has p NaN and enters no correction."""
    tests = []
    for rule in RULES:
        arm = main_arm(seeds, rule)
        x, y, tasks = task_means(arm, "actor")
        fit = line_tests(x, y) if len(tasks) >= 3 and np.ptp(x) > 0 else None
        for name in ("paper", "flat"):
            p = float(fit[f"p_{name}"]) if fit else np.nan
            tests.append({"rule": rule, "test": name, "p": p, "fit": fit, "tasks": tasks})
        effect = width_effect(width_arm(seeds, rule))
        tests.append({"rule": rule, "test": "width", "p": effect["p"], "fit": effect, "tasks": []})
    finite = [t for t in tests if np.isfinite(t["p"])]
    for t, a in zip(finite, stats.holm([t["p"] for t in finite]) if finite else [], strict=True):
        t["holm"] = a
    for t in tests:
        t.setdefault("holm", np.nan)
        t["rejected"] = bool(t["holm"] < ALPHA)
    return tests


def decision(paper_rejected: bool, flat_rejected: bool) -> str:
    """The pre-registered reading of the two line tests of one rule."""
    if paper_rejected and not flat_rejected:
        return "does not follow 2·d_a + 1: the line (0, 1) is rejected and no dependence on d_a was detected"  # fmt: skip
    if paper_rejected and flat_rejected:
        return "depends on d_a, but not as 2·d_a + 1: both the line (0, 1) and slope 0 are rejected"
    if flat_rejected:
        return "consistent with 2·d_a + 1: slope 0 is rejected, the line (0, 1) is not"
    return "undecided: neither the line (0, 1) nor slope 0 is rejected"


def complete(seeds: pd.DataFrame) -> bool:
    """Every seed of the design has finished: the main arm's 9 tasks × 2 rules × 5 seeds and the
    arm's 2 tasks × 2 rules × 3 cells × 3 seeds."""
    for rule in RULES:
        main = main_arm(seeds, rule)
        for task in TASKS:
            if sorted(main.loc[main["task"] == task, "seed"]) != list(SEEDS):
                return False
        arm = width_arm(seeds, rule)
        for task in ARM_TASKS:
            for width in ARM_WIDTHS:
                for beta in ARM_BETAS:
                    if (width, beta) == (MAIN_WIDTH, MAIN_BETA):
                        continue
                    cell = arm[(arm["task"] == task) & (arm["width"] == width) & np.isclose(arm["beta"], beta)]  # fmt: skip
                    if sorted(cell["seed"]) != list(ARM_SEEDS):
                        return False
    return True


# ----------------------------------------------------------------------------- the report
def _p(p: float) -> str:
    return "—" if not np.isfinite(p) else ("< 0.001" if p < 0.001 else f"{p:.3f}")


def _range(values) -> str:
    values = [v for v in values if np.isfinite(v)]
    if not values:
        return "—"
    lo, hi = min(values), max(values)
    return f"{lo:g}" if lo == hi else f"{lo:g}–{hi:g}"


def report(seeds: pd.DataFrame, running: list[str] = ()) -> list[str]:
    kept = seeds[seeds["excluded"] == ""]
    done = complete(seeds)
    lines = ["### Runs", ""]
    lines.append(
        f"{len(kept)} finished seeds in the design, {len(running)} runs still training"
        + (
            "; every seed of the design has finished."
            if done
            else "; **interim**: the design is not complete, no decision is read."
        )
    )
    for _, r in seeds[seeds["excluded"] != ""].iterrows():
        lines.append(f"- left out: {r['run']} seed {r['seed']}: {r['excluded']}")
    lines.append("")

    tests = primaries(seeds)
    lines += ["### Primary tests (Holm over the six)", ""]
    lines += ["| rule | test | estimate | 95% interval | p | Holm p | rejected |", "| --- | --- | --- | --- | ---: | ---: | --- |"]  # fmt: skip
    for t in tests:
        fit = t["fit"]
        if t["test"] == "width":
            est = f"w = {fit['effect']:+.3f} (elasticity {fit['effect'] / np.log(2):+.2f})" if np.isfinite(fit["effect"]) else "—"  # fmt: skip
            ci = f"[{fit['ci'][0]:+.3f}, {fit['ci'][1]:+.3f}]" if np.isfinite(fit["effect"]) else "—"  # fmt: skip
            name = "width 128 vs 64 (log rank) = 0"
        elif fit is None:
            est, ci, name = "—", "—", "(0, 1)" if t["test"] == "paper" else "slope = 0"
        elif t["test"] == "paper":
            lo, hi = fit["intercept_ci"]
            est, ci = f"a = {float(fit['intercept']):.2f}, F = {float(fit['f_paper']):.1f}", f"a: [{float(lo):.2f}, {float(hi):.2f}]"  # fmt: skip
            name = "(intercept, slope) = (0, 1)"
        else:
            lo, hi = fit["slope_ci"]
            est, ci, name = f"b = {float(fit['slope']):+.3f}", f"[{float(lo):+.3f}, {float(hi):+.3f}]", "slope = 0"  # fmt: skip
        rejected = "**yes**" if t["rejected"] else ("no" if np.isfinite(t["holm"]) else "—")
        lines.append(f"| {t['rule']} | {name} | {est} | {ci} | {_p(t['p'])} | {_p(t['holm'])} | {rejected} |")  # fmt: skip
    lines.append("")
    lines += ["Decision (the pre-registered rule)" + ("" if done else ", not read until the design is complete") + ":", ""]  # fmt: skip
    for rule in RULES:
        paper, flat, width = (t for t in tests if t["rule"] == rule)
        if done:
            text = decision(paper["rejected"], flat["rejected"])
            text += "; the width effect is " + (
                "**detected**" if width["rejected"] else "not detected"
            )
        else:
            text = "interim"
        lines.append(f"- {rule}: {text}")
    lines.append("")

    lines += ["### The lines (main arm: 64 wide, β = 0.98; x = 2·d_a + 1)", ""]
    lines += [
        "| rule | rank | tasks | intercept [95%] | slope [95%] | slope, task bootstrap 95% | slope, each task left out | residual SD | p (0, 1) | p slope 0 |",  # fmt: skip
        "| --- | --- | ---: | --- | --- | --- | --- | ---: | ---: | ---: |",
    ]
    for rule in RULES:
        arm = main_arm(seeds, rule)
        for column in ("actor", "critic"):
            x, y, tasks = task_means(arm.dropna(subset=[column]), column)
            if len(tasks) < 3:
                lines.append(f"| {rule} | {column} | {len(tasks)} | — | — | — | — | — | — | — |")
                continue
            fit = line_tests(x, y)
            lo, hi, dropped = bootstrap_slope(arm.dropna(subset=[column]), column)
            loo = leave_one_out(arm.dropna(subset=[column]), column) if len(tasks) >= 4 else {}
            loo_text = f"{min(loo.values()):+.3f} … {max(loo.values()):+.3f}" if loo else "—"
            a_lo, a_hi = fit["intercept_ci"]
            b_lo, b_hi = fit["slope_ci"]
            lines.append(
                f"| {rule} | {column}{'' if column == 'actor' else ' (secondary)'} | {len(tasks)} "
                f"| {float(fit['intercept']):.2f} [{float(a_lo):.2f}, {float(a_hi):.2f}] "
                f"| {float(fit['slope']):+.3f} [{float(b_lo):+.3f}, {float(b_hi):+.3f}] "
                f"| [{lo:+.3f}, {hi:+.3f}]{f' ({dropped} draws dropped)' if dropped else ''} "
                f"| {loo_text} | {float(fit['s']):.2f} | {_p(float(fit['p_paper']))} | {_p(float(fit['p_flat']))} |"  # fmt: skip
            )
    lines.append("")

    lines += ["### Kept ranks per cut (main arm): min–max over seeds", ""]
    lines += ["| task | 2·d_a + 1 | rule | layer | seeds | cut 1 | cut 2 | cut 3 | cut 4 |", "| --- | ---: | --- | --- | ---: | --- | --- | --- | --- |"]  # fmt: skip
    for task in TASKS:
        for rule in RULES:
            arm = main_arm(seeds, rule)
            arm = arm[arm["task"] == task]
            if arm.empty:
                continue
            for layer in (ACTOR, *CRITICS):
                cuts = [_range([c[k] for c in arm[f"{layer}_cuts"] if len(c) > k]) for k in range(CUTS)]  # fmt: skip
                lines.append(f"| {task} | {intrinsic(task)} | {rule} | {layer} | {len(arm)} | " + " | ".join(cuts) + " |")  # fmt: skip
    lines.append("")

    lines += [f"### Returns beside the ranks (main arm): learned = u ≥ {LEARNED_FRACTION}", ""]
    lines += [
        "| task | rule | random-action return | reference | return per seed | u per seed | learned | final actor rank per seed |",  # fmt: skip
        "| --- | --- | ---: | ---: | --- | --- | ---: | --- |",
    ]
    for task in TASKS:
        for rule in RULES:
            arm = main_arm(seeds, rule)
            arm = arm[arm["task"] == task].sort_values("seed")
            if arm.empty:
                continue
            lines.append(
                f"| {task} | {rule} | {arm['random_return'].mean():,.1f} | {REFERENCE_RETURN[task]:,g} "
                f"| {', '.join(f'{v:,.0f}' for v in arm['return'])} "
                f"| {', '.join(f'{v:.2f}' for v in arm['normalised'])} "
                f"| {int(arm['learned'].sum())}/{len(arm)} | {', '.join(f'{v:g}' for v in arm['actor'])} |"
            )
    lines.append("")

    lines += ["### Sensitivity: the lines on the seeds that learned (tasks with at least 2 such seeds)", ""]  # fmt: skip
    lines += ["| rule | tasks | left out | slope [95%] | p (0, 1) | p slope 0 |", "| --- | ---: | --- | --- | ---: | ---: |"]  # fmt: skip
    for rule in RULES:
        arm = main_arm(seeds, rule)
        learned = arm[arm["learned"]]
        counts = learned.groupby("task").size()
        use = learned[learned["task"].isin(counts[counts >= 2].index)]
        x, y, tasks = task_means(use, "actor")
        out = ", ".join(t for t in TASKS if t in set(arm["task"]) and t not in tasks) or "none"
        if len(tasks) < 3 or np.ptp(x) == 0:
            lines.append(f"| {rule} | {len(tasks)} | {out} | — | — | — |")
            continue
        fit = line_tests(x, y)
        b_lo, b_hi = fit["slope_ci"]
        lines.append(f"| {rule} | {len(tasks)} | {out} | {float(fit['slope']):+.3f} [{float(b_lo):+.3f}, {float(b_hi):+.3f}] | {_p(float(fit['p_paper']))} | {_p(float(fit['p_flat']))} |")  # fmt: skip
    lines.append("")

    lines += ["### The width and β arm (final actor rank; log scale effects)", ""]
    lines += ["| rule | task | width | β | seeds | cut 1 | cut 2 | cut 3 | cut 4 |", "| --- | --- | ---: | ---: | ---: | --- | --- | --- | --- |"]  # fmt: skip
    for rule in RULES:
        arm = width_arm(seeds, rule)
        for task in ARM_TASKS:
            for width in ARM_WIDTHS:
                for beta in ARM_BETAS:
                    cell = arm[(arm["task"] == task) & (arm["width"] == width) & np.isclose(arm["beta"], beta)]  # fmt: skip
                    if cell.empty:
                        continue
                    cuts = [_range([c[k] for c in cell[f"{ACTOR}_cuts"] if len(c) > k]) for k in range(CUTS)]  # fmt: skip
                    lines.append(f"| {rule} | {task} | {width} | {beta:g} | {len(cell)} | " + " | ".join(cuts) + " |")  # fmt: skip
    lines.append("")
    lines += ["| rule | effect | estimate (log) | 95% | ratio | p | role |", "| --- | --- | ---: | --- | ---: | ---: | --- |"]  # fmt: skip
    for rule in RULES:
        arm = width_arm(seeds, rule)
        for factor, name, role in (("width", "width 128 vs 64", "primary"), ("beta", "β 0.9 vs 0.98", "secondary")):  # fmt: skip
            e = width_effect(arm, factor=factor)
            if not np.isfinite(e["effect"]):
                lines.append(f"| {rule} | {name} | — | — | — | — | {role} |")
                continue
            lines.append(f"| {rule} | {name} | {e['effect']:+.3f} | [{e['ci'][0]:+.3f}, {e['ci'][1]:+.3f}] | {np.exp(e['effect']):.2f} | {_p(e['p'])} | {role} |")  # fmt: skip
        main = arm[(arm["width"] == MAIN_WIDTH) & np.isclose(arm["beta"], MAIN_BETA)]
        by_task = [main.loc[main["task"] == t, "actor"] for t in ARM_TASKS]
        if all(len(v) >= 2 for v in by_task):
            ci = stats.welch_difference_ci(np.log(by_task[1]), np.log(by_task[0]))
            paper = np.log(intrinsic(ARM_TASKS[1]) / intrinsic(ARM_TASKS[0]))
            lines.append(
                f"| {rule} | {ARM_TASKS[1]} vs {ARM_TASKS[0]} (64, β 0.98; the paper: {paper:+.3f}) "
                f"| {ci.point:+.3f} | [{ci.low:+.3f}, {ci.high:+.3f}] | {np.exp(ci.point):.2f} | — | secondary |"
            )
    lines.append("")
    return lines


# ----------------------------------------------------------------------------- figures
def figure(seeds: pd.DataFrame, stem: Path) -> list[Path]:
    """Kept actor rank per seed per cut against 2·d_a + 1 with the identity line and the fitted
    line of the final cut, one panel per rule (top), and the mean rank over seeds against the cut
    index per task (bottom); main arm."""
    import matplotlib

    from adarl.report import figures

    with matplotlib.rc_context(figures.STYLE):
        fig = figures.Figure(figsize=(figures.FULL_WIDTH, 2 * figures.PANEL_HEIGHT + 0.6), layout="constrained")  # fmt: skip
        axes = fig.subplots(2, len(RULES), squeeze=False)
        colours = matplotlib.colormaps["viridis"](np.linspace(0, 0.9, CUTS))
        task_colours = matplotlib.colormaps["tab10"]
        for j, rule in enumerate(RULES):
            arm = main_arm(seeds, rule)
            top, bottom = axes[0][j], axes[1][j]
            top.plot([0, 37], [0, 37], label="2·d_a + 1 (the paper)", **figures.INTRINSIC_STYLE)
            for k in range(CUTS):
                xs, ys = [], []
                for _, r in arm.iterrows():
                    if len(r[f"{ACTOR}_cuts"]) > k:
                        xs.append(r["x"] + 0.3 * (k - (CUTS - 1) / 2))
                        ys.append(r[f"{ACTOR}_cuts"][k])
                top.scatter(xs, ys, s=8, color=colours[k], alpha=0.8, label=f"after cut {k + 1}")
            x, y, tasks = task_means(arm.dropna(subset=["actor"]), "actor")
            if len(tasks) >= 3 and np.ptp(x) > 0:
                fit = line_tests(x, y)
                grid = np.array([0.0, 37.0])
                top.plot(grid, float(fit["intercept"]) + float(fit["slope"]) * grid, color="grey", linestyle="--", linewidth=0.9, label="fit, after cut 4")  # fmt: skip
            top.set(title=f"{rule} (β = {MAIN_BETA})", xlabel="2·d_a + 1", ylabel="kept actor rank", xlim=(0, 37), ylim=(0, MAIN_WIDTH + 2))  # fmt: skip
            for i, task in enumerate(TASKS):
                rows = arm[arm["task"] == task]
                if rows.empty:
                    continue
                curves = np.array([[MAIN_WIDTH, *c] for c in rows[f"{ACTOR}_cuts"] if len(c) == CUTS], float)  # fmt: skip
                if curves.size:
                    bottom.plot(range(CUTS + 1), curves.mean(axis=0), marker="o", markersize=2.5, color=task_colours(i % 10), label=f"{task} ({intrinsic(task)})")  # fmt: skip
            bottom.set(xlabel="cut (0: the full width)", ylabel="kept actor rank (mean over seeds)", xticks=range(CUTS + 1), ylim=(0, MAIN_WIDTH + 2))  # fmt: skip
        axes[0][0].legend(loc="upper right")
        axes[1][-1].legend(loc="upper right", ncols=2)
        return figures.save_figure(fig, stem)


def width_figure(seeds: pd.DataFrame, stem: Path) -> list[Path]:
    """The arm: mean kept actor rank over seeds against the cut index, per task, width and β, one
    panel per rule."""
    import matplotlib

    from adarl.report import figures

    with matplotlib.rc_context(figures.STYLE):
        fig = figures.Figure(figsize=(figures.FULL_WIDTH, figures.PANEL_HEIGHT + 0.5), layout="constrained")  # fmt: skip
        axes = fig.subplots(1, len(RULES), squeeze=False)[0]
        for ax, rule in zip(axes, RULES, strict=True):
            arm = width_arm(seeds, rule)
            for i, task in enumerate(ARM_TASKS):
                for width in ARM_WIDTHS:
                    for beta in ARM_BETAS:
                        cell = arm[(arm["task"] == task) & (arm["width"] == width) & np.isclose(arm["beta"], beta)]  # fmt: skip
                        curves = np.array([[width, *c] for c in cell[f"{ACTOR}_cuts"] if len(c) == CUTS], float)  # fmt: skip
                        if not curves.size:
                            continue
                        ax.plot(range(CUTS + 1), curves.mean(axis=0), marker="os"[i], markersize=3,
                                color="C0" if width == ARM_WIDTHS[0] else "C3",
                                linestyle="-" if beta == ARM_BETAS[0] else "--",
                                label=f"{task}, {width} wide, β {beta:g}")  # fmt: skip
                ax.axhline(intrinsic(task), color="grey", linewidth=0.6, linestyle=":")
                ax.annotate(f"2·d_a + 1 of {task}", (CUTS, intrinsic(task)), fontsize=5, ha="right", va="bottom", color="grey")  # fmt: skip
            ax.set(title=rule, xlabel="cut (0: the full width)", ylabel="kept actor rank (mean over seeds)", xticks=range(CUTS + 1))  # fmt: skip
        axes[-1].legend(loc="upper right", fontsize=5)
        return figures.save_figure(fig, stem)


# ----------------------------------------------------------------------------- power
DESIGN_X = np.array([intrinsic(t) for t in TASKS], float)


def simulated_means(line, u, e) -> np.ndarray:
    """Task means of simulated final ranks, rank_ij = clip(round(line_i + u_i + e_ij), 1, 64):
    `line` (K,) the true line at each task's x, `u` (sims, K) each task's own departure from it
    (N(0, τ²)), `e` (sims, K, seeds) the seeds' (N(0, σ²))."""
    ranks = np.clip(np.round(np.asarray(line)[None, :, None] + u[..., None] + e), 1, MAIN_WIDTH)
    return ranks.mean(axis=-1)


def detectable(power_of, high: float, target: float = 0.8, steps: int = 16) -> tuple[float, float]:
    """The smallest effect in [0, high] whose power (`power_of(effect)`, increasing in it) reaches
    `target`, by bisection on common random numbers, and the half-width of its Monte-Carlo 95%
    band, 1.96·SE(power) / (the power's slope there), SE(power) = √(target(1 − target)/sims);
    NaN when even `high` falls short."""
    sims = power_of.sims
    if power_of(high) < target:
        return float("nan"), float("nan")
    low = 0.0
    for _ in range(steps):
        mid = (low + high) / 2
        low, high = (mid, high) if power_of(mid) < target else (low, mid)
    step = 0.1 * high
    slope = (power_of(high + step) - power_of(max(high - step, 0.0))) / (high + step - max(high - step, 0.0))  # fmt: skip
    band = 1.96 * np.sqrt(target * (1 - target) / sims) / slope if slope > 0 else float("nan")
    return float(high), float(band)


class _LinePower:
    """The power of one of `line_tests`' tests (`p_flat` or `p_paper`) at `level` when the ranks
    follow `line_of(effect)`, on fixed noise draws (common random numbers)."""

    def __init__(self, line_of, test, level, u, e):
        self.line_of, self.test, self.level, self.u, self.e = line_of, test, level, u, e
        self.sims = u.shape[0]

    def __call__(self, effect: float) -> float:
        means = simulated_means(self.line_of(effect), self.u, self.e)
        return float(np.mean(line_tests(DESIGN_X, means)[f"p_{self.test}"] < self.level))


def power_table(sims: int = 20_000, seed: int = 1, sigma: float = 2.0) -> list[str]:
    """The design's power, by simulation of `line_tests` on ranks from `simulated_means` (and of
    `width_effect`'s test on log ranks), at α = 0.05 and at α/6 (Bonferroni over the six
    primaries, which Holm's procedure never does worse than); each power's Monte-Carlo 95% band
    is ± 1.96·√(p(1 − p)/sims), each detectable effect's from it (`detectable`)."""
    rng = np.random.default_rng(seed)
    bonferroni = ALPHA / 6
    band = 1.96 * np.sqrt(0.25 / sims)
    taus = (1.0, 2.0, 4.0, 8.0)
    k, n = DESIGN_X.size, len(SEEDS)
    noise = {tau: (rng.normal(0, tau, (sims, k)), rng.normal(0, sigma, (sims, k, n))) for tau in taus}  # fmt: skip
    x_mean = DESIGN_X.mean()
    lines = [f"{sims:,} simulated data sets per τ (the same draws for every row); a power's Monte-Carlo 95% band is at most ±{band:.3f}; seed SD σ = {sigma:g}, {n} seeds per task, x = {', '.join(f'{v:g}' for v in DESIGN_X)}.", ""]  # fmt: skip
    lines += ["| truth | test | " + " | ".join(f"τ = {t:g}" for t in taus) + " |", "| --- | --- |" + " ---: |" * len(taus)]  # fmt: skip
    rows = [
        (
            "flat: rank 24 on every task",
            lambda _: np.full(k, 24.0),
            "paper",
            bonferroni,
            "reject (0, 1) at α/6",
        ),
        (
            "flat: rank 24 on every task",
            lambda _: np.full(k, 24.0),
            "flat",
            ALPHA,
            "reject slope 0 at α (type I error)",
        ),
        (
            "the paper: rank = 2·d_a + 1",
            lambda _: DESIGN_X,
            "flat",
            bonferroni,
            "reject slope 0 at α/6",
        ),
        (
            "the paper: rank = 2·d_a + 1",
            lambda _: DESIGN_X,
            "paper",
            ALPHA,
            "reject (0, 1) at α (type I error)",
        ),
    ]
    for name, line_of, test, level, what in rows:
        cells = [f"{_LinePower(line_of, test, level, *noise[tau])(0.0):.3f}" for tau in taus]
        lines.append(f"| {name} | {what} | " + " | ".join(cells) + " |")
    lines += ["", "Smallest effects detected with 80% power at α/6 (± their Monte-Carlo 95% band):", ""]  # fmt: skip
    lines += ["| truth | test | " + " | ".join(f"τ = {t:g}" for t in taus) + " |", "| --- | --- |" + " ---: |" * len(taus)]  # fmt: skip
    effects = [
        ("slope b through (x̄, 24): b", lambda b: 24.0 + b * (DESIGN_X - x_mean), "flat", 3.0),
        ("rank = (1 − c)·(2·d_a + 1): c", lambda c: (1 - c) * DESIGN_X, "paper", 1.0),
        ("rank = (1 + c)·(2·d_a + 1): c", lambda c: (1 + c) * DESIGN_X, "paper", 1.0),
        ("rank = 2·d_a + 1 + d: d", lambda d: DESIGN_X + d, "paper", 30.0),
    ]
    for name, line_of, test, high in effects:
        cells = []
        for tau in taus:
            value, half = detectable(_LinePower(line_of, test, bonferroni, *noise[tau]), high)
            cells.append("beyond the range" if not np.isfinite(value) else f"{value:.3f} ± {half:.3f}")  # fmt: skip
        lines.append(f"| {name} | {'reject (0, 1)' if test == 'paper' else 'reject slope 0'} | " + " | ".join(cells) + " |")  # fmt: skip
    lines.append("")
    lines += ["Width arm (per rule): log rank = cell + w·[128 wide] + N(0, σ_log²), 4 cells (task × β), seeds 5 + 3 at 64 wide (β 0.98, 0.9) and 3 + 3 at 128:", ""]  # fmt: skip
    sig_logs = (0.05, 0.1, 0.2)
    lines += ["| w (ratio) | test | " + " | ".join(f"σ_log = {s:g}" for s in sig_logs) + " |", "| --- | --- |" + " ---: |" * len(sig_logs)]  # fmt: skip
    cells_n = [((t, b), (5 if b == MAIN_BETA else 3), 3) for t in ARM_TASKS for b in ARM_BETAS]
    for w in (0.0, np.log(1.1), np.log(1.25), np.log(2.0)):
        level = bonferroni if w else ALPHA
        row = [f"{_width_power(rng, sims, w, s, cells_n, level):.3f}" for s in sig_logs]
        what = "reject w = 0 at α/6" if w else "reject w = 0 at α (type I error)"
        lines.append(f"| {w:+.3f} ({np.exp(w):.2f}×) | {what} | " + " | ".join(row) + " |")
    return lines


def _width_power(rng, sims, w, sigma_log, cells_n, level) -> float:
    """The share of `sims` simulated arms in which `effect_test` (as `width_effect` runs it)
    rejects w = 0 at `level`."""
    rows = []
    for (task, beta), n64, n128 in cells_n:
        for width, n in ((64, n64), (128, n128)):
            rows += [{"task": task, "beta": beta, "width": width, "seed": i} for i in range(n)]
    frame = pd.DataFrame(rows)
    base = 24.0 * np.where(frame["task"] == ARM_TASKS[0], 1.0, 1.2) * np.where(np.isclose(frame["beta"], 0.9), 0.7, 1.0)  # fmt: skip
    shift = np.where(frame["width"] == 128, w, 0.0)
    y = np.log(base) + shift + rng.normal(0, sigma_log, (sims, len(frame)))
    return float(np.mean(effect_test(effect_design(frame), y)["p"] < level))


# ----------------------------------------------------------------------------- rows
def export(sweep: Path, rows: Path | None = None) -> tuple[list[Path], list[Path]]:
    """Copy every finished run under `sweep` (config.yaml and DONE as they are, the CSVs gzipped,
    never checkpoints or spectra) to the same place under `rows` (default `ROWS`); runs still
    training are left. Returns the files written and the runs left."""
    rows = ROWS if rows is None else rows
    written, left = [], []
    for run in find_runs([sweep]):
        if run.done_step is None:
            left.append(run.path)
            continue
        target = rows / run.path.relative_to(sweep)
        target.mkdir(parents=True, exist_ok=True)
        for name in RUN_FILES:
            if (run.path / name).is_file():
                shutil.copyfile(run.path / name, target / name)
                written.append(target / name)
        for name in FILES:
            if (run.path / name).is_file():
                with (run.path / name).open("rb") as f, gzip.GzipFile(target / f"{name}.gz", "wb", mtime=0) as g:  # fmt: skip
                    shutil.copyfileobj(f, g)
                written.append(target / f"{name}.gz")
    return written, left


def main(argv: list[str]) -> int:
    try:
        return _main(argv)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def _main(argv: list[str]) -> int:
    usage = (
        "usage: claim2_across_tasks.py SWEEP_DIR [--out DIR] | export SWEEP_DIR | power [--sims N]"
    )
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__)
        return 0
    if argv[:1] == ["power"]:
        sims = 20_000
        if argv[1:2] == ["--sims"] and len(argv) == 3 and argv[2].isdigit() and int(argv[2]) > 0:
            sims = int(argv[2])
        elif len(argv) != 1:
            raise UsageError(f"power takes --sims N (a whole number > 0), got {' '.join(argv[1:])!r}")  # fmt: skip
        print("\n".join(power_table(sims)))
        return 0
    if argv[:1] == ["export"]:
        if len(argv) != 2 or not Path(argv[1]).is_dir():
            raise UsageError(f"export takes one sweep folder, got {' '.join(argv[1:]) or 'none'}")
        written, left = export(Path(argv[1]))
        print(f"wrote {len(written)} files under {ROWS}")
        for run in left:
            print(f"left {run}: still training (no DONE)")
        return 0
    if not argv or argv[0].startswith("-"):
        print(usage, file=sys.stderr)
        return 2
    sweep, out = argv[0], None
    if argv[1:2] == ["--out"] and len(argv) == 3:
        out = Path(argv[2])
    elif len(argv) != 1:
        print(usage, file=sys.stderr)
        return 2
    seeds, running = load([sweep])
    lines = report(seeds, running)
    print("\n".join(lines))
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / "report.md", "\n".join(lines) + "\n")
        for path in figure(seeds, out / "ranks") + width_figure(seeds, out / "width-beta"):
            print(f"wrote {path}")
        print(f"wrote {out / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
