"""Issue 55 §4: AdaRL against its control in `adarl report`, numbers computed here from the
runs' eval.csv: the detectable difference is the paired t-test's at the SD of the differences
with ddof 1, and 5 of 5 positive pairs show the exact sign-flip p 2/2^5 = 0.0625."""

from __future__ import annotations

import numpy as np
import pandas as pd
import scipy.optimize
import scipy.stats
from synthetic_runs import write_run

from adarl.report.build import build_report
from adarl.report.common import ReportOptions


def final_scores(run, k: int = 5) -> pd.Series:
    evals = pd.read_csv(run / "eval.csv")
    last = evals[evals["step"].isin(sorted(evals["step"].unique())[-k:])]
    return last.groupby(["seed", "step"])["return"].mean().groupby("seed").mean()


def paired_detectable(sd: float, n: int, power: float = 0.8, alpha: float = 0.05) -> float:
    """The Δ a two-sided paired t-test of n pairs detects with `power`: noncentral t with
    n − 1 degrees of freedom and noncentrality Δ√n / sd (written out, not adarl.stats)."""
    df, crit = n - 1, scipy.stats.t.ppf(1 - alpha / 2, n - 1)

    def reached(delta):
        nc = delta * np.sqrt(n) / sd
        return scipy.stats.nct.sf(crit, df, nc) + scipy.stats.nct.cdf(-crit, df, nc) - power

    return scipy.optimize.brentq(reached, 1e-9 * sd, 10 * sd)


def test_five_positive_pairs_their_sign_flip_p_and_detectable_difference(tmp_path):
    runs = tmp_path / "runs"
    seeds = (0, 1, 2, 3, 4)
    adarl = write_run(runs, "adarl", seeds=seeds)
    control = write_run(
        runs, "control", algo="adarl-control", seeds=seeds, quality=0.5,
        extra_config={"rank_rule": "energy", "apply_cuts": False},
    )  # fmt: skip
    out = build_report([runs], tmp_path / "report", ReportOptions(bootstrap_reps=50))
    d = (final_scores(adarl) - final_scores(control)).loc[list(seeds)].to_numpy()
    assert (d > 0).all()  # 5 of 5 positive
    row = next(
        line for line in (out / "tables" / "control_pairs.md").read_text().splitlines()
        if line.startswith("| hopper")
    )  # fmt: skip
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[3] == "5"
    assert cells[7] == "0.0625"  # 2 of the 32 sign vectors are as extreme
    assert float(cells[8]) == round(paired_detectable(np.std(d, ddof=1), 5))
    assert float(cells[8]) != round(paired_detectable(np.std(d, ddof=0), 5))
