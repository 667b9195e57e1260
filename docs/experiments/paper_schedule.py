"""Tables of a milestone of docs/experiments/paper-schedule-<task>.md from the sweep's run folders:
the ranks Eq. 5 proposed at each cut logged so far (applied by AdaRL; logged and not applied by the
control, whose networks differ after the first cut), that the control shares AdaRL's prefix
bit for bit, and each seed's score at the milestone (the mean of its last 5 nominal evaluations
at steps up to it) and mean episode length in the three arms, with the paired AdaRL − control test
(t interval and p, sign-flip p, each seed's difference), the Welch AdaRL − SAC test (t interval
and p, permutation p) and their power, and the same tests on the evaluation at the milestone
alone. An arm that has not reached the milestone is named and left out. With a third argument,
also a figure of each seed's nominal evaluations in the three arms up to the milestone, saved as
FIGURE.png and FIGURE.pdf.

    python docs/experiments/paper_schedule.py results/paper-schedule-hopper 2000000 \
        docs/experiments/paper-schedule-hopper-2m
    python docs/experiments/paper_schedule.py results/paper-schedule-walker2d 1000000

The score's two pre-registered primary tests (AdaRL − control paired t, AdaRL − SAC Welch) get
Holm's adjustment over the two and the decision (detected when the adjusted p < 0.05).

`export SWEEP ROWS` copies each unit's raw rows (eval.csv, episodes.csv, train.csv,
truncations.csv and, once evaluated, the `paper` suite's episode table and summary; never
checkpoints) gzipped into ROWS/<task>/<unit>/seeds-*/, the run folders' own layout, so that
everything above also runs on ROWS, from the repository alone. `robustness DIR` (a sweep or
exported rows) is the pre-registered robustness test at 3M (paper-schedule-walker2d.md): per
seed the worst-case and the average return over the `paper` suite's grid, recomputed from the
suite's episode table, and AdaRL − SAC on each, Welch, Holm over the two, with the inverted
permutation interval and the detectable difference over the SD's interval beside each.

    python docs/experiments/paper_schedule.py export results/paper-schedule-walker2d \
        docs/experiments/paper-schedule-walker2d/rows
    python docs/experiments/paper_schedule.py robustness docs/experiments/paper-schedule-walker2d/rows
"""

from __future__ import annotations

import collections
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.stats
from matplotlib.figure import Figure
from mechanism import LAYERS, TARGET, paired_line, prefix_rows, rows
from table1_ant_humanoid import compare, comparison_row, folder, gzip_copy

from adarl import stats
from adarl.report import figures
from adarl.report.tables import p_text
from adarl.results.collect import last_evaluations
from adarl.runs.logs import TEXT_COLUMNS

ARMS = {"AdaRL": "adarl_rank_rule-cumulative", "control": "adarl-control-eq5", "SAC": "sac"}
LAST_K = 5  # the report's default score: the mean of the last 5 evaluations
SUITE = "paper"  # the robustness grid: torso × foot length, 10 × 10 points
EXPORTED = (
    "eval.csv",
    "episodes.csv",
    "train.csv",
    "truncations.csv",
    f"evaluations/suite-{SUITE}.csv",
    f"suites/{SUITE}.csv",
)


def export(sweep: Path, rows_dir: Path) -> list[Path]:
    """Copy the raw rows (`EXPORTED`) of every unit of `sweep` (task/unit/seeds-*/) to
    `rows_dir` in the same layout, each file gzipped (`NAME.gz`, no timestamp inside)."""
    written = []
    for unit in sorted(sweep.glob("*/*/seeds-*")):
        for name in EXPORTED:
            source = unit / name
            if not source.is_file():
                continue
            target = rows_dir / unit.relative_to(sweep) / f"{name}.gz"
            gzip_copy(source, target)
            written.append(target)
    return written


def table(path: Path) -> pd.DataFrame:
    """A run CSV (`path`, or `path.gz` as exported) as a DataFrame, each column but the text
    ones as numbers."""
    frame = pd.DataFrame(rows(path))
    for column in frame.columns.difference(sorted(TEXT_COLUMNS)):
        frame[column] = pd.to_numeric(frame[column])
    return frame


