"""`adarl train` on tasks beyond the paper's four (issue 53), from the command line: the issue's
report (`gym:HalfCheetah-v5` crashed at its first checkpoint) runs to the end, and bad input
(an unknown element, a parameter the model does not have, actions adarl cannot train, the resume
of an env whose state cannot be captured) is one line, exit 2, with nothing written."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from adarl.runs import checkpoints

TESTS = str(Path(__file__).parents[1])


def adarl(*args, cwd=None):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([TESTS, os.environ.get("PYTHONPATH", "")]))
    return subprocess.run(
        [sys.executable, "-m", "adarl.cli.main", *args],
        capture_output=True, text=True, env=env, cwd=cwd,
    )  # fmt: skip


def test_the_reported_gym_task_trains_past_its_checkpoints(tmp_path):
    run = tmp_path / "hc"
    done = adarl(
        "train", "--algo", "sac", "--preset", "smoke", "--task", "gym:HalfCheetah-v5",
        "--dynamics", "default", "--total-steps", "1000", "--checkpoint-every", "500",
        "--out", str(run), "--no-progress",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert (run / "DONE").read_text().strip() == "1000"
    assert len(checkpoints.checkpoint_dirs(run)) >= 1


@pytest.mark.parametrize(
    "flags, message",
    [
        (
            ["--task", "HalfCheetah-v5", "--dynamics", "fixed:body:nosuch.mass=2"],
            "unknown body 'nosuch'",
        ),
        (
            ["--task", "Swimmer-v5", "--dynamics", "fixed:torso_length=0.3"],
            "unknown Swimmer-v5 parameter",
        ),
        (["--task", "CartPole-v1"], "has actions Discrete"),
        (["--task", "NoSuch-v0"], "unknown task 'NoSuch-v0'"),
        (["--task", "hopper", "--env-kwargs", "xml_file=x.xml"], "apply to Gymnasium ids"),
        (["--task", "Swimmer-v5", "--env-kwargs", "no such=1"], "malformed env-kwargs"),
        (["--task", "Swimmer-v5", "--env-module", "no_such_module"], "cannot import env-module"),
        (
            ["--task", "Swimmer-v5", "--physics", "ompo"],
            "allowed for task 'Swimmer-v5': consistent",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, flags, message):
    done = adarl(
        "train", "--algo", "sac", "--preset", "smoke", *flags, "--out", str(tmp_path / "run")
    )
    assert done.returncode == 2, done.stderr[-2000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], done.stderr
    assert not (tmp_path / "run").exists()


def test_the_resume_of_an_env_whose_state_cannot_be_captured_is_refused(tmp_path):
    run = tmp_path / "drift"
    flags = [
        "train", "--algo", "sac", "--preset", "smoke", "--task", "adarltest/Drift-v0",
        "--env-module", "user_env", "--total-steps", "600", "--checkpoint-every", "300",
        "--no-progress", "--out", str(run),
    ]  # fmt: skip
    assert adarl(*flags).returncode == 0
    (run / "DONE").unlink()  # as if it had been killed after its last checkpoint
    before = sorted(p.name for p in run.rglob("*"))
    done = adarl("train", "--resume", str(run))
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "cannot resume this run exactly" in done.stderr and "Drift" in done.stderr
    assert sorted(p.name for p in run.rglob("*")) == before
