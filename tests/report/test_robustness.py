"""The robustness suites' numbers in the report (`adarl.report.robustness`): the mean over seeds of
the worst-case and of the average return with Student-t intervals, and the heatmap's grid."""

import numpy as np
import pandas as pd
import pytest
import scipy.stats

from adarl.report.robustness import heatmap_grid, worst_and_average


def test_worst_and_average_are_means_over_seeds_with_t_intervals():
    worst, average = [120.0, 80.0, 160.0], [300.0, 250.0, 410.0]
    got = worst_and_average(pd.DataFrame({"worst": worst, "average": average}))
    for column, values in (("worst", worst), ("average", average)):
        expected = scipy.stats.ttest_1samp(values, 0.0).confidence_interval(0.95)
        assert got[column] == pytest.approx((np.mean(values), expected.low, expected.high))
    one = worst_and_average(pd.DataFrame({"worst": [5.0], "average": [7.0]}))  # a mean, no interval
    assert one["average"][0] == 7.0 and np.isnan(one["average"][1]) and np.isnan(one["average"][2])


def test_heatmap_grid_averages_each_point_over_its_episodes_then_over_seeds():
    # seed -> point means over a 3 (a) x 2 (b) grid; each point's two episodes are mean ∓ 1
    rng = np.random.default_rng(0)
    means = {0: rng.uniform(0, 100, (3, 2)), 3: rng.uniform(0, 100, (3, 2))}
    rows = [
        {"step": 100, "seed": seed, "dynamics": f"fixed:a={a},b={b}", "episode": k,
         "return": m[i, j] + (1 if k else -1), "p_a": a, "p_b": b}
        for seed, m in means.items()
        for i, a in enumerate((0.1, 0.2, 0.3))
        for j, b in enumerate((1, 2))
        for k in range(2)
    ]  # fmt: skip
    x, y, cells = heatmap_grid(pd.DataFrame(rows), "b", "a")
    assert list(x) == [1, 2] and list(y) == [0.1, 0.2, 0.3]
    np.testing.assert_allclose(cells, (means[0] + means[3]) / 2)


def test_the_suites_table_counts_the_fewest_episodes_any_point_ran(tmp_path, monkeypatch):
    """Seed 1 ran one episode of three at one point: the table says 3 points × 1 episode."""
    from types import SimpleNamespace

    from adarl.report import common, robustness
    from adarl.report.common import ReportOptions

    rows = [
        {"step": 100, "seed": seed, "dynamics": f"fixed:floor_friction={f}", "episode": k,
         "return": 100.0 * seed + 10.0 * i + k, "length": 1000, "p_floor_friction": f}
        for seed in (0, 1)
        for i, f in enumerate((0.1, 1.55, 3.0))
        for k in range(3)
        if not (seed == 1 and f == 1.55 and k > 0)
    ]  # fmt: skip
    evaluation = SimpleNamespace(
        meta={"suite": "m2td3-1d", "final_checkpoint": True}, table=pd.DataFrame(rows)
    )
    monkeypatch.setattr(robustness.collect, "evaluations", lambda run: [evaluation])
    monkeypatch.setattr(common, "save_figure", lambda *args, **kwargs: [])
    (tmp_path / "tables").mkdir()
    run = SimpleNamespace(task="hopper", label="sac")
    section = robustness.suites_section([run], tmp_path, ReportOptions())
    table = pd.read_csv(tmp_path / "tables" / "suites.csv").iloc[0]
    assert (table["seeds"], table["points"], table["episodes"]) == (2, 3, 1)
    assert "| 2 | 3 × 1 |" in section.text
    # the worst case per seed: its lowest point mean (seed 0: 1; seed 1: 101), their mean
    assert table["worst_mean"] == pytest.approx(51.0)