def scores_at(
    run_dir: Path, milestone: int, k: int = LAST_K
) -> tuple[dict[int, float], dict[int, float]] | int:
    """Each seed's score (the mean of its last `k`) from the nominal evaluations at steps ≤
    `milestone`, and the mean episode length of those evaluations (what the policies did: 1,000
    is the time limit); the newest evaluated step instead when the run has not reached the
    milestone."""
    log = table(run_dir / "eval.csv")
    if log.empty:
        return 0
    log = log[log["dynamics"] == "nominal"]
    newest = int(log["step"].max()) if len(log) else 0
    if newest < milestone:
        return newest
    log = log[log["step"] <= milestone]
    score = last_evaluations(log, k)
    length = last_evaluations(log.assign(**{"return": log["length"]}), k)
    return (
        {int(s): float(v) for s, v in zip(score["seed"], score["score"])},
        {int(s): float(v) for s, v in zip(length["seed"], length["score"])},
    )


def proposals(run_dir: Path) -> dict[int, dict[int, dict[str, int]]]:
    """cut step → seed → layer → the rank Eq. 5 proposed there."""
    out = collections.defaultdict(lambda: collections.defaultdict(dict))
    for r in rows(run_dir / "truncations.csv"):
        out[int(r["step"])][int(r["seed"])][r["layer"]] = int(r["proposed_rank"])
    return out


def paired_t_line(x: np.ndarray, y: np.ndarray) -> str:
    """The paired t-test's statistic and p, and each seed's difference (the pre-registered
    primary test of AdaRL − control)."""
    test = scipy.stats.ttest_rel(x, y)
    differences = ", ".join(f"{d:+,.0f}" for d in x - y)
    return (
        f"- paired t = {test.statistic:.2f} ({len(x) - 1} df), p = {test.pvalue:.2g}; "
        f"differences by seed: {differences}"
    )


def welch_line(what: str, x: np.ndarray, y: np.ndarray) -> str:
    ci = stats.welch_difference_ci(x, y)
    sd = stats.pooled_sd(x, y)
    test = scipy.stats.ttest_ind(x, y, equal_var=False)
    return (
        f"- {what}: AdaRL − SAC: AdaRL {x.mean():,.0f}, SAC {y.mean():,.0f}; difference {ci.point:+,.0f}, "
        f"95% Welch t interval [{ci.low:+,.0f}, {ci.high:+,.0f}]; Welch t = "
        f"{test.statistic:.2f} ({test.df:.1f} df), p = {test.pvalue:.2g}; exact permutation p = "
        f"{stats.permutation_p_value(x, y):.3g} ({len(x)} vs {len(y)} seeds); pooled SD "
        f"{sd:,.0f}; smallest difference detectable at 80% power "
        f"{stats.minimum_detectable_difference(sd, len(x), len(y)):,.0f}; seeds per arm a "
        f"{TARGET:.0f}-point difference would need: {stats.seeds_per_arm(TARGET, sd):,.0f}"
    )


