"""Return against the size of the perturbation: sizes and rings against hand computations, the
per-ring statistics on constructed tables, and the report's figure and table on synthetic runs."""

import itertools

import numpy as np
import pandas as pd
import pytest
import scipy.stats

from adarl.errors import UsageError
from adarl.evaluation import suites
from adarl.report import perturbation

CENTRE, HALF = (0.4, 0.39), (0.2, 0.2)  # Hopper's paper schedule: torso, foot


def test_training_box_is_the_paper_schedule():
    centre, half = perturbation.training_box("hopper", ["torso_length", "foot_length"])
    np.testing.assert_allclose(centre, CENTRE) and np.testing.assert_allclose(half, HALF)
    centre, half = perturbation.training_box("walker2d", ["foot_length", "torso_length"])
    np.testing.assert_allclose(centre, (0.1, 0.2)) and np.testing.assert_allclose(half, (0.05, 0.1))
    # masses and friction are not trained on: no training range, no curve
    assert perturbation.training_box("hopper", ["floor_friction", "torso_mass"]) is None
    assert perturbation.training_box("hopper", []) is None


def test_sizes_by_hand():
    points = [(0.4, 0.39), (0.5, 0.39), (0.3, 0.49), (0.5, 0.19), (0.6, 0.59), (0.5, 0.49)]
    np.testing.assert_allclose(
        perturbation.perturbation_size(points, CENTRE, HALF), [0, 0.5, 0.5, 1, 1, 0.5]
    )
    euclidean = perturbation.perturbation_size(points, CENTRE, HALF, norm="euclidean")
    np.testing.assert_allclose(
        euclidean, [0, 0.5, np.sqrt(0.5), np.sqrt(1.25), np.sqrt(2), np.sqrt(0.5)]
    )
    with pytest.raises(UsageError, match="unknown norm 'l1'; allowed: max, euclidean"):
        perturbation.perturbation_size(points, CENTRE, HALF, norm="l1")
    with pytest.raises(UsageError, match="half-ranges must be > 0"):
        perturbation.perturbation_size(points, CENTRE, (0.2, 0.0))


def test_rings_by_upper_edge():
    sizes = np.array([0.0, 0.1, 0.25, 0.26, 0.5, 0.75000000001, 1.0])
    edges = (0.25, 0.5, 0.75, 1.0)
    np.testing.assert_allclose(
        perturbation.assign_rings(sizes, edges), [0, 0.25, 0.25, 0.5, 0.5, 0.75, 1.0]
    )
    # exact rings: each distinct size (to 1e-4, labels to 4 decimals), nothing pooled; sizes a
    # CSV digit apart are one ring even across a rounding boundary (0.33335 | 0.333349)
    np.testing.assert_allclose(
        perturbation.assign_rings([1 / 3, 0.333335, 0.33335, 0.333349, 0.5, 0.0, 0.50004, 0.6]),
        [0.3333, 0.3333, 0.3333, 0.3333, 0.5, 0.0, 0.5, 0.6],
    )
    with pytest.raises(UsageError, match="beyond the last ring edge 1"):
        perturbation.assign_rings([1.2], edges)
    with pytest.raises(UsageError, match="increasing"):
        perturbation.assign_rings([0.1], (0.5, 0.25))


def paper_grid(task="hopper"):
    """The `paper` suite's 10 x 10 grid as (torso, foot) pairs, from the suite itself."""
    axes = suites.get_suite("paper", task).axes()
    assert [a.name for a in axes] == ["torso_length", "foot_length"]
    return np.array(list(itertools.product(axes[0].values, axes[1].values)))


def test_the_paper_grid_has_five_square_rings():
    """linspace(c − a, c + a, 10) → normalised ±1/9, ±3/9, …, ±1: max-norm rings of side 2k
    hold (2k)² − (2k − 2)² points, the nominal point is not on the grid."""
    csv_digits = np.vectorize(lambda v: float(f"{v:.6g}"))  # as an evaluation CSV stores them
    for task, points in itertools.product(("hopper", "walker2d"), ("exact", "csv")):
        box = perturbation.training_box(task, ["torso_length", "foot_length"])
        grid_points = paper_grid(task) if points == "exact" else csv_digits(paper_grid(task))
        rings = perturbation.assign_rings(perturbation.perturbation_size(grid_points, *box))
        values, counts = np.unique(rings, return_counts=True)
        np.testing.assert_allclose(values, [1 / 9, 3 / 9, 5 / 9, 7 / 9, 1], atol=1e-4)
        assert list(counts) == [4, 12, 20, 28, 36]


