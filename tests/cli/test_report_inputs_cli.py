"""Run logs whose values the statistics cannot take (issue 38, class 2; docs/reliability.md):
`nan` or `inf` where a number is needed, a renamed column, run kinds mixed in one report. The
report refuses in one line naming the file, line and column, or is made: never a traceback, a
numpy warning or a NaN statistic from a damaged value."""

import math

import pytest
from synthetic_runs import write_run

from adarl import stats
from adarl.cli.main import main


def _report(tmp_path, capsys):
    argv = ["report", str(tmp_path / "runs"), "--out", str(tmp_path / "report")]
    code = main([*argv, "--bootstrap-reps", "20"])
    return code, capsys.readouterr().err


def _edit(path, line: int, column: str, value: str) -> None:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[line - 1].split(",")
    cells[header.index(column)] = value
    lines[line - 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("log", ["eval.csv", "episodes.csv"])
@pytest.mark.parametrize("value", ["NaN", "1e999", "", "Infinity"])
def test_a_non_finite_return_is_refused_in_one_line(log, value, tmp_path, capsys):
    """What no run writes; `nan`, `inf` and `-inf` are what a diverged run writes (issue 55:
    data, read as NaN: tests/results/test_run_nan.py, and below)."""
    run = write_run(tmp_path / "runs", "r", seeds=(0, 1))
    _edit(run / log, 3, "return", value)
    if log == "episodes.csv":  # read for the training curve of a run without eval.csv
        (run / "eval.csv").unlink()
    code, err = _report(tmp_path, capsys)
    assert code == 2, err
    assert err.count("\n") == 1, err  # no numpy warning, no traceback
    assert f"{log} line 3: return is {value!r}; allowed: a finite number" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]


@pytest.mark.parametrize("log", ["eval.csv", "episodes.csv"])
@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_a_non_finite_return_the_run_wrote_is_reported(log, value, tmp_path, capsys):
    run = write_run(tmp_path / "runs", "r", seeds=(0, 1))
    _edit(run / log, 3, "return", value)
    if log == "episodes.csv":
        (run / "eval.csv").unlink()
    code, err = _report(tmp_path, capsys)
    assert code == 0, err


@pytest.mark.parametrize("log, column", [("eval.csv", "return"), ("eval.csv", "seed"),
                                         ("truncations.csv", "new_rank"), ("eval.csv", "dynamics")])  # fmt: skip
def test_a_renamed_column_is_refused_in_one_line(log, column, tmp_path, capsys):
    run = write_run(tmp_path / "runs", "r", seeds=(0, 1))
    text = (run / log).read_text()
    header, rest = text.split("\n", 1)
    (run / log).write_text(header.replace(column, column.upper()) + "\n" + rest)
    code, err = _report(tmp_path, capsys)
    assert code == 2, err
    assert err.count("\n") == 1, err
    assert f"{log} has no column {column!r}" in err, err


def test_a_non_finite_value_in_a_column_the_report_does_not_score_is_kept(tmp_path, capsys):
    run = write_run(tmp_path / "runs", "r", seeds=(0, 1))
    _edit(run / "eval.csv", 3, "length", "nan")  # not a score: shown as a gap, not refused
    code, err = _report(tmp_path, capsys)
    assert code == 0, err


@pytest.mark.parametrize(
    "adarl, sac, control", [((0,), (0, 1), (0, 1)), ((0, 1), (0, 1, 2), (0, 1)), ((0, 1, 2),) * 3]
)
def test_adarl_sac_and_a_control_in_one_report(adarl, sac, control, tmp_path, capsys):
    write_run(tmp_path / "runs", "adarl", algo="adarl", seeds=adarl)
    write_run(tmp_path / "runs", "sac", algo="sac", seeds=sac, quality=0.8)
    write_run(tmp_path / "runs", "control", algo="adarl-control", seeds=control, quality=0.9)
    code, err = _report(tmp_path, capsys)
    assert code == 0, err
    assert "Traceback" not in err and "Warning" not in err, err
    index = (tmp_path / "report" / "index.md").read_text()
    assert "AdaRL against its control" in index


def test_the_detectable_difference_of_two_paired_seeds_is_nan_not_an_error():
    # one degree of freedom: scipy's noncentral t is NaN where the root would be bracketed
    assert math.isnan(stats.paired_minimum_detectable_difference(1.0, 2, 0.8))
    assert math.isnan(stats.minimum_detectable_difference(1.0, 1, 2, 0.8))
    # with a degree of freedom more it is found: power 0.8 at the root (checked through scipy)
    import scipy.stats

    d = stats.paired_minimum_detectable_difference(1.0, 3, 0.8)
    crit = scipy.stats.t.ppf(0.975, 2)
    lam = d * math.sqrt(3)
    power = scipy.stats.nct.sf(crit, 2, lam) + scipy.stats.nct.cdf(-crit, 2, lam)
    assert power == pytest.approx(0.8, abs=1e-6)
