"""Issue 55 §4: report behaviour that planted bugs got past, each number computed here from the
run folders: a two-valued contrast reads "b − a" against the documented reference (the first
value in sorted order, or the one named), one 1-seed cell does not drop the per-task section, a
shortened `adarl evaluate` (--max-episode-steps) never makes the final score, and an episode at
a bin edge of the episodes.csv curve lands in the bin that edge closes."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from synthetic_runs import write_run

from adarl.report.build import build_report
from adarl.report.common import ReportOptions
from adarl.results import collect
from adarl.results.runs import load_run


def final_scores(run, k: int = 5) -> pd.Series:
    evals = pd.read_csv(run / "eval.csv")
    last = evals[evals["step"].isin(sorted(evals["step"].unique())[-k:])]
    return last.groupby(["seed", "step"])["return"].mean().groupby("seed").mean()


@pytest.mark.parametrize("contrast, reference", [("gamma", "0.95"), ("gamma=0.99", "0.99")])
def test_a_two_valued_contrast_is_b_minus_the_reference(contrast, reference, tmp_path):
    runs = tmp_path / "runs"
    low = write_run(runs, "g95", algo="sac", seeds=(0, 1, 2), extra_config={"gamma": 0.95})
    high = write_run(
        runs, "g99", algo="sac", seeds=(0, 1, 2), quality=2.0, extra_config={"gamma": 0.99}
    )
    options = ReportOptions(bootstrap_reps=50, contrasts=(contrast,))
    out = build_report([runs], tmp_path / "report", options)
    table = pd.read_csv(out / "tables" / "contrast_gamma.csv")
    assert len(table) == 1
    other = "0.99" if reference == "0.95" else "0.95"
    assert table["contrast"][0] == f"gamma: {other} − {reference}"
    by_value = {"0.95": final_scores(low).mean(), "0.99": final_scores(high).mean()}
    want = by_value[other] - by_value[reference]
    assert table["difference"][0] == pytest.approx(want, rel=1e-4)
    assert (want > 0) == (reference == "0.95")  # the better run is the 0.99 one


def test_one_single_seed_cell_does_not_drop_the_per_task_section(tmp_path):
    runs = tmp_path / "runs"
    write_run(runs, "sac", algo="sac", seeds=(0, 1, 2))
    write_run(runs, "adarl", algo="adarl", seeds=(0,))  # one seed
    out = build_report([runs], tmp_path / "report", ReportOptions(bootstrap_reps=50))
    per_task = pd.read_csv(out / "tables" / "per_task.csv")
    assert set(per_task["method"]) >= {"sac", "adarl"}, per_task
    sac = per_task[per_task["method"] == "sac"].iloc[0]
    assert sac["seeds"] == 3 and np.isfinite(sac["mean_low"]) and sac["mean_low"] < sac["mean_high"]
    adarl = per_task[per_task["method"] == "adarl"].iloc[0]
    assert adarl["seeds"] == 1 and np.isnan(adarl["mean_low"])  # no interval from one seed


def test_a_shortened_evaluation_never_makes_the_final_score(tmp_path):
    run = write_run(tmp_path, "r", algo="sac", seeds=(0, 1))
    last = collect.final_step(load_run(run))
    folder = run / "evaluations"
    folder.mkdir()
    for name, limit in (("short", 100), ("full", None)):
        rows = [
            {"step": last, "seed": s, "dynamics": "nominal", "episode": e, "return": 99_999.0}
            for s in (0, 1) for e in range(2)
        ]  # fmt: skip
        pd.DataFrame(rows).to_csv(folder / f"{name}.csv", index=False)
        meta = {"dynamics": "nominal", "sweep": {}, "hold": {}, "episodes": 2,
                "checkpoint_step": last, "final_checkpoint": True, "max_episode_steps": limit}  # fmt: skip
        (folder / f"{name}.json").write_text(json.dumps(meta))
        scores, note = collect.final_scores(load_run(run))
        if limit is None:  # a full-length evaluation of the final checkpoint is the final score
            assert "adarl evaluate" in note and (scores["score"] == 99_999.0).all()
        else:
            assert note.startswith("eval.csv"), note
            np.testing.assert_allclose(
                scores.set_index("seed")["score"], final_scores(run, k=1), rtol=1e-6
            )
            (folder / "short.csv").unlink()  # keep only the full one for the next round
            (folder / "short.json").unlink()


def test_an_episode_on_a_bin_edge_lands_in_the_bin_it_closes(tmp_path):
    run = write_run(tmp_path, "r", algo="sac", seeds=(0,), total_steps=5_000)
    (run / "eval.csv").unlink()  # the curve then comes from episodes.csv
    top = 5_000
    edges = np.linspace(0.0, top, collect.CURVE_BINS + 1)
    steps = [int(edges[3]), int(edges[3]) + 1, 0, top]  # 300, 301, 0 and the last edge
    rows = [
        {"step": s, "seed": 0, "episode": i, "return": float(i), "length": 10}
        for i, s in enumerate(steps)
    ]
    header = (run / "episodes.csv").read_text().splitlines()[0].split(",")
    pd.DataFrame([{c: r.get(c, 1.0) for c in header} for r in rows]).to_csv(
        run / "episodes.csv", index=False
    )
    curve, source = collect.training_curve(load_run(run))
    assert source == "training episodes (episodes.csv)"
    at = dict(zip(curve["step"], curve["return"]))
    assert at[int(edges[3])] == 0.0  # step 300 closes bin 3: drawn at 300
    assert at[int(edges[4])] == 1.0  # step 301 opens bin 4
    assert at[int(edges[1])] == 2.0  # step 0: the first bin
    assert at[top] == 3.0
