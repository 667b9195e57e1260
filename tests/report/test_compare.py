"""The report's per-task numbers on a hand-made score table, where one seed's final checkpoint
score is NaN (a run that diverged at its end, `--on-divergence continue`): the final means,
standard deviations and Student-t intervals are those of the finite finals, computed here with
NumPy and SciPy (adarl.report.compare, adarl.report.scores, adarl.report.common)."""

import numpy as np
import pandas as pd
import pytest
import scipy.stats

from adarl.report import compare, scores
from adarl.report.common import final_checkpoint_scores

SCORES = pd.DataFrame(
    {
        "task": ["hopper"] * 4 + ["walker2d"] * 2,
        "method": ["sac"] * 6,
        "seed": [0, 1, 2, 3, 0, 1],
        "score": [100.0, 200.0, 300.0, 500.0, 50.0, 70.0],
        "final": [110.0, 190.0, np.nan, 400.0, 60.0, np.nan],  # one NaN final per task
    }
)
FINITE = {"hopper": np.array([110.0, 190.0, 400.0]), "walker2d": np.array([60.0])}


def test_the_per_task_final_mean_and_interval_leave_nan_finals_out():
    rows = compare.per_task_estimates(SCORES, 0.9).set_index("task")
    hopper = rows.loc["hopper"]
    assert hopper["seeds"] == 4 and hopper["mean"] == pytest.approx(275.0)
    finals = FINITE["hopper"]
    half = scipy.stats.t.ppf(0.95, 2) * finals.std(ddof=1) / np.sqrt(3)
    assert hopper["final_mean"] == pytest.approx(finals.mean(), rel=1e-12)
    assert hopper["final_low"] == pytest.approx(finals.mean() - half, rel=1e-12)
    assert hopper["final_high"] == pytest.approx(finals.mean() + half, rel=1e-12)
    walker = rows.loc["walker2d"]  # one finite final: its value, and no interval
    assert walker["final_mean"] == 60.0
    assert np.isnan(walker["final_low"]) and np.isnan(walker["final_high"])


def test_table_1s_final_rows_leave_nan_finals_out(tmp_path):
    at_final = final_checkpoint_scores(SCORES)
    assert sorted(zip(at_final["task"], at_final["seed"])) == [
        ("hopper", 0), ("hopper", 1), ("hopper", 3), ("walker2d", 0),
    ]  # fmt: skip
    (tmp_path / "tables").mkdir()
    scores.table1_section(SCORES, tmp_path)
    table = pd.read_csv(tmp_path / "tables" / "table1.csv").set_index("task")
    for task, finals in FINITE.items():
        assert table.at[task, "final_seeds"] == finals.size
        assert table.at[task, "final_mean"] == pytest.approx(finals.mean(), rel=1e-5)
    assert table.at["hopper", "final_std"] == pytest.approx(FINITE["hopper"].std(ddof=1), rel=1e-5)
    md = (tmp_path / "tables" / "table1.md").read_text(encoding="utf-8")
    hopper = FINITE["hopper"]
    assert f"| hopper, final checkpoint | {hopper.mean():.1f} ± {hopper.std(ddof=1):.1f} |" in md