def seed_curves(units: dict[str, list[Path]], milestone: int, cuts: list[int]) -> Figure:
    """One panel per seed: the mean return of each nominal evaluation up to `milestone` in each
    arm, with AdaRL's cuts as red dashed lines."""
    curves = {}
    for arm, dirs in units.items():
        for run_dir in dirs:
            log = table(run_dir / "eval.csv")
            if log.empty:
                continue
            log = log[(log["dynamics"] == "nominal") & (log["step"] <= milestone)]
            for seed, seed_log in log.groupby("seed"):
                curves.setdefault(int(seed), {})[arm] = seed_log.groupby("step")["return"].mean()
    colours = dict(zip(ARMS, ("tab:blue", "tab:orange", "tab:green")))
    millions = figures.matplotlib.ticker.FuncFormatter(lambda x, _: f"{x / 1e6:g}M" if x else "0")
    with figures.matplotlib.rc_context(figures.STYLE):
        fig = Figure(figsize=(figures.FULL_WIDTH, 2.0), layout="constrained")
        axes = fig.subplots(1, len(curves), sharey=True, squeeze=False)[0]
        for ax, seed in zip(axes, sorted(curves)):
            for arm in ("control", "SAC", "AdaRL"):  # AdaRL last: the shared prefix in its colour
                if arm in curves[seed]:
                    curve = curves[seed][arm]
                    ax.plot(curve.index, curve.values, label=arm, color=colours[arm], lw=0.9)
            for cut in cuts:
                ax.axvline(cut, **figures.TRUNCATION_STYLE)
            ax.set_title(f"seed {seed}")
            ax.xaxis.set_major_formatter(millions)
        axes[0].set_ylabel("return (nominal)")
        fig.supxlabel("environment steps", fontsize=8)
        shown = dict(zip(*reversed(axes[0].get_legend_handles_labels())))
        arms = [arm for arm in ARMS if arm in shown]
        fig.legend([shown[arm] for arm in arms], arms, loc="outside upper center", ncols=3)
    return fig


def comparisons(
    what: str, score: dict[str, dict[int, float]], length: dict[str, dict[int, float]]
) -> None:
    """Each arm's mean ± SD over seeds (and mean episode length), then the paired AdaRL − control
    and the Welch AdaRL − SAC tests of one score."""
    arms = [
        f"{arm} {np.mean(list(score[arm].values())):,.0f} ± "
        f"{np.std(list(score[arm].values()), ddof=1):,.0f} "
        f"({np.mean(list(length[arm].values())):,.0f} steps)"
        for arm in ARMS
        if len(score[arm]) > 1
    ]
    print(f"- {what}, mean ± SD over seeds (mean episode length): " + ", ".join(arms))
    if score["AdaRL"] and score["control"]:
        print(paired_line(what, score["AdaRL"], score["control"]))
        print(paired_t_line(*against(score, "control")))
    if score["AdaRL"] and score["SAC"]:
        print(welch_line(what, *against(score, "SAC")))


def against(score: dict[str, dict[int, float]], arm: str) -> tuple[np.ndarray, np.ndarray]:
    """AdaRL's and `arm`'s scores on the seeds both have, in seed order."""
    both = sorted(set(score["AdaRL"]) & set(score[arm]))
    return np.array([score["AdaRL"][s] for s in both]), np.array([score[arm][s] for s in both])


def primary_line(score: dict[str, dict[int, float]]) -> str:
    """The decision of the two pre-registered primary tests of the score: AdaRL − control
    (paired t) and AdaRL − SAC (Welch), two-sided, Holm over the two; detected where the
    adjusted p < 0.05."""
    p = [
        float(scipy.stats.ttest_rel(*against(score, "control")).pvalue),
        float(scipy.stats.ttest_ind(*against(score, "SAC"), equal_var=False).pvalue),
    ]
    if not np.all(np.isfinite(p)):  # a t statistic of 0/0: every difference the same
        return (
            f"- Primary tests: no Holm adjustment, a p-value is undefined ({p[0]:.3g}, {p[1]:.3g})"
        )
    cells = [
        f"{what} p = {raw:.3g}, Holm {adjusted:.3g}: "
        + ("**detected**" if adjusted < 0.05 else "not detected")
        for what, raw, adjusted in zip(
            ("AdaRL − control (paired t)", "AdaRL − SAC (Welch)"), p, stats.holm(p), strict=True
        )
    ]
    return "- Primary tests, Holm over the two: " + "; ".join(cells)


