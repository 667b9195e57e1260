"""docs/experiments/fixed_rank_power.py: the raw rows out of a sweep, the pre-registered analysis
from them and its planning power. Expected values are computed here by hand (exact permutation p
from counting splits, Fisher's p from the hypergeometric law) from the rows the test writes."""

import csv
import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

EXPERIMENTS = Path(__file__).parents[2] / "docs/experiments"


@pytest.fixture(scope="module")
def script():
    sys.path.insert(0, str(EXPERIMENTS))  # it imports table1_ant_humanoid's row helpers
    try:
        spec = importlib.util.spec_from_file_location("fixed_rank_power", EXPERIMENTS / "fixed_rank_power.py")  # fmt: skip
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(EXPERIMENTS))
    return module


def _unit(root, rank, first_seed, scores, last_step=300_000):
    """A unit of sac-fixed-rank at `rank` whose seed first_seed + i evaluates to
    scores[i] + step/1e5 (the mean of two episodes ±1) at every nominal evaluation."""
    unit = root / "hopper" / f"sac-fixed-rank_rank-{rank}" / f"seeds-{first_seed}-{first_seed + 4}"
    unit.mkdir(parents=True)
    with (unit / "eval.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "seed", "dynamics", "episode", "return", "length"])
        for step in range(10_000, last_step + 1, 10_000):
            for i, r in enumerate(scores):
                for episode, noise in enumerate((-1.0, 1.0)):
                    w.writerow([step, first_seed + i, "nominal", episode, r + step / 1e5 + noise, 1000])  # fmt: skip
    (unit / "checkpoints").mkdir()  # never exported
    if last_step >= 300_000:  # the run reached its budget (docs/run-format.md)
        (unit / "DONE").write_text(f"{last_step}\n")
    return unit


def _sweep(root, arms, last_steps=None):
    """Two units of five seeds per rank; last_steps[rank] is its second unit's last step."""
    last_steps = last_steps or {}
    for rank, scores in arms.items():
        _unit(root, rank, 0, scores[:5])
        _unit(root, rank, 5, scores[5:], last_steps.get(rank, 300_000))


def test_scores_and_the_wait_for_every_rank(script, tmp_path):
    arms = {7: [100.0 * i for i in range(10)], 13: [50.0] * 10, 64: [10.0] * 10}
    _sweep(tmp_path / "sweep", arms, last_steps={64: 150_000})
    script.export(tmp_path / "sweep", tmp_path / "rows")
    assert sorted(p.name for p in (tmp_path / "rows/hopper/sac-fixed-rank_rank-7").iterdir()) == [
        "seeds-0-4-eval.csv.gz",
        "seeds-5-9-eval.csv.gz",
    ]
    # rank 64's second unit is still training: left for a later export
    assert sorted(p.name for p in (tmp_path / "rows/hopper/sac-fixed-rank_rank-64").iterdir()) == [
        "seeds-0-4-eval.csv.gz"
    ]
    data = script.load(tmp_path / "rows")
    # the last five evaluations at 260k..300k: mean of step/1e5 = 2.8
    assert data[7]["scores"] == pytest.approx({i: 100.0 * i + 2.8 for i in range(10)})
    assert sorted(data[64]["scores"]) == [0, 1, 2, 3, 4]
    text = "\n".join(script.report(data))
    assert "Not computed until every rank's 10 seeds finish (rank 64: running)" in text
    assert "| 64 | 5 | 300,000 (running) |" in text


def test_separated_arms_give_the_smallest_exact_p(script, tmp_path):
    """Every rank-7 and rank-13 seed above every rank-64 seed: the observed split is the most
    extreme of C(20, 10), so the two-sided exact p is 2/C(20, 10) and Holm doubles the smaller."""
    low = [400.0 + 10 * i for i in range(10)]
    arms = {
        7: [2500.0 + 10 * i for i in range(10)],
        13: [2000.0 + 10 * i for i in range(10)],
        64: low,
    }
    _sweep(tmp_path / "sweep", arms)
    script.export(tmp_path / "sweep", tmp_path / "rows")
    lines = script.report(script.load(tmp_path / "rows"))
    splits = math.comb(20, 10)
    p = 2 / splits
    row7 = next(line for line in lines if line.startswith("| rank 7 − rank 64"))
    row13 = next(line for line in lines if line.startswith("| rank 13 − rank 64"))
    assert "(**detected**)" in row7 and "(**detected**)" in row13
    assert "| +2,100 |" in row7 and "| < 0.0001 | < 0.0001 |" in row7  # p = 1.1e-5, Holm 2.2e-5
    assert script.compare(np.array(arms[7]), np.array(low))["p"] == pytest.approx(p)
    # hop counts 10/10 (rank 7) against 0/10: Fisher's two-sided p is 2/C(20, 10) as well
    assert "10/10 vs 0/10: < 0.001, < 0.001 |" in row7
    assert script.compare(np.array(arms[7]), np.array(low))["counts"].fisher_p == pytest.approx(p)
    # rank 13's seeds all score 2,000-2,090: above the hop line too; rank 7 − rank 13 exploratory
    row = next(line for line in lines if line.startswith("| rank 7 − rank 13 |"))
    assert "| +500 |" in row and "| — |" in row


def test_no_difference_is_not_detected(script, tmp_path):
    rng = np.random.default_rng(1)
    same = list(rng.normal(1000.0, 300.0, 10))
    _sweep(tmp_path / "sweep", {7: same, 13: same, 64: same})
    script.export(tmp_path / "sweep", tmp_path / "rows")
    lines = script.report(script.load(tmp_path / "rows"))
    rows = [
        line for line in lines if line.startswith(("| rank 7 − rank 64", "| rank 13 − rank 64"))
    ]
    assert len(rows) == 2 and all("(not detected)" in r and "| +0 |" in r for r in rows)
    assert all("| 1.0000 | 1.0000 |" in r for r in rows)  # identical arms: p = 1


def test_the_simulations_exact_p_is_adarls(script):
    """The batched p of the power simulation (one matrix product over all splits) is
    `stats.permutation_p_value` row by row, ties included: identical arms give 1, fully
    separated arms 2/C(12, 6), a shifted copy of the same values the tie at the observed split."""
    from adarl import stats

    rng = np.random.default_rng(2)
    x, y = rng.normal(0.5, 1, (5, 6)), rng.normal(0, 1, (5, 6))
    x[1], y[2] = y[1], x[2] + 10.0  # identical arms; separated arms
    y[3] = x[3] - 0.25  # a pure shift
    indicator = script._splits(6, 6)
    assert indicator.shape == (math.comb(12, 6), 12) and (indicator.sum(axis=1) == 6).all()
    got = script._exact_ps(indicator, x, y)
    want = [stats.permutation_p_value(a, b) for a, b in zip(x, y, strict=True)]
    assert got == pytest.approx(want, abs=1e-12)
    assert got[1] == 1.0 and got[2] == pytest.approx(2 / math.comb(12, 6))


def test_the_power_tables_number_of_data_sets_gives_a_band_of_0_01(script):
    """n from the binomial SE: 1.96·√(0.25/n) ≤ 0.01 first at n = 9,604 (p = 0.5 is the worst
    case), and each cell's band is 1.96·√(p̂(1 − p̂)/n); the doc says both."""
    n = script.sims_for()
    assert n == 9604
    assert 1.959964 * math.sqrt(0.25 / n) <= 0.01 < 1.959964 * math.sqrt(0.25 / (n - 1))
    assert script.band(0.8, n) == pytest.approx(1.959964 * math.sqrt(0.16 / n))
    doc = " ".join((EXPERIMENTS / "fixed-rank-power.md").read_text().split())
    assert "9,604 simulated data sets per row" in doc


def test_the_power_table_says_its_bands_and_data_sets(script):
    lines = script.power_table(sims=40, seed=1)
    rows = [line for line in lines if line.startswith("| normal") or line.startswith("| hop")]
    assert len(rows) == 9 and all(" ± " in row for row in rows)
    assert lines[-1] == "(40 simulated data sets per row, seed 1.)"


def test_power_simulation_holds_its_level_and_finds_large_gaps(script):
    rng = np.random.default_rng(0)
    null = script._permutation_power(
        lambda r: (r.normal(0, 1, 10), r.normal(0, 1, 10)), 200, (0.05,), rng
    )
    assert null[0] <= 0.05 + 3 * math.sqrt(0.05 * 0.95 / 200)  # exact test: size ≤ α
    large = script._permutation_power(
        lambda r: (r.normal(5, 1, 10), r.normal(0, 1, 10)), 20, (0.05, 0.025), rng
    )
    assert large == [1.0, 1.0]


def test_command_line(script, capsys):
    assert script.main(["nonsense"]) == 2
    assert "usage" in capsys.readouterr().err
    assert script.main(["--help"]) == 0
    assert "export" in capsys.readouterr().out


def test_a_folder_that_is_not_there_is_refused(script, tmp_path, capsys):
    for command in ("export", "report"):  # the one-line message itself: table1's test
        with pytest.raises(SystemExit, match="2"):
            script.main([command, str(tmp_path / "nope")])
        assert "nope is not a folder" in capsys.readouterr().err


def test_the_docs_power_table_is_consistent_with_the_script(script):
    """fixed-rank-power.md's power table (the script's output, 9,604 data sets a row; too slow
    to rerun here): its Welch column is adarl's Welch power, each band is 1.96·√(p̂(1 − p̂)/n) of
    its own p̂, every band is within ±0.01, and the normal rows' permutation power holds the
    pooled t-test's (scipy's noncentral t, computed here) inside its band."""
    from scipy import stats as st

    from adarl import stats

    doc = (EXPERIMENTS / "fixed-rank-power.md").read_text()
    rows = [line for line in doc.splitlines() if line.startswith(("| normal, SD", "| hop with p"))]
    assert len(rows) == 9
    n = script.sims_for()
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        for cell in cells[2].split(" / "):
            p_hat, band = (float(v) for v in cell.split(" ± "))
            assert round(script.band(p_hat, n), 3) == band and band <= 0.01
        if not row.startswith("| normal"):
            continue
        sd, delta = (float(v.replace(",", "")) for v in (cells[0].split("SD ")[1], cells[1]))
        welch = [float(v) for v in cells[3].split(" / ")]
        assert welch == [round(stats.welch_power(delta, sd, sd, 10, 10, a), 3) for a in (0.05, 0.025)]  # fmt: skip
        for cell, alpha in zip(cells[2].split(" / "), (0.05, 0.025), strict=True):
            p_hat, band = (float(v) for v in cell.split(" ± "))
            critical = st.t.ppf(1 - alpha / 2, 18)
            nc = delta / (sd * math.sqrt(2 / 10))
            pooled_t = st.nct.sf(critical, 18, nc) + st.nct.cdf(-critical, 18, nc)
            assert abs(p_hat - pooled_t) <= band + 0.0005, (row, alpha, pooled_t)
