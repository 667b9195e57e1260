"""Tables of docs/experiments/mechanism-<task>.md from the sweep's run folders: that each control
shares its AdaRL run's prefix bit for bit, the ranks Eq. 5 proposed at the cut (applied by AdaRL,
logged and not applied by the control), and each seed's score in both arms with the paired test
and its power, for the score (the last 5 evaluations) and the final evaluation.

    python docs/experiments/mechanism.py results/mechanism-hopper
"""

from __future__ import annotations

import collections
import sys
from pathlib import Path

import numpy as np
from table1_ant_humanoid import folder, read_gzipped

from adarl import stats
from adarl.results.collect import last_k_scores
from adarl.results.runs import load_run
from adarl.runs.logs import read_csv

LAYERS = ("actor_1", "q1_1", "q2_1")
LAST_K = 5  # the report's default score: the mean of the last 5 evaluations
TARGET = 300.0


def rows(path: Path) -> list[dict]:
    """A run CSV's rows (a half-written last line left out), or those of `path.gz` where only
    that is there (the raw rows the report scripts export into docs/experiments/); none where
    neither is."""
    packed = path.with_name(path.name + ".gz")
    if not path.is_file() and packed.is_file():
        return read_gzipped(packed)
    return read_csv(path) if path.is_file() else []


def prefix_rows(path: Path, fork_step: int) -> list[tuple]:
    """A log's rows up to the fork, without the wall-clock column."""
    return [
        tuple(v for k, v in r.items() if k != "steps_per_s")
        for r in rows(path)
        if float(r["step"]) <= fork_step
    ]


def scores(run_dir: Path, k: int) -> dict[int, float]:
    """Each seed's mean nominal return over its last `k` evaluations (k = 1: the final one)."""
    table, _ = last_k_scores(load_run(run_dir), k)
    return {int(s): float(v) for s, v in zip(table["seed"], table["score"])}


def paired_line(what: str, method: dict, control: dict) -> str:
    seeds = sorted(set(method) & set(control))
    x = np.array([method[s] for s in seeds])
    y = np.array([control[s] for s in seeds])
    ci = stats.paired_difference_ci(x, y)
    sd = float(np.std(x - y, ddof=1))
    return (
        f"- {what}: AdaRL {x.mean():,.0f}, control {y.mean():,.0f}; AdaRL − control "
        f"{ci.point:+,.0f}, 95% paired t interval [{ci.low:+,.0f}, {ci.high:+,.0f}]; sign-flip "
        f"p = {stats.paired_permutation_p_value(x, y):.3g} ({len(seeds)} pairs); SD of the "
        f"differences {sd:,.0f}; smallest difference detectable at 80% power "
        f"{stats.paired_minimum_detectable_difference(sd, len(seeds)):,.0f}; pairs a "
        f"{TARGET:.0f}-point difference would need: {stats.paired_seeds_needed(TARGET, sd):,.0f}"
    )


def main(sweep: Path) -> None:
    print("## The shared prefix\n")
    print("| unit | fork step | episodes.csv rows | eval.csv rows | train.csv rows | identical |")
    print("| --- | ---: | ---: | ---: | ---: | --- |")
    cuts = collections.defaultdict(dict)
    score = {"method": {}, "control": {}}
    final = {"method": {}, "control": {}}
    for method_dir in sorted(sweep.glob("*/adarl-eq5/seeds-*")):
        control_dir = method_dir.parent.parent / "adarl-control-eq5" / method_dir.name
        truncations = rows(method_dir / "truncations.csv")
        fork = int(truncations[0]["step"])
        counts, same = [], True
        for name in ("episodes.csv", "eval.csv", "train.csv"):
            a, b = prefix_rows(method_dir / name, fork), prefix_rows(control_dir / name, fork)
            counts.append(len(a))
            same &= a == b
        print(f"| {method_dir.name} | {fork:,} | {' | '.join(f'{c:,}' for c in counts)} | {same} |")
        for r in truncations:
            cuts[int(r["seed"])][r["layer"]] = int(r["proposed_rank"])
        logged = {(r["seed"], r["layer"], r["proposed_rank"]) for r in truncations}
        shadow = rows(control_dir / "truncations.csv")
        assert {(r["seed"], r["layer"], r["proposed_rank"]) for r in shadow} == logged
        assert {r["decision"] for r in shadow} == {"control"}
        for side, run_dir in (("method", method_dir), ("control", control_dir)):
            score[side] |= scores(run_dir, LAST_K)
            final[side] |= scores(run_dir, 1)

    print("\n## Ranks Eq. 5 proposed at the cut (AdaRL applied them; the control kept 64)\n")
    print("| seed | actor | Q1 | Q2 |\n| ---: | ---: | ---: | ---: |")
    for seed in sorted(cuts):
        print(f"| {seed} | " + " | ".join(str(cuts[seed][layer]) for layer in LAYERS) + " |")

    print(f"\n## Score (mean of the last {LAST_K} nominal evaluations), seed by seed\n")
    print("| seed | AdaRL | control | AdaRL − control | final: AdaRL | final: control |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: |")
    for s in sorted(set(score["method"]) & set(score["control"])):
        a, b = score["method"][s], score["control"][s]
        print(
            f"| {s} | {a:,.0f} | {b:,.0f} | {a - b:+,.0f} | {final['method'][s]:,.0f} | "
            f"{final['control'][s]:,.0f} |"
        )
    print()
    print(paired_line(f"score (last {LAST_K} evaluations)", score["method"], score["control"]))
    print(paired_line("final evaluation", final["method"], final["control"]))


if __name__ == "__main__":
    if sys.argv[1:] in (["-h"], ["--help"]):
        print(__doc__)
    elif len(sys.argv) != 2:
        print("usage: mechanism.py SWEEP_DIR", file=sys.stderr)
        sys.exit(2)
    else:
        main(folder(sys.argv[1]))
