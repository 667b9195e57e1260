"""Reading run folders into tables: rank histories at the exact truncation steps."""

import pandas as pd

from adarl.evaluation import collect
from adarl.evaluation.runs import load_run
from adarl.evaluation.synthetic import write_run


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