def main(sweep: Path, milestone: int, figure: Path | None = None) -> None:
    units = {arm: sorted(sweep.glob(f"*/{name}/seeds-*")) for arm, name in ARMS.items()}
    score: dict[str, dict[int, float]] = {arm: {} for arm in ARMS}
    length: dict[str, dict[int, float]] = {arm: {} for arm in ARMS}
    # the evaluation at the milestone alone, and its episode lengths
    final: dict[str, dict[int, float]] = {arm: {} for arm in ARMS}
    final_length: dict[str, dict[int, float]] = {arm: {} for arm in ARMS}
    print(f"## Milestone {milestone:,}\n")
    for arm, dirs in units.items():
        for run_dir in dirs:
            got = scores_at(run_dir, milestone)
            if isinstance(got, int):
                print(f"- {arm} ({run_dir.name}) has not reached it: newest evaluation at {got:,}")
            else:
                score[arm] |= got[0]
                length[arm] |= got[1]
                final_score, lengths = scores_at(run_dir, milestone, k=1)
                final[arm] |= final_score
                final_length[arm] |= lengths

    for method_dir in units["AdaRL"]:
        control_dir = method_dir.parent.parent / ARMS["control"] / method_dir.name
        applied = proposals(method_dir)
        if not applied:
            continue
        fork = min(applied)
        same = all(
            prefix_rows(method_dir / name, fork) == prefix_rows(control_dir / name, fork)
            for name in ("episodes.csv", "eval.csv", "train.csv")
        )
        print(f"\nThe control shares AdaRL's logs up to the fork at {fork:,}: {same}")
        shadow = proposals(control_dir) if control_dir.exists() else {}
        for cut in sorted(applied):
            print(f"\n### Ranks Eq. 5 proposed at step {cut:,} (AdaRL applied them; the control")
            print("kept 64 and logged its own)\n")
            print("| seed | AdaRL actor | Q1 | Q2 | control actor | Q1 | Q2 |")
            print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
            for seed, layers in sorted(applied[cut].items()):
                logged = shadow.get(cut, {}).get(seed, {})
                print(
                    f"| {seed} | "
                    + " | ".join(str(layers[name]) for name in LAYERS)
                    + " | "
                    + " | ".join(str(logged.get(name, "—")) for name in LAYERS)
                    + " |"
                )

    present = [arm for arm in ARMS if score[arm]]
    seeds = sorted(set.intersection(*(set(score[arm]) for arm in present))) if present else []
    print(f"\n### Score at {milestone:,} (mean of the last {LAST_K} nominal evaluations)\n")
    print("and the mean episode length of those evaluations (of 1,000)\n")
    header = present + [f"length: {arm}" for arm in present]
    print("| seed | " + " | ".join(header) + " |\n| ---: |" + " ---: |" * len(header))
    for s in seeds:
        cells = [f"{score[arm][s]:,.0f}" for arm in present]
        cells += [f"{length[arm][s]:,.0f}" for arm in present]
        print(f"| {s} | " + " | ".join(cells) + " |")
    print()
    comparisons(f"score at {milestone:,}", score, length)
    if all(len(score[arm]) > 1 for arm in ARMS):
        print(primary_line(score))
    print(f"\nThe evaluation at step {milestone:,} alone:\n")
    comparisons(f"evaluation at {milestone:,}", final, final_length)
    if figure is not None:
        cuts = sorted({cut for d in units["AdaRL"] for cut in proposals(d) if cut <= milestone})
        for path in figures.save_figure(seed_curves(units, milestone, cuts), figure):
            print(f"\nwrote {path}")


def robustness_scores(run_dir: Path) -> dict[int, dict]:
    """Per seed, from the `paper` suite's episode table (one row per episode at each grid point):
    the worst-case return (the lowest point mean) and the average return (the mean of the point
    means), as M2TD3 and RRLS report them, with the points, the fewest episodes at a point and
    the step of the policy evaluated."""
    returns = collections.defaultdict(lambda: collections.defaultdict(list))  # seed, point
    steps = collections.defaultdict(set)
    for r in rows(run_dir / f"evaluations/suite-{SUITE}.csv"):
        returns[int(r["seed"])][r["dynamics"]].append(float(r["return"]))
        steps[int(r["seed"])].add(int(float(r["step"])))
    out = {}
    for seed, by_point in sorted(returns.items()):
        means = [float(np.mean(v)) for v in by_point.values()]
        out[seed] = {
            "worst": min(means),
            "average": float(np.mean(means)),
            "points": len(means),
            "episodes": min(len(v) for v in by_point.values()),
            "step": max(steps[seed]),
        }
    return out


