"""Issue 55: a NaN (or inf) return that the run itself wrote (`--on-divergence continue` keeps
training diverged weights, whose episodes have no finite return) is data: the summary and the
report read it as a missing return, a seed's score with one is NaN (not the mean of its finite
episodes), and NaN finals are left out of a mean over seeds. What a run never writes there (an
empty cell in eval.csv, `1e999`, text) is still refused as damage."""

from __future__ import annotations

import csv

import numpy as np
import pandas as pd
import pytest
import scipy.stats
from synthetic_runs import write_run

from adarl.cli.main import main
from adarl.errors import UsageError
from adarl.report.summary import training_summary
from adarl.results import collect
from adarl.results.runs import load_run


def rewrite_returns(path, change) -> list[dict]:
    """Rewrite `path`'s `return` cells with `change(row)` (None: keep); the rows as written."""
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        new = change(row)
        if new is not None:
            row["return"] = new
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return rows


def diverged_run(tmp_path, text="nan"):
    """Three seeds; seed 2's last evaluation holds `text` in one of its two episodes."""
    run = write_run(tmp_path, "r", algo="sac", seeds=(0, 1, 2))
    last = max(int(r["step"]) for r in collect.read_table(run / "eval.csv").to_dict("records"))
    rows = rewrite_returns(
        run / "eval.csv",
        lambda r: text if (r["seed"], int(r["step"]), r["episode"]) == ("2", last, "1") else None,
    )
    return run, rows, last


@pytest.mark.parametrize("text", ["nan", "inf", "-inf"])
def test_a_run_written_non_finite_return_is_read_as_nan(text, tmp_path):
    run, rows, last = diverged_run(tmp_path, text)
    table = collect.read_table(run / "eval.csv")
    assert table["return"].isna().sum() == 1
    scores, _ = collect.last_k_scores(load_run(run), 1)
    by_seed = dict(zip(scores["seed"], scores["score"]))
    assert np.isnan(by_seed[2])  # not the other episode's return alone
    for seed in (0, 1):  # by hand: the mean of the two episodes at the last step
        want = np.mean(
            [float(r["return"]) for r in rows if r["seed"] == str(seed) and int(r["step"]) == last]
        )
        assert by_seed[seed] == pytest.approx(want)
    finals, _ = collect.final_scores(load_run(run))
    assert np.isnan(finals.set_index("seed").loc[2, "score"])


def test_the_summary_of_a_diverged_run_says_nan_instead_of_calling_it_damaged(tmp_path):
    run, _, _ = diverged_run(tmp_path)
    text = training_summary(run, 12.0)
    assert "nan" in text and "restore the file" not in text


def test_the_report_leaves_nan_finals_out_of_the_mean(tmp_path, capsys):
    run, rows, last = diverged_run(tmp_path)
    out = tmp_path / "report"
    assert main(["report", str(run), "--out", str(out), "--bootstrap-reps", "200"]) == 0
    with open(out / "tables" / "scores.csv", encoding="utf-8") as f:
        scores = {int(r["seed"]): r for r in csv.DictReader(f)}
    assert scores[2]["final"] in ("", "nan")
    finite = [
        np.mean(
            [float(r["return"]) for r in rows if r["seed"] == str(s) and int(r["step"]) == last]
        )
        for s in (0, 1)
    ]
    for seed, want in zip((0, 1), finite):
        assert float(scores[seed]["final"]) == pytest.approx(want, rel=1e-5)
    index = (out / "index.md").read_text(encoding="utf-8")
    cell = f"| hopper, final checkpoint | {np.mean(finite):.1f} ± {np.std(finite, ddof=1):.1f} |"
    assert cell in index, index[:3000]  # the two finite seeds' mean and SD
    # the per-task section's final mean and its t interval: the two finite seeds' too
    per_task = pd.read_csv(out / "tables" / "per_task.csv").iloc[0]
    half = scipy.stats.t.ppf(0.975, 1) * np.std(finite, ddof=1) / np.sqrt(2)
    assert per_task["seeds"] == 3
    assert per_task["final_mean"] == pytest.approx(np.mean(finite), rel=1e-5)
    assert per_task["final_low"] == pytest.approx(np.mean(finite) - half, rel=1e-5)
    assert per_task["final_high"] == pytest.approx(np.mean(finite) + half, rel=1e-5)


@pytest.mark.parametrize("text", ["", "1e999", "lots"])
def test_what_a_run_never_writes_is_still_damage(text, tmp_path):
    run, _, _ = diverged_run(tmp_path, text)
    with pytest.raises(UsageError, match=r"eval.csv line \d+: return is"):
        collect.read_table(run / "eval.csv")
