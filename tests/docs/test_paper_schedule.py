"""docs/experiments/paper_schedule.py: the milestone report from a sweep and from its exported
raw rows (the same output), the pre-registered primaries with Holm's adjustment, and the
robustness report. Expected values are computed here by hand from the rows the test writes."""

import contextlib
import csv
import importlib.util
import io
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.stats

EXPERIMENTS = Path(__file__).parents[2] / "docs/experiments"
FORK = 50_000
ADARL = [1000.0, 1400.0, 900.0, 1600.0, 1200.0]
CONTROL = [900.0, 1450.0, 700.0, 1500.0, 1000.0]  # after the fork
SAC = [500.0, 800.0, 650.0, 700.0, 400.0]


@pytest.fixture(scope="module")
def script():
    sys.path.insert(0, str(EXPERIMENTS))  # it imports mechanism's and table1's helpers
    try:
        spec = importlib.util.spec_from_file_location("paper_schedule", EXPERIMENTS / "paper_schedule.py")  # fmt: skip
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.path.remove(str(EXPERIMENTS))


def _write(path: Path, header: list[str], rows: list[list]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        csv.writer(f).writerows([header, *rows])


def _unit(sweep: Path, name: str, returns: list[float], before: list[float] | None = None) -> Path:
    """Seed s returns returns[s] + step/1e5 at every nominal evaluation (10k..100k), before[s]
    + step/1e5 up to the fork when `before` is given (a control that shares AdaRL's prefix)."""
    unit = sweep / "walker2d" / name / "seeds-0-4"
    evals, episodes, train = [], [], []
    for step in range(10_000, 100_001, 10_000):
        for seed, r in enumerate(returns):
            base = before[seed] if before is not None and step <= FORK else r
            for episode, noise in enumerate((-2.0, 2.0)):  # mean over episodes: base + step/1e5
                evals.append([step, seed, "nominal", episode, base + step / 1e5 + noise, 1000])
            evals.append([step, seed, "paper", 0, -1e6, 10])  # not nominal: ignored
            episodes.append([step, seed, base, 500])
            train.append([step, seed, base / 10, 123.0])  # steps_per_s: timing, never compared
    _write(unit / "eval.csv", ["step", "seed", "dynamics", "episode", "return", "length"], evals)
    _write(unit / "episodes.csv", ["step", "seed", "return", "length"], episodes)
    _write(unit / "train.csv", ["step", "seed", "loss", "steps_per_s"], train)
    (unit / "checkpoints").mkdir()  # never exported
    return unit


def _cuts(unit: Path, ranks: list[int], applied: bool) -> None:
    rows = [
        [FORK, s, layer, 64, r + i, r + i if applied else 64]
        for s, r in enumerate(ranks)
        for i, layer in enumerate(("actor_1", "q1_1", "q2_1"))
    ]
    _write(unit / "truncations.csv", ["step", "seed", "layer", "old_rank", "proposed_rank", "new_rank"], rows)  # fmt: skip


def _suite(unit: Path, point_returns: dict[int, list[list[float]]]) -> None:
    """The `paper` suite's episode table: seed -> points -> that point's episode returns."""
    rows = [
        [3_000_000, seed, f"p{i}", e, ret, 1000, 1.0, 0.3 + i / 10]
        for seed, points in point_returns.items()
        for i, episodes in enumerate(points)
        for e, ret in enumerate(episodes)
    ]
    header = ["step", "seed", "dynamics", "episode", "return", "length", "distance", "p_torso"]
    _write(unit / "evaluations/suite-paper.csv", header, rows)


@pytest.fixture()
def sweep(tmp_path):
    root = tmp_path / "sweep"
    adarl = _unit(root, "adarl_rank_rule-cumulative", ADARL)
    _cuts(adarl, [36, 36, 38, 36, 39], applied=True)
    control = _unit(root, "adarl-control-eq5", CONTROL, before=ADARL)
    _cuts(control, [36, 36, 38, 36, 39], applied=False)
    _unit(root, "sac", SAC)
    return root


def _main(script, root: Path, milestone: int) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        script.main(root, milestone)
    return out.getvalue()


def test_export_keeps_the_layout_and_the_report_is_the_same_from_the_rows(script, sweep, tmp_path):
    rows = tmp_path / "rows"
    script.export(sweep, rows)
    unit = rows / "walker2d/adarl_rank_rule-cumulative/seeds-0-4"
    assert sorted(p.name for p in unit.iterdir()) == [
        "episodes.csv.gz", "eval.csv.gz", "train.csv.gz", "truncations.csv.gz"
    ]  # fmt: skip
    assert not (rows / "walker2d/sac/seeds-0-4/checkpoints").exists()
    from_sweep = _main(script, sweep, 100_000)
    assert _main(script, rows, 100_000) == from_sweep
    assert f"shares AdaRL's logs up to the fork at {FORK:,}: True" in from_sweep
    assert "| 2 | 38 | 39 | 40 | 38 | 39 | 40 |" in from_sweep  # seed 2: proposals in both arms


def test_the_primaries_are_holm_adjusted_over_the_two(script, sweep):
    out = _main(script, sweep, 100_000)
    # scores: each arm's returns + 0.8 (steps 60k..100k); the shift cancels in the differences
    d = np.subtract(ADARL, CONTROL)
    t = d.mean() / (d.std(ddof=1) / np.sqrt(d.size))
    p_control = 2 * scipy.stats.t.sf(abs(t), d.size - 1)
    a, s = np.array(ADARL), np.array(SAC)
    va, vs = a.var(ddof=1) / a.size, s.var(ddof=1) / s.size
    df = (va + vs) ** 2 / (va**2 / (a.size - 1) + vs**2 / (s.size - 1))
    p_sac = 2 * scipy.stats.t.sf((a.mean() - s.mean()) / np.sqrt(va + vs), df)
    low, high = sorted((p_control, p_sac))
    holm = {low: 2 * low, high: max(2 * low, high)}
    line = next(x for x in out.splitlines() if x.startswith("- Primary tests, Holm"))
    assert f"AdaRL − control (paired t) p = {p_control:.3g}, Holm {holm[p_control]:.3g}" in line
    assert f"AdaRL − SAC (Welch) p = {p_sac:.3g}, Holm {holm[p_sac]:.3g}" in line
    expected = ["**detected**" if holm[p] < 0.05 else "not detected" for p in (p_control, p_sac)]
    assert [part.rsplit(": ", 1)[1] for part in line.split("; ")] == expected


def _summary(unit: Path, worst: np.ndarray, average: np.ndarray) -> None:
    """suites/paper.csv as adarl writes it (6 significant digits)."""
    rows = [["paper", 3_000_000, s, 4, 3, f"{w:.6g}", f"{a:.6g}", "p0"] for s, (w, a) in enumerate(zip(worst, average))]  # fmt: skip
    _write(unit / "suites/paper.csv", ["suite", "step", "seed", "points", "episodes", "worst", "average", "worst_point"], rows)  # fmt: skip


def test_robustness_recomputes_worst_and_average_from_the_episodes(script, sweep, tmp_path):
    rng = np.random.default_rng(0)
    by_hand = {}
    for name, level in (("adarl_rank_rule-cumulative", 1000.0), ("sac", 600.0)):
        table = {
            seed: [
                [level + 50 * seed + 10 * i + noise for noise in rng.normal(0, 30, size=3)]
                for i in range(4)
            ]  # fmt: skip
            for seed in range(5)
        }
        unit = sweep / "walker2d" / name / "seeds-0-4"
        _suite(unit, table)
        means = [[np.mean(episodes) for episodes in points] for points in table.values()]
        by_hand[name] = np.array([min(m) for m in means]), np.array([np.mean(m) for m in means])
        _summary(unit, *by_hand[name])
    rows = tmp_path / "rows"
    script.export(sweep, rows)
    lines = script.robustness(rows)
    assert lines == script.robustness(sweep)
    assert "adarl's own summaries (suites/paper.csv) agree: True." in "\n".join(lines)
    (a_worst, a_avg), (s_worst, s_avg) = by_hand["adarl_rank_rule-cumulative"], by_hand["sac"]
    assert f"| AdaRL | 3 | 3,000,000 | 4 × 3 | {a_worst[3]:,.0f} | {a_avg[3]:,.0f} |" in lines
    p = [scipy.stats.ttest_ind(a_worst, s_worst, equal_var=False).pvalue,
         scipy.stats.ttest_ind(a_avg, s_avg, equal_var=False).pvalue]  # fmt: skip
    adjusted = [min(1.0, 2 * min(p)), max(min(1.0, 2 * min(p)), max(p))]
    if p[0] > p[1]:
        adjusted.reverse()
    for score, x, y, raw, holm in zip(("worst", "average"), (a_worst, a_avg), (s_worst, s_avg), p, adjusted):  # fmt: skip
        row = next(line for line in lines if line.startswith(f"| {score} ("))
        assert row.startswith(f"| {score} (**detected**)" if holm < 0.05 else f"| {score} (not detected)")  # fmt: skip
        cells = [c.strip() for c in row.split("|")[1:-1]]
        assert cells[1] == f"{x.mean() - y.mean():+,.0f}"
        shown = [f"{v:.3f}" if v >= 0.0005 else "< 0.001" for v in (raw, holm)]  # never 0.000
        assert [cells[3], cells[4]] == shown


def test_robustness_says_when_adarls_summary_disagrees(script, sweep):
    for name in ("adarl_rank_rule-cumulative", "sac"):
        _suite(sweep / "walker2d" / name / "seeds-0-4", {0: [[10.0, 20.0], [40.0]], 1: [[5.0]]})
        _summary(sweep / "walker2d" / name / "seeds-0-4", np.array([15.0, 5.0]), np.array([27.5, 5.0]))  # fmt: skip
    assert "agree: True." in "\n".join(script.robustness(sweep))
    _summary(sweep / "walker2d/sac/seeds-0-4", np.array([15.0, 5.0]), np.array([27.6, 5.0]))
    assert "agree: False." in "\n".join(script.robustness(sweep))


def test_robustness_waits_for_both_arms(script, sweep):
    _suite(sweep / "walker2d/sac/seeds-0-4", {0: [[1.0]], 1: [[2.0]]})
    assert any(line.startswith("Not computed: no `paper` suite evaluation of AdaRL") for line in script.robustness(sweep))  # fmt: skip


def test_command_line(script, sweep, tmp_path, capsys):
    assert script.cli(["--help"]) == 0 and "robustness DIR" in capsys.readouterr().out
    for argv in (["export", str(tmp_path / "nope"), str(tmp_path / "rows")], [str(tmp_path / "nope"), "100"]):  # fmt: skip
        with pytest.raises(SystemExit) as stopped:
            script.cli(argv)
        err = capsys.readouterr().err
        assert stopped.value.code == 2 and err.count("\n") == 1 and "nope is not a folder" in err
    for argv in ([], ["export", str(sweep)], [str(sweep), "1e6"], ["robustness"]):
        assert script.cli(argv) == 2 and capsys.readouterr().err.startswith("usage:")
    assert script.cli(["export", str(sweep), str(tmp_path / "rows")]) == 0
    # AdaRL and the control: 4 files each; SAC has no truncations.csv
    assert capsys.readouterr().out == f"wrote 11 files under {tmp_path / 'rows'}\n"


def test_what_the_walker2d_progress_says_of_its_finished_adarl_units():
    """paper-schedule-walker2d.md, "Progress": the ranks kept at each cut and the training time,
    read with pandas from the committed rows (seeds finished so far, at least 0 and 1)."""
    import pandas as pd

    arm = EXPERIMENTS / "paper-schedule-walker2d/rows/walker2d/adarl_rank_rule-cumulative"
    quoted = {  # seed: actor's ranks, each critic's ranks, seconds of training
        0: ([36, 29, 25, 23], [42, 36, 32, 29], 6236),
        1: ([34, 28, 25, 23], [40, 34, 30, 27], 6290),
    }
    for seed, (actor, critic, seconds) in quoted.items():
        cuts = pd.read_csv(arm / f"seeds-{seed}/truncations.csv.gz")
        assert sorted(set(cuts["step"])) == [700_950, 1_400_950, 2_100_950, 2_800_950]
        for layer, ranks in [("actor_1", actor), ("q1_1", critic), ("q2_1", critic)]:
            assert list(cuts[cuts["layer"] == layer].sort_values("step")["new_rank"]) == ranks
        train = pd.read_csv(arm / f"seeds-{seed}/train.csv.gz")
        assert train["step"].iloc[-1] == 3_000_000 and (np.diff(train["step"]) > 0).all()
        assert round((np.diff(train["step"], prepend=0) / train["steps_per_s"]).sum()) == seconds