def test_an_odd_grid_holds_the_nominal_point_as_ring_zero():
    """`--points 7`: normalised 0, ±1/3, ±2/3, ±1, so rings 0, 1/3, 2/3, 1 of 1, 8, 16, 24."""
    axes = suites.get_suite("paper", "hopper", points=7).axes()
    grid_points = np.array(list(itertools.product(axes[0].values, axes[1].values)))
    rings = perturbation.assign_rings(perturbation.perturbation_size(grid_points, CENTRE, HALF))
    values, counts = np.unique(rings, return_counts=True)
    np.testing.assert_allclose(values, [0, 1 / 3, 2 / 3, 1], atol=1e-4)
    assert list(counts) == [1, 8, 16, 24]


def point_table(returns_of, seeds=(0, 1)) -> pd.DataFrame:
    """One row per seed and point of Hopper's paper grid: `return` = returns_of(seed, size, torso)."""
    grid_points = paper_grid()
    sizes = perturbation.perturbation_size(grid_points, CENTRE, HALF)
    rows = [
        {"seed": seed, "p_torso_length": t, "p_foot_length": f, "return": returns_of(seed, s, t)}
        for seed in seeds
        for (t, f), s in zip(grid_points, sizes)
    ]
    return pd.DataFrame(rows)


def test_ring_means_worst_and_worst_within_on_a_constructed_table():
    # return = 1000 − 500·size, ± 10 by the side of the torso (cancels in a ring's mean), seed 1
    # is 100 higher, and seed 0 fails (0) at the inner points left of the nominal torso.
    def returns_of(seed, size, torso):
        if seed == 0 and np.isclose(size, 1 / 9) and torso < 0.4 and torso > 0.37:
            return 0.0
        return 1000 - 500 * size + 100 * seed + (10 if torso > 0.4 else -10)

    table = point_table(returns_of)
    per_seed = perturbation.ring_returns(table, ["torso_length", "foot_length"], CENTRE, HALF)
    assert list(per_seed.columns) == perturbation.RING_COLUMNS
    rings = np.array([1, 3, 5, 7, 9]) / 9
    seed1 = per_seed[per_seed["seed"] == 1]
    np.testing.assert_allclose(seed1["ring"], rings, atol=1e-4)
    assert list(seed1["points"]) == [4, 12, 20, 28, 36]
    np.testing.assert_allclose(seed1["mean"], 1100 - 500 * rings)
    np.testing.assert_allclose(seed1["worst"], 1090 - 500 * rings)
    np.testing.assert_allclose(seed1["worst_within"], 1090 - 500 * rings)  # falls with size
    seed0 = per_seed[per_seed["seed"] == 0]
    # of the 4 points at size 1/9 (torso 0.3778 or 0.4222, foot 0.3678 or 0.4122), the 2 with
    # torso 0.3778 fail; the other 2 have the + 10
    np.testing.assert_allclose(seed0["mean"].iloc[0], (2 * (1000 - 500 / 9 + 10)) / 4)
    np.testing.assert_allclose(seed0["mean"].iloc[1:], 1000 - 500 * rings[1:])
    np.testing.assert_allclose(seed0["worst"].iloc[1:], 990 - 500 * rings[1:])
    np.testing.assert_allclose(seed0["worst_within"], 0.0)  # the inner failure is within every size

    summary = perturbation.ring_summary(per_seed)
    np.testing.assert_allclose(summary["mean_mean"].iloc[1:], 1050 - 500 * rings[1:])
    # two seeds 100 apart: s = 100/√2, half-width t_{0.975, 1} · s / √2 = t · 50
    half = scipy.stats.t.ppf(0.975, 1) * 50
    np.testing.assert_allclose(summary["mean_high"].iloc[1:] - summary["mean_mean"].iloc[1:], half)
    np.testing.assert_allclose(summary["mean_low"].iloc[1:], 1050 - 500 * rings[1:] - half)
    assert list(summary["seeds"]) == [2] * 5 and list(summary["points"]) == [4, 12, 20, 28, 36]


def test_worst_within_the_largest_size_is_the_suites_worst_case():
    rng = np.random.default_rng(0)
    noise = {seed: rng.normal(0, 50, 100) for seed in (0, 1, 2)}
    order = {}

    def returns_of(seed, size, torso):
        k = order.setdefault(seed, iter(range(100)))
        return 1000 - 400 * size + noise[seed][next(k)]

    table = point_table(returns_of, seeds=(0, 1, 2))
    per_seed = perturbation.ring_returns(table, ["torso_length", "foot_length"], CENTRE, HALF)
    last = per_seed[per_seed["ring"] == 1.0].set_index("seed")["worst_within"]
    np.testing.assert_allclose(last, table.groupby("seed")["return"].min())
    assert (per_seed.groupby("seed")["worst_within"].diff().dropna() <= 0).all()


