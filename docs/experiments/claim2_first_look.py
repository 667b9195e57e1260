"""Tables of docs/experiments/claim2-first-look.md from the sweep's run folders (partial or done):
the ranks Eq. 5 proposed at each truncation, the components holding 90% of the singular-value
mass and 99% of the energy in each spectrum, and the nominal evaluation returns.

    python docs/experiments/claim2_first_look.py results/claim2-first-look
"""

from __future__ import annotations

import collections
import csv
import sys
from pathlib import Path

import numpy as np

LAYERS = ("actor_1", "q1_1", "q2_1")


def rows(path: Path) -> list[dict]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def components_holding(values: np.ndarray, share: float) -> int:
    """The fewest leading components whose sum holds `share` of the total."""
    values = np.sort(values[values > 0])[::-1]
    return int(np.searchsorted(np.cumsum(values) / values.sum(), share) + 1)


def spread(values) -> str:
    low, high = min(values), max(values)
    return f"{low}" if low == high else f"{low}–{high}"


def main(sweep: Path) -> None:
    runs = sorted(sweep.glob("*/adarl_rank_rule-cumulative/seeds-*"))
    print("| task | after updates | actor | Q1 | Q2 |\n| --- | ---: | --- | --- | --- |")
    for run in runs:
        cuts = collections.defaultdict(dict)
        for r in rows(run / "truncations.csv"):
            cuts[int(r["step"])].setdefault(r["layer"], []).append(r["proposed_rank"])
        for k, step in enumerate(sorted(cuts), start=1):
            cells = " | ".join(", ".join(cuts[step][layer]) for layer in LAYERS)
            print(f"| {run.parts[-3].capitalize()} | {250 * k}k | {cells} |")
    print("\n| task | after updates | layer | 90% of Σσ in | 99% of Σσ² in |")
    print("| --- | ---: | --- | --- | --- |")
    for run in runs:
        for k, path in enumerate(sorted((run / "spectra").glob("step_*.npz")), start=1):
            with np.load(path) as spectra:
                for layer in LAYERS:
                    s = spectra[layer]  # (seeds, components), zero-padded past a seed's rank
                    mass = [components_holding(x, 0.90) for x in s]
                    energy = [components_holding(x**2, 0.99) for x in s]
                    task = run.parts[-3].capitalize()
                    print(f"| {task} | {250 * k}k | {layer} | {spread(mass)} | {spread(energy)} |")
    print("\n| task | seed | return at 50k, 100k, … (every 50k steps) |\n| --- | ---: | --- |")
    for run in runs:
        returns = collections.defaultdict(list)
        for r in rows(run / "eval.csv"):
            returns[(int(r["seed"]), int(r["step"]))].append(float(r["return"]))
        for seed in sorted({s for s, _ in returns}):
            means = [np.mean(v) for (s, _), v in sorted(returns.items()) if s == seed]
            text = ", ".join(f"{m:.0f}" for m in means)
            print(f"| {run.parts[-3].capitalize()} | {seed} | {text} |")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "results/claim2-first-look"))