def adarl_summary_agrees(run_dir: Path, recomputed: dict[int, dict]) -> bool:
    """Whether adarl's own per-seed summary (`suites/paper.csv`, written to 6 significant
    digits) holds the worst-case and average return recomputed here."""
    summary = {int(r["seed"]): r for r in rows(run_dir / f"suites/{SUITE}.csv")}
    return set(summary) == set(recomputed) and all(
        np.isclose(float(summary[s][score]), v[score], rtol=1e-5, atol=1e-3)
        for s, v in recomputed.items()
        for score in ("worst", "average")
    )


def robustness(root: Path) -> list[str]:
    """The robustness report at 3M (paper-schedule-walker2d.md, "Robustness at 3M")."""
    got: dict[str, dict[int, dict]] = {"AdaRL": {}, "SAC": {}}
    agrees = True
    for arm in got:
        for run_dir in sorted(root.glob(f"*/{ARMS[arm]}/seeds-*")):
            recomputed = robustness_scores(run_dir)
            got[arm] |= recomputed
            agrees &= not recomputed or adarl_summary_agrees(run_dir, recomputed)
    lines = [f"### Robustness on the `{SUITE}` suite (worst-case and average return per seed)", ""]
    missing = [arm for arm, seeds in got.items() if len(seeds) < 2]
    if missing:
        return lines + [f"Not computed: no `{SUITE}` suite evaluation of {', '.join(missing)} (2 seeds or more) under {root}.", ""]  # fmt: skip
    lines += ["| arm | seed | policy step | points × episodes | worst-case | average |"]
    lines += ["| --- | ---: | ---: | ---: | ---: | ---: |"]
    for arm, seeds in got.items():
        for seed, v in seeds.items():
            lines.append(
                f"| {arm} | {seed} | {v['step']:,} | {v['points']} × {v['episodes']} "
                f"| {v['worst']:,.0f} | {v['average']:,.0f} |"
            )
    lines += ["", f"Recomputed from the episodes; adarl's own summaries (suites/{SUITE}.csv) agree: {agrees}.", ""]  # fmt: skip
    lines += ["AdaRL − SAC, Welch, Holm over the two scores; detected where the Holm p < 0.05:", ""]  # fmt: skip
    lines += [
        "| score | difference | Welch 95% | Welch p | Holm p | permutation 95% | pooled SD "
        "| detectable at 80% (range) |",
        "| --- | ---: | --- | ---: | ---: | --- | ---: | ---: |",
    ]
    arms = {score: [np.array([v[score] for v in got[arm].values()]) for arm in got] for score in ("worst", "average")}  # fmt: skip
    results = {score: compare(*pair) for score, pair in arms.items()}
    adjusted = stats.holm([r["p"] for r in results.values()])
    for (score, r), a in zip(results.items(), adjusted, strict=True):
        decision = "**detected**" if a < 0.05 else "not detected"
        lines.append(comparison_row(f"{score} ({decision})", r, p_text(a)))
    return lines + [""]


USAGE = (
    "usage: paper_schedule.py SWEEP_DIR STEP [FIGURE] | export SWEEP_DIR ROWS_DIR | robustness DIR"
)


def cli(argv: list[str]) -> int:
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__)
        return 0
    command = argv[0] if argv[:1] in (["export"], ["robustness"]) else "milestone"
    if command == "milestone":
        well_formed = len(argv) in (2, 3) and argv[1].isdigit()
    else:
        well_formed = len(argv) == {"export": 3, "robustness": 2}[command]
    if not well_formed:
        print(USAGE, file=sys.stderr)
        return 2
    source = folder(argv[0] if command == "milestone" else argv[1])
    if command == "export":
        print(f"wrote {len(export(source, Path(argv[2])))} files under {argv[2]}")
    elif command == "robustness":
        print("\n".join(robustness(source)))
    else:
        main(source, int(argv[1]), Path(argv[2]) if len(argv) > 2 else None)
    return 0


if __name__ == "__main__":
    sys.exit(cli(sys.argv[1:]))
