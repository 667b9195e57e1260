"""Learning on the device backend against the host backend (issue 36): the same algorithm, task,
seeds and budget trained by each, every policy evaluated on the host task (MuJoCo C), and the
difference of the scores with Welch's interval, the permutation interval and the detectable
difference at 80% power.

    adarl train --algo sac --task hopper --dynamics nominal --seeds 0-4 --total-steps 20000 \\
        --eval-every 5000 --eval-episodes 5 --out RUNS/host
    adarl train ... --backend device --out RUNS/device
    python bench/device_parity.py RUNS/host RUNS/device [--copy docs/benchmarks/device-parity]

Score of a seed (fixed before the device run finished): the mean return of its last nominal
evaluation's episodes. `--copy DIR` copies both runs' eval.csv and config.yaml there, so that the
table is recomputed from committed rows (`python bench/device_parity.py DIR/host DIR/device`).
"""

from __future__ import annotations

import argparse
import csv
import shutil
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy import stats as st

from adarl import stats


def final_scores(run: Path) -> tuple[dict[int, float], int]:
    """Each seed's mean return over the episodes of its last nominal evaluation, and its step."""
    returns = defaultdict(lambda: defaultdict(list))
    with (run / "eval.csv").open(newline="") as f:
        for r in csv.DictReader(f):
            if r["dynamics"] == "nominal":
                returns[int(r["seed"])][int(r["step"])].append(float(r["return"]))
    last = min(max(by_step) for by_step in returns.values())
    return {s: float(np.mean(by_step[last])) for s, by_step in sorted(returns.items())}, last


def fail(message: str) -> int:
    """A one-line error on stderr; exit status 2, as adarl's commands."""
    print(f"device_parity.py: error: {message}", file=sys.stderr)
    return 2


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("host", type=Path)
    parser.add_argument("device", type=Path)
    parser.add_argument("--copy", type=Path, default=None)
    args = parser.parse_args(argv)
    for side, run in (("host", args.host), ("device", args.device)):
        if not (run / "eval.csv").is_file():
            return fail(f"{side} run {run} has no eval.csv; give two run folders of adarl train")
    host, step = final_scores(args.host)
    device, device_step = final_scores(args.device)
    if step != device_step:
        return fail(
            f"the runs' last evaluations differ (host at step {step:,}, device at "
            f"{device_step:,}); give runs of the same budget"
        )
    if args.copy:
        for side, run in (("host", args.host), ("device", args.device)):
            (args.copy / side).mkdir(parents=True, exist_ok=True)
            for name in ("eval.csv", "config.yaml"):
                shutil.copyfile(run / name, args.copy / side / name)
    x = np.array(list(device.values()))
    y = np.array(list(host.values()))
    ci = stats.welch_difference_ci(x, y)
    p = float(st.ttest_ind(x, y, equal_var=False).pvalue)
    perm = stats.two_sample_permutation_interval(x, y)
    sd = stats.pooled_sd(x, y)
    detectable = stats.welch_minimum_detectable_difference(sd, sd, len(x), len(y))
    low, high = stats.detectable_difference_range(sd, len(x), len(y))
    print(f"| backend | seeds | score at step {step:,} per seed | mean ± SD |")
    print("| --- | --- | --- | ---: |")
    for name, scores in (("host", host), ("device", device)):
        v = np.array(list(scores.values()))
        per_seed = ", ".join(f"{s}: {r:,.0f}" for s, r in scores.items())
        print(f"| {name} | {len(v)} | {per_seed} | {v.mean():,.0f} ± {v.std(ddof=1):,.0f} |")
    print()
    print("| device − host | Welch 95% | Welch p | permutation 95% | pooled SD | detectable at 80% (range) |")  # fmt: skip
    print("| ---: | --- | ---: | --- | ---: | ---: |")
    print(
        f"| {ci.point:+,.0f} | [{ci.low:+,.0f}, {ci.high:+,.0f}] | {p:.3f} | "
        f"[{perm.low:+,.0f}, {perm.high:+,.0f}] | {sd:,.0f} | {detectable:,.0f} ({low:,.0f}–{high:,.0f}) |"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
