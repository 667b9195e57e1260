"""`--physics`, `--model-version` and the `paper-ompo` preset: train flags, sweeps, `adarl tasks`,
bit-exact resume under ompo physics on v4 models, and one-line errors for bad input."""

import json
from pathlib import Path

import numpy as np
import pytest

from adarl.algos import registry
from adarl.cli.main import main
from adarl.errors import UsageError
from adarl.evaluation import evaluate
from adarl.results.runs import load_run
from adarl.runs import checkpoints
from adarl.runs.logs import read_csv
from adarl.sweeps import spec
from adarl.train import sac_learner


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--physics", "newton"], "unknown physics 'newton'; allowed: consistent, ompo"),
        (["--model-version", "v3"], "unknown model version 'v3'; allowed: v5, v4"),
        (["--algo", "rnac", "--physics", "mjspec"], "unknown physics 'mjspec'"),
        (["--algo", "rnac", "--model-version", "v6"], "unknown model version 'v6'"),
        (
            ["--task", "gym:Pendulum-v1", "--dynamics", "default", "--physics", "ompo"],
            "physics 'ompo' applies to hopper, walker2d, ant, humanoid; "
            "allowed for task 'gym:Pendulum-v1': consistent",
        ),
        (
            ["--task", "gym:Pendulum-v1", "--dynamics", "default", "--model-version", "v4"],
            "model version 'v4' applies to hopper, walker2d, ant, humanoid; "
            "allowed for 'gym:Pendulum-v1': v5",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(argv, needle, tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["train", *argv, "--preset", "smoke", "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err, err
    assert err.count("\n") == 1
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def build(argv):
    """The config `adarl train *argv` would train (argv: `--name value` pairs)."""
    flags = {name[2:].replace("-", "_"): text for name, text in zip(argv[::2], argv[1::2])}
    return registry.resolve_config(flags.pop("algo", "adarl"), flags.pop("preset", None), flags)


def test_paper_ompo_preset_and_flags():
    for algo in ("adarl", "sac-parseval", "rnac"):
        extra = ["--parseval-coef", "1e-4"] if algo == "sac-parseval" else []
        config = build(["--algo", algo, "--preset", "paper-ompo", *extra])
        assert (config.dynamics, config.physics, config.model_version) == ("ompo", "ompo", "v4")
    default = build(["--algo", "adarl"])
    assert (default.dynamics, default.physics, default.model_version) == (
        "paper",
        "consistent",
        "v5",
    )
    flags = build(["--physics", "ompo", "--model-version", "v4", "--task", "walker2d"])
    assert (flags.physics, flags.model_version) == ("ompo", "v4")


def test_sweep_yaml_takes_the_preset_and_the_fields():
    base = {"tasks": ["hopper", "walker2d"], "seeds": "0-1", "budget": 1000}
    sweep = spec.parse({**base, "algos": ["adarl", "sac", "rnac"], "preset": "paper-ompo"})
    for unit in sweep.units:
        assert (unit.config.physics, unit.config.model_version) == ("ompo", "v4"), unit.id
        assert unit.config.dynamics == "ompo"
    sweep = spec.parse(
        {**base, "algos": ["sac"], "overrides": {"physics": "ompo", "model_version": "v4"}}
    )
    args = list(sweep.units[0].train_args)
    assert args[args.index("--physics") + 1] == "ompo"
    assert args[args.index("--model-version") + 1] == "v4"
    with pytest.raises(UsageError, match="unknown physics 'newton'"):
        spec.parse({**base, "algos": ["sac"], "overrides": {"physics": "newton"}})


def test_tasks_shows_versions_and_nominal_masses(capsys):
    assert main(["tasks", "hopper"]) == 0
    out = capsys.readouterr().out
    assert "model versions: v5 Hopper-v5 obs 11 (default), v4 Hopper-v4 obs 11" in out
    assert "masses at the nominal point (kg), physics consistent / ompo:" in out
    assert "torso 6.807 / 3.665" in out and "foot 9.726 / 5.316" in out
    assert "device task (MJX, adarl.device): same physics as MuJoCo C" in out
    assert main(["tasks", "ant", "--json"]) == 0
    (ant,) = json.loads(capsys.readouterr().out)
    assert ant["nominal_masses"]["consistent"] == ant["nominal_masses"]["ompo"]
    assert ant["device"].startswith("differs from MuJoCo C from the first contact")
    assert main(["tasks", "ant"]) == 0
    assert "v4 Ant-v4 obs 27" in capsys.readouterr().out


class Crash(Exception):
    pass


def test_resume_is_bit_exact_under_ompo_physics_and_v4_models(tmp_path, monkeypatch):
    argv = ["--preset", "smoke", "--task", "walker2d", "--dynamics", "ompo"]
    argv += ["--physics", "ompo", "--model-version", "v4", "--total-steps", "1500"]
    argv += ["--checkpoint-every", "500", "--eval-every", "500", "--no-progress"]
    assert main(["train", *argv, "--out", str(tmp_path / "full")]) == 0

    original = sac_learner.SACLearner.env_step

    def crashing(self, lane, t, actions, run):
        original(self, lane, t, actions, run)
        if t == 1_200:  # after the checkpoint at 1000, with several episodes since
            raise Crash

    monkeypatch.setattr(sac_learner.SACLearner, "env_step", crashing)
    with pytest.raises(Crash):
        main(["train", *argv, "--out", str(tmp_path / "crashed")])
    monkeypatch.setattr(sac_learner.SACLearner, "env_step", original)
    assert main(["train", "--resume", str(tmp_path / "crashed"), "--no-progress"]) == 0

    full, crashed = tmp_path / "full", tmp_path / "crashed"
    config = (crashed / "config.yaml").read_text()
    assert "physics: ompo" in config and "model_version: v4" in config
    for name in ("episodes.csv", "train.csv", "eval.csv"):
        rows = [read_csv(Path(d) / name) for d in (full, crashed)]
        drop = ("steps_per_s",)
        a, b = ([{k: v for k, v in r.items() if k not in drop} for r in rs] for rs in rows)
        assert a == b, name
    a, _ = checkpoints.load_checkpoint(checkpoints.latest_checkpoint(full))
    b, _ = checkpoints.load_checkpoint(checkpoints.latest_checkpoint(crashed))
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)

    # `adarl evaluate` runs the policies on the run's own physics and models (OMPO's Hopper
    # protocol, the default geometry, here on Walker2d-v4)
    units = evaluate.plan([load_run(full)], evaluate.EvalSpec(dynamics="default"))
    assert dict(units[0].env) == {"physics": "ompo", "model_version": "v4"}
    argv = ["evaluate", str(full), "--dynamics", "default", "--episodes", "1", "--workers", "1"]
    assert main([*argv, "--max-episode-steps", "5"]) == 0
    assert (full / "evaluations" / "default.csv").exists()
