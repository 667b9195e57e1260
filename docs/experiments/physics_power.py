"""Tables of docs/experiments/physics-power.md from the sweep's run folders: each seed's score
(the mean of its last 5 nominal evaluations) under `consistent` and `ompo` physics and under the
paper-ompo settings, and the Welch comparisons with their power.

    python docs/experiments/physics_power.py results/physics-power
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from adarl import stats
from adarl.results.collect import last_k_scores
from adarl.results.runs import load_run

ARMS = {
    "consistent": "sac_physics-consistent",
    "ompo": "sac_physics-ompo",
    "paper-ompo": "sac_paper-ompo",
}
LAST_K = 5  # the report's default score: the mean of the last 5 evaluations
TARGET = 300.0


def scores(sweep: Path, name: str) -> dict[int, float]:
    out = {}
    for run_dir in sorted(sweep.glob(f"*/{name}/seeds-*")):
        table, _ = last_k_scores(load_run(run_dir), LAST_K)
        out |= {int(s): float(v) for s, v in zip(table["seed"], table["score"])}
    return out


def main(sweep: Path) -> None:
    arms = {label: scores(sweep, name) for label, name in ARMS.items()}
    seeds = sorted(set.intersection(*(set(a) for a in arms.values())))
    print(f"| seed | {' | '.join(arms)} |\n| ---: |" + " ---: |" * len(arms))
    for s in seeds:
        print(f"| {s} | " + " | ".join(f"{arms[a][s]:,.0f}" for a in arms) + " |")
    values = {a: np.array([arms[a][s] for s in seeds]) for a in arms}
    print("| mean ± sd | " + " | ".join(
        f"{v.mean():,.0f} ± {v.std(ddof=1):,.0f}" for v in values.values()) + " |")  # fmt: skip
    print()
    print("| comparison | difference [95% Welch t] | permutation p | detectable at 80% | seeds per arm for 300 |")  # fmt: skip
    print("| --- | --- | ---: | ---: | ---: |")
    for a, b in (("ompo", "consistent"), ("paper-ompo", "consistent"), ("paper-ompo", "ompo")):
        x, y = values[a], values[b]
        ci = stats.welch_difference_ci(x, y)
        sd = stats.pooled_sd(x, y)
        print(
            f"| {a} − {b} | {ci.point:+,.0f} [{ci.low:+,.0f}, {ci.high:+,.0f}] | "
            f"{stats.permutation_p_value(x, y):.3g} | "
            f"{stats.minimum_detectable_difference(sd, len(x), len(y)):,.0f} | "
            f"{stats.seeds_per_arm(TARGET, sd):,.0f} |"
        )


if __name__ == "__main__":
    main(Path(sys.argv[1]))
