"""AdaRL against its schedule-matched control in `adarl report`: seeds paired by number, the
Student-t interval of the mean per-seed difference (`stats.paired_difference_ci`)."""

import numpy as np
import pandas as pd
import pytest
import scipy.stats
from synthetic_runs import write_run

from adarl import stats
from adarl.report.build import build_report
from adarl.report.common import ReportOptions


def test_paired_difference_ci_is_the_t_interval_of_the_differences():
    x, y = np.array([3.0, 5.0, 4.0, 7.0]), np.array([1.0, 4.0, 4.5, 2.0])
    d = x - y
    half = scipy.stats.t.ppf(0.95, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d))
    ci = stats.paired_difference_ci(x, y, confidence=0.9)
    assert (ci.point, ci.low, ci.high) == pytest.approx(
        (d.mean(), d.mean() - half, d.mean() + half)
    )
    low, high = scipy.stats.ttest_rel(x, y).confidence_interval(0.9)
    assert (ci.low, ci.high) == pytest.approx((low, high))
    one = stats.paired_difference_ci([2.0], [1.0])
    assert one.point == 1.0 and np.isnan(one.low) and np.isnan(one.high)
    with pytest.raises(ValueError, match="same number of seeds"):
        stats.paired_difference_ci([1.0, 2.0], [1.0])


def final_scores(run, k: int = 5) -> pd.Series:
    """Each seed's score as the report's default: the mean, over the last k evaluations of
    eval.csv, of each evaluation's mean nominal return."""
    evals = pd.read_csv(run / "eval.csv")
    last = evals[evals["step"].isin(sorted(evals["step"].unique())[-k:])]
    return last.groupby(["seed", "step"])["return"].mean().groupby("seed").mean()


def test_the_report_pairs_adarl_with_its_control_seed_by_seed(tmp_path):
    runs = tmp_path / "runs"
    adarl = write_run(runs, "adarl", seeds=(0, 1, 2, 3))
    fork = {"from": str(adarl), "step": 5000, "checkpoint": "pre_truncation", "changed": {}}
    control = write_run(
        runs, "control", algo="adarl-control", seeds=(1, 2, 3, 4), quality=0.8,
        extra_config={"rank_rule": "energy", "apply_cuts": False, "fork": fork},
    )  # fmt: skip
    write_run(runs, "sac", algo="sac", seeds=(0, 1), quality=0.5)  # paired with nothing
    other = write_run(  # another rule: no AdaRL run to pair with
        runs, "other", algo="adarl-control", seeds=(0,),
        extra_config={"rank_rule": "ratio", "apply_cuts": False},
    )  # fmt: skip
    out = build_report([runs], tmp_path / "report", ReportOptions(bootstrap_reps=50))

    pairs = pd.read_csv(out / "tables" / "control_pairs.csv")
    a, c = final_scores(adarl), final_scores(control)
    assert list(pairs["seed"]) == [1, 2, 3]  # the seeds both arms ran
    assert list(pairs["method"].unique()) == ["adarl"]
    assert list(pairs["control"].unique()) == ["adarl-control"]
    np.testing.assert_allclose(pairs["difference"], (a - c).loc[[1, 2, 3]], rtol=1e-5)  # 6 digits
    low, high = scipy.stats.ttest_rel(a.loc[[1, 2, 3]], c.loc[[1, 2, 3]]).confidence_interval()
    md = (out / "tables" / "control_pairs.md").read_text()
    assert f"[{low:.1f}, {high:.1f}]" in md and "| 3 |" in md
    index = (out / "index.md").read_text()
    assert "AdaRL against its control" in index
    assert f"{control}: forked from {adarl} at step 5000" in index
    assert str(other) not in pairs.to_string()
