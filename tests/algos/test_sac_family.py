"""Every SAC-family algorithm runs a few hundred steps for one and several seeds, and resumes."""

import numpy as np
import pytest

from adarl.algos import sac_config
from adarl.algos.sac_config import SAC_FAMILY
from adarl.runs.logs import read_csv
from adarl.train import sac_learner, trainers

# adarl runs, crashes and resumes in tests/train/test_sac_learner.py
ALGOS = {
    "sac": {},
    "sac-fixed-rank": {"rank": 7},
    "sac-parseval": {},
    "sac-sparse": {"sparse_width": 256},  # narrower than the default 1024 to keep the test fast
}


class Crash(Exception):
    pass


@pytest.mark.parametrize("algo", ALGOS)
def test_runs_and_resumes(algo, tmp_path, monkeypatch):
    # the smoke preset's learner settings (shared compilations with the other tests); only the
    # run's schedule is shorter
    values = {
        **SAC_FAMILY[algo],
        **sac_config.PRESETS["smoke"],
        "algo": algo,
        "task": "hopper",
        "seeds": (0, 1),
        "total_steps": 400,
        "start_steps": 100,
        "update_after": 100,
        "checkpoint_every": 200,
        "eval_every": 400,
        "log_every": 100,
        **ALGOS[algo],
    }
    config = sac_config.SACConfig(**values)
    original = sac_learner.SACLearner.env_step

    def crashing(self, lane, t, actions, run):
        original(self, lane, t, actions, run)
        if t == 300:
            raise Crash

    monkeypatch.setattr(sac_learner.SACLearner, "env_step", crashing)
    with pytest.raises(Crash):
        trainers.train(config, tmp_path / "run", progress=False)
    monkeypatch.setattr(sac_learner.SACLearner, "env_step", original)
    trainers.train(config, tmp_path / "run", resume=True, progress=False)
    rows = read_csv(tmp_path / "run" / "train.csv")
    assert [int(r["step"]) for r in rows] == [100, 100, 200, 200, 300, 300, 400, 400]
    last = rows[-1]
    assert np.isfinite(float(last["loss_q"])) and np.isfinite(float(last["loss_pi"]))
    if algo == "sac-parseval":
        assert float(last["parseval_penalty"]) > 0
    if algo == "sac-sparse":
        assert 0.0 < float(last["active_fraction"]) < 1.0
    if algo == "sac-fixed-rank":
        assert {last["rank_actor_1"], last["rank_q1_1"], last["rank_q2_1"]} == {"7"}
    assert (tmp_path / "run" / "DONE").exists()
    eval_rows = read_csv(tmp_path / "run" / "eval.csv")
    assert {r["seed"] for r in eval_rows} == {"0", "1"}


@pytest.mark.parametrize("algo", ["sac-fixed-rank", "sac-parseval", "sac-sparse"])
def test_runs_with_one_seed(algo, tmp_path):
    """One seed alone (sac and adarl alone are covered in tests/train/test_sac_learner.py)."""
    values = {
        **SAC_FAMILY[algo],
        **sac_config.PRESETS["smoke"],
        "algo": algo,
        "task": "hopper",
        "seeds": (0,),
        "total_steps": 200,
        "start_steps": 100,
        "update_after": 100,
        "checkpoint_every": 200,
        "eval_every": 200,
        "log_every": 100,
        **ALGOS[algo],
    }
    trainers.train(sac_config.SACConfig(**values), tmp_path / "run", progress=False)
    rows = read_csv(tmp_path / "run" / "train.csv")
    assert [int(r["step"]) for r in rows] == [100, 200]
    assert all(np.isfinite(float(r["loss_q"])) for r in rows)
    assert (tmp_path / "run" / "checkpoints").is_dir() and (tmp_path / "run" / "DONE").exists()
