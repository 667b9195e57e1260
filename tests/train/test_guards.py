"""The divergence watch: non-finite values stop a run, or warn once with --on-divergence continue."""

import numpy as np
import pytest

from adarl.errors import Diverged
from adarl.train.guards import DivergenceWatch


def test_divergence_watch_names_step_seeds_and_quantity(tmp_path, capsys):
    watch = DivergenceWatch(tmp_path, "stop")
    watch.check(10)  # nothing noted: nothing happens
    watch.note_values("loss_q", [0, 3, 5], [1.0, np.inf, np.nan])
    watch.note_values("actor parameters", [0, 3, 5], np.ones((3, 4)))
    with pytest.raises(Diverged) as err:
        watch.check(500)
    assert err.value.exit_code == 3
    assert "step 500" in str(err.value) and "loss_q (seeds 3, 5)" in str(err.value)
    assert "actor" not in str(err.value)
    keep_going = DivergenceWatch(tmp_path, "continue")
    for step in (500, 1000):
        keep_going.note("episode return", [1])
        keep_going.check(step)
    err_text = capsys.readouterr().err
    assert err_text.count("\n") == 1 and "episode return (seed 1)" in err_text


def test_divergence_is_noted_for_one_non_finite_value_among_finite_ones(tmp_path):
    watch = DivergenceWatch(tmp_path, "stop")
    values = np.ones((3, 5))
    values[1, 3] = np.nan  # seed 7: one value of five
    values[2, 0] = -np.inf  # seed 9: one value of five
    watch.note_values("critic parameters", [5, 7, 9], values)
    assert watch.found == {"critic parameters": [7, 9]}
    watch.note_values("loss_q", [5, 7, 9], [1.0, 2.0, 3.0])
    assert "loss_q" not in watch.found
    with pytest.raises(Diverged, match=r"critic parameters \(seeds 7, 9\)"):
        watch.check(100)