def test_binned_rings_pool_sizes_by_upper_edge():
    table = point_table(lambda seed, size, torso: 1000 - 500 * size, seeds=(0,))
    per_seed = perturbation.ring_returns(
        table, ["torso_length", "foot_length"], CENTRE, HALF, edges=(0.25, 0.5, 0.75, 1.0)
    )
    # 1/9 → 0.25; 3/9 → 0.5; 5/9 → 0.75; 7/9 and 1 → 1.0 (28 + 36 points)
    np.testing.assert_allclose(per_seed["ring"], [0.25, 0.5, 0.75, 1.0])
    assert list(per_seed["points"]) == [4, 12, 20, 64]
    expected_last = (28 * (1000 - 500 * 7 / 9) + 36 * 500) / 64
    np.testing.assert_allclose(per_seed["mean"].iloc[-1], expected_last)


# ----------------------------------------------------------------------------- the report
def write_suite_evaluation(run_dir, returns_of, seeds=(0, 1)):
    """Store a constructed `paper` suite evaluation (2 episodes per point, mean = returns_of)
    in a synthetic Hopper run, as `adarl evaluate --suite paper` would (no episode is run)."""
    from adarl.results.runs import find_runs
    from adarl.runs.checkpoints import select_checkpoint
    from adarl.runs.layout import checkpoint_step

    (run,) = find_runs([run_dir])
    step = checkpoint_step(select_checkpoint(run.path))
    rows = []
    for seed, (t, f) in itertools.product(seeds, paper_grid()):
        size = perturbation.perturbation_size([(t, f)], CENTRE, HALF)[0]
        for episode, jitter in enumerate((-1.0, 1.0)):
            rows.append(
                {"step": step, "seed": seed, "dynamics": f"nominal:torso_length={t},foot_length={f}",
                 "episode": episode, "return": returns_of(seed, size) + jitter, "length": 1000,
                 "distance": 1.0, "p_foot_length": f, "p_torso_length": t}
            )  # fmt: skip
    suites.write_suite(pd.DataFrame(rows), run, "paper", command="test")


def test_report_draws_the_size_curve_next_to_the_heatmap(tmp_path):
    from synthetic_runs import write_run

    from adarl.report.build import build_report
    from adarl.report.common import ReportOptions

    runs = tmp_path / "runs"
    sac = write_run(runs, "sac", algo="sac", seeds=(0, 1), quality=0.8)
    adarl = write_run(runs, "adarl", algo="adarl", seeds=(0, 1))
    write_suite_evaluation(sac, lambda seed, size: 1000 - 600 * size + 20 * seed)
    write_suite_evaluation(adarl, lambda seed, size: 1000 - 200 * size + 20 * seed)
    out = tmp_path / "report"
    build_report([runs], out, ReportOptions(bootstrap_reps=100))
    for suffix in ("png", "pdf"):
        assert (out / "figures" / f"robustness_size_hopper_paper.{suffix}").stat().st_size > 0
    assert (out / "figures" / "suite_hopper_paper_adarl.png").is_file()
    table = pd.read_csv(out / "tables" / "robustness_size_hopper_paper.csv")
    assert list(table["method"].unique()) == ["adarl", "sac"]  # the report's method order
    rings = np.array([1, 3, 5, 7, 9]) / 9
    for method, slope in (("adarl", 200), ("sac", 600)):
        rows = table[table["method"] == method]
        np.testing.assert_allclose(rows["ring"], rings, atol=1e-4)
        np.testing.assert_allclose(rows["mean_mean"], 1010 - slope * rings, rtol=1e-5)
        np.testing.assert_allclose(rows["worst_within_mean"], 1010 - slope * rings, rtol=1e-5)
        assert list(rows["points"]) == [4, 12, 20, 28, 36] and set(rows["seeds"]) == {2}
    index = (out / "index.md").read_text()
    assert "Return against the size of the perturbation" in index
    assert "robustness_size_hopper_paper" in index
    assert "| mean return at size | 0.111 | 0.333 | 0.556 | 0.778 | 1 | worst within 1 |" in index
    assert "| sac | 943.3 | 810.0 | 676.7 | 543.3 | 410.0 | 410.0 |" in index  # 1010 − 600·size
