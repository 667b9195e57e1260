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
    done = adarl("train", "--resume", str(run), "--env-module", "user_env")
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "cannot resume this run exactly" in done.stderr and "Drift" in done.stderr
    assert sorted(p.name for p in run.rglob("*")) == before


def test_a_users_robot_gets_a_budget_that_cuts_and_says_so(tmp_path):
    """Issue 62, a user's own XML robot at a small budget: d_t and the warm-up follow
    --total-steps (1M steps' d_t of 200k would never cut in 2,000), the start line and the
    summary say so, config.yaml records the values, only the ball's mass varies and the summary
    suggests sweeping it over its training range."""
    import user_env

    from adarl.runs import folder
    from adarl.runs.logs import read_csv

    run = tmp_path / "bot"
    done = adarl(
        "train", "--algo", "adarl", "--task", user_env.ENV_ID, "--env-module", "user_env",
        "--env-kwargs", f"xml_file={user_env.write_xml(tmp_path)}",
        "--dynamics", "uniform:body:ball.mass=0.2..1.0", "--total-steps", "2000",
        "--eval-every", "1000", "--eval-episodes", "1", "--log-every", "500",
        "--checkpoint-every", "1000", "--buffer-size", "5000", "--batch-size", "64",
        "--no-progress", "--no-report", "--out", str(run),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    assert "warning" not in done.stderr
    lines = done.stdout.splitlines()
    facts = (
        "2 cuts of the rank, every 400 gradient steps (d_t = total-steps / 5), at steps 1,350, "
        "1,750; random-action warm-up for the first 100 steps (start-steps = 5% of total-steps, "
        "at most 10,000)"
    )
    assert lines[0] == f"start: adarl on {user_env.ENV_ID}, 1 seed x 2,000 steps; {facts}"
    assert f"budget: {facts}" in lines
    config = folder.load_config(run)  # stored, so a resume reads them, never recomputes them
    assert (config["truncate_every"], config["start_steps"]) == (400, 100)
    assert sorted({int(r["step"]) for r in read_csv(run / "truncations.csv")}) == [1350, 1750]
    episodes = read_csv(run / "episodes.csv")
    assert {float(r["p_mass_scale"]) for r in episodes} == {1.0}
    assert len({r["p_body:ball.mass"] for r in episodes}) > 3
    assert f"  adarl evaluate {run} --sweep body:ball.mass=0.2..1:9" in lines
    assert not any("--sweep mass_scale" in line for line in lines)
