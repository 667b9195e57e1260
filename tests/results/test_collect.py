"""Reading run folders into tables: rank histories at the exact truncation steps."""

import pandas as pd
import pytest
from synthetic_runs import write_run

from adarl.results import collect
from adarl.results.runs import load_run


def test_rank_history_changes_at_the_truncation_step_not_the_next_log_row(tmp_path):
    run_dir = write_run(tmp_path, "run", algo="adarl", seeds=(0, 1))
    cuts = pd.read_csv(run_dir / "truncations.csv")
    logged = pd.read_csv(run_dir / "train.csv")["step"]
    cuts["step"] -= 50  # between two logging points (every 500 steps), before the one that shows it
    cuts.to_csv(run_dir / "truncations.csv", index=False)
    history = collect.rank_history(load_run(run_dir))
    assert not history.duplicated(["step", "seed", "layer"]).any()
    assert history.equals(history.sort_values(["step", "seed", "layer"]).reset_index(drop=True))
    for cut in cuts.itertuples():
        rows = history[(history["seed"] == cut.seed) & (history["layer"] == cut.layer)]
        at = rows[rows["step"] == cut.step]["rank"]
        before = rows[rows["step"] < cut.step]["rank"]
        assert at.tolist() == [cut.new_rank] and before.iloc[-1] == cut.old_rank
    assert set(history["step"]) == set(logged) | set(cuts["step"])


def test_last_evaluations_by_hand():
    # seed 0: evaluations at steps 1..4 with episode means 10, 20, 30, 40; seed 1: two only
    rows = [(step, 0, e, 10.0 * step + (1 if e else -1)) for step in (1, 2, 3, 4) for e in (0, 1)]
    rows += [(1, 1, 0, 7.0), (2, 1, 0, 9.0)]
    log = pd.DataFrame(rows, columns=["step", "seed", "episode", "return"])
    got = collect.last_evaluations(log, 3).set_index("seed")
    assert got.loc[0, "score"] == (20 + 30 + 40) / 3 and got.loc[0, "evaluations"] == 3
    assert (got.loc[0, "first_step"], got.loc[0, "last_step"], got.loc[0, "episodes"]) == (2, 4, 2)
    assert got.loc[1, "score"] == 8.0 and got.loc[1, "evaluations"] == 2  # fewer than k: all
    assert got.loc[1, "episodes"] == 1
    assert collect.last_evaluations(log, 1).set_index("seed").loc[0, "score"] == 40.0


def test_score_dynamics_prefers_nominal_else_the_first_logged():
    log = pd.DataFrame({"dynamics": ["fixed:a=1", "nominal", "fixed:a=1"]})
    assert collect.score_dynamics(log) == "nominal"
    assert collect.score_dynamics(log.iloc[[0, 2]]) == "fixed:a=1"
    assert collect.score_dynamics(pd.DataFrame()) is None


def test_last_k_scores_of_a_run_use_its_nominal_evaluations(tmp_path):
    run_dir = write_run(tmp_path, "run", algo="sac", seeds=(0, 1), n_evals=6)
    log = pd.read_csv(run_dir / "eval.csv")
    other = log.assign(dynamics="fixed:torso_length=0.3", **{"return": 0.0})
    pd.concat([log, other]).to_csv(run_dir / "eval.csv", index=False)  # ignored: not nominal
    scores, note = collect.last_k_scores(load_run(run_dir), 5)
    expected = log.groupby(["seed", "step"])["return"].mean().groupby("seed").tail(5)
    assert scores["score"].tolist() == pytest.approx(expected.groupby("seed").mean().tolist())
    assert note == "eval.csv, mean of the last 5 evaluation(s) (steps 3333–10000, nominal)"


def test_last_k_is_the_latest_evaluations_not_the_best():
    # issue 38: returns that dip late; the rows out of step order, as a resumed log never is
    means = {1: 10.0, 2: 50.0, 3: 40.0, 4: 5.0}
    rows = [(step, 0, e, means[step] + (2 if e else -2)) for step in (3, 1, 4, 2) for e in (0, 1)]
    log = pd.DataFrame(rows, columns=["step", "seed", "episode", "return"])
    got = collect.last_evaluations(log, 2).set_index("seed").loc[0]
    assert got["score"] == (40.0 + 5.0) / 2  # steps 3 and 4; the best two would give 45
    assert (got["first_step"], got["last_step"], got["evaluations"]) == (3, 4, 2)
    assert collect.last_evaluations(log, 1).set_index("seed").loc[0, "score"] == 5.0
