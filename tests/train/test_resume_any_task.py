"""Exact resume on tasks beyond the paper's four (issue 53): a generic Gymnasium MuJoCo task under
uniform generic and addressed parameters, and a user's own robot (its XML written by the test)
through the CLI (`--env-module`, `--env-kwargs`, SIGKILL) and through `adarl.train(env_fn=...)`,
each killed with SIGKILL between two checkpoints and resumed, write what the uninterrupted run
writes. A
plain env whose state cannot be captured trains and checkpoints, and its resume is refused in
one line. `pytest -m alltasks` runs every Gymnasium MuJoCo v5 task the same way (minutes)."""

import functools
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import user_env
from test_resume_every_algorithm import Crash, assert_same_run

import adarl
from adarl.algos import registry
from adarl.runs import checkpoints, folder
from adarl.runs.layout import CHECKPOINT_DIR
from adarl.runs.logs import read_csv
from adarl.train.trainers import trainer

TINY = {
    "seeds": (0,),
    "total_steps": 400,
    "start_steps": 100,
    "update_after": 100,
    "checkpoint_every": 200,
    "eval_every": 200,
    "log_every": 100,
    "truncate_every": 150,
    "warmup_steps": 50,
}
TESTS = str(Path(__file__).parents[1])


# Trains a config in a process of its own that SIGKILLs itself as its second regular checkpoint
# starts (the first is complete): a kill at a fixed point of the run, nothing flushed or closed.
KILLED_AT_SECOND_CHECKPOINT = """
import json, os, signal, sys
from adarl.algos import registry
from adarl.runs import checkpoints
from adarl.runs.layout import CHECKPOINT_DIR
from adarl.train.trainers import trainer

algo, fields, run_dir = json.loads(sys.argv[1])
original, saved = checkpoints.save_checkpoint, []

def save_or_die(*args, **kwargs):
    if kwargs.get("folder", CHECKPOINT_DIR) == CHECKPOINT_DIR:
        if saved:
            os.kill(os.getpid(), signal.SIGKILL)
        saved.append(True)
    return original(*args, **kwargs)

checkpoints.save_checkpoint = save_or_die
trainer(algo)(registry.resolve_config(algo, "smoke", fields), run_dir, progress=False)
"""


def _train_killed_then_resumed(config, run_dir, fields):
    """Train `config` (`fields` on the smoke preset) into `run_dir` in a subprocess killed with
    SIGKILL before its second checkpoint, then resume it here."""
    import json

    argv = json.dumps([config.algo, fields, str(run_dir)])
    cmd = [sys.executable, "-c", KILLED_AT_SECOND_CHECKPOINT, argv]
    killed = subprocess.run(cmd, capture_output=True, text=True, env=_cli()[1])
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    assert len(checkpoints.checkpoint_dirs(run_dir)) == 1 and not (run_dir / "DONE").exists()
    _, back = folder.config_from_run(run_dir)
    assert back == config
    trainer(config.algo)(back, run_dir, resume=True, progress=False)


def _train_crashed_then_resumed(config, run_dir, monkeypatch):
    """Train `config` into `run_dir` in this process, dying (an exception) as its second
    checkpoint starts, then resume it: for an `env_fn` task, which only this process has
    registered (the CLI's own robot is killed with SIGKILL above)."""
    saved, original = [], checkpoints.save_checkpoint

    def save_then_crash(*args, **kwargs):
        if kwargs.get("folder", CHECKPOINT_DIR) != CHECKPOINT_DIR:
            return original(*args, **kwargs)
        if saved:
            raise Crash
        saved.append(original(*args, **kwargs))
        return saved[-1]

    monkeypatch.setattr(checkpoints, "save_checkpoint", save_then_crash)
    with pytest.raises(Crash):
        trainer(config.algo)(config, run_dir, progress=False)
    monkeypatch.setattr(checkpoints, "save_checkpoint", original)
    _, back = folder.config_from_run(run_dir)
    assert back == config
    trainer(config.algo)(back, run_dir, resume=True, progress=False)


@pytest.mark.parametrize(
    "task, dynamics",
    [("HalfCheetah-v5", "uniform:mass_scale=0.7..1.3,body:torso.mass=4..9")],
)
def test_a_generic_task_resumes_exactly_after_sigkill(task, dynamics, tmp_path):
    fields = {**TINY, "task": task, "dynamics": dynamics}
    config = registry.resolve_config("adarl", "smoke", fields)
    trainer("adarl")(config, tmp_path / "full", progress=False)
    _train_killed_then_resumed(config, tmp_path / "killed", fields)
    assert_same_run(tmp_path / "full", tmp_path / "killed", "adarl")
    masses = {float(r["p_body:torso.mass"]) for r in read_csv(tmp_path / "full" / "episodes.csv")}
    assert len(masses) > 1 and all(4 <= m <= 9 for m in masses)  # varied by episode, logged


def _cli(*args, env=None):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([TESTS, os.environ.get("PYTHONPATH", "")]))
    return [sys.executable, "-m", "adarl.cli.main", *args], env


def test_a_users_own_xml_trains_varies_and_resumes_after_sigkill_from_the_cli(tmp_path):
    xml = user_env.write_xml(tmp_path)
    flags = [
        "train", "--algo", "adarl", "--preset", "smoke", "--task", user_env.ENV_ID,
        "--env-module", "user_env", "--env-kwargs", f"xml_file={xml}",
        "--dynamics", "uniform:body:ball.mass=0.5..2,geom:floor.friction=0.3..1.5",
        "--total-steps", "1500", "--checkpoint-every", "300", "--eval-every", "500",
        "--log-every", "100", "--truncate-every", "300", "--warmup-steps", "50",
        "--start-steps", "100", "--update-after", "100", "--no-progress",
    ]  # fmt: skip
    cmd, env = _cli(*flags, "--out", str(tmp_path / "full"))
    full = subprocess.run(cmd, env=env, capture_output=True, text=True)
    assert full.returncode == 0, full.stderr
    cmd, env = _cli(*flags, "--out", str(tmp_path / "killed"))
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300
    while len(checkpoints.checkpoint_dirs(tmp_path / "killed")) < 2:
        assert time.time() < deadline and proc.poll() is None, "ended before it could be killed"
        time.sleep(0.1)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (tmp_path / "killed" / "DONE").exists()
    # the run names the module that registers it, which adarl imports only when the user
    # names it too (issue 61): without, the resume says so in one line; without the module on
    # the path, too
    for named, environ in (([], env), (["--env-module", "user_env"], dict(os.environ))):
        cmd, _ = _cli("train", "--resume", str(tmp_path / "killed"), *named)
        bare = subprocess.run(cmd, capture_output=True, text=True, env=environ)
        assert bare.returncode == 2 and len(bare.stderr.strip().splitlines()) == 1, bare.stderr
        assert "user_env" in bare.stderr
    cmd, env = _cli("train", "--resume", str(tmp_path / "killed"), "--env-module", "user_env")
    cmd.append("--no-progress")
    resumed = subprocess.run(cmd, env=env, capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert_same_run(tmp_path / "full", tmp_path / "killed", "adarl")
    masses = {r["p_body:ball.mass"] for r in read_csv(tmp_path / "full" / "episodes.csv")}
    assert len(masses) > 3


def test_a_users_own_env_fn_trains_and_resumes_exactly_from_python(tmp_path, monkeypatch):
    xml = user_env.write_xml(tmp_path)
    make_robot = functools.partial(user_env.PointBot, xml_file=str(xml))
    fields = {**TINY, "seeds": 0, "dynamics": "uniform:body:ball.mass=0.5..2"}
    run = adarl.train("adarl", env_fn=make_robot, env_name="PointBot", out=tmp_path / "full",
                      preset="smoke", **fields)  # fmt: skip
    assert run.path == tmp_path / "full" and run.config.task == "adarl-fn/PointBot-v0"
    assert set(run.final_ranks) == {"actor_1", "q1_1", "q2_1"}
    policy = adarl.load_policy(run.path, seed=0)
    assert policy(run_obs := user_env.np.zeros(4)).shape == (2,) and run_obs.shape == (4,)
    _train_crashed_then_resumed(run.config, tmp_path / "killed", monkeypatch)
    assert_same_run(tmp_path / "full", tmp_path / "killed", "adarl")
    with pytest.raises(adarl.UsageError, match="drop total_steps"):
        adarl.train(env_fn=make_robot, resume=tmp_path / "killed", total_steps=5)


def test_bad_input_to_the_python_api_is_a_usage_error_and_writes_nothing(tmp_path):
    with pytest.raises(adarl.UsageError, match="unknown body 'nosuch'"):
        adarl.train("sac", task="HalfCheetah-v5", out=tmp_path / "run",
                    dynamics="fixed:body:nosuch.mass=1")  # fmt: skip
    with pytest.raises(adarl.UsageError, match="has actions Discrete"):
        adarl.train("sac", task="CartPole-v1", out=tmp_path / "run")
    with pytest.raises(adarl.UsageError, match="give task or env_fn"):
        adarl.train("sac", task="Swimmer-v5", env_fn=user_env.Drift)
    assert not (tmp_path / "run").exists()


def test_a_plain_env_whose_state_cannot_be_captured_refuses_its_resume(tmp_path):
    config = registry.resolve_config(
        "sac", "smoke", {**TINY, "task": user_env.DRIFT_ID, "total_steps": 300}
    )
    trainer("sac")(config, tmp_path / "run", progress=False)  # checkpoints without a crash
    (tmp_path / "run" / "DONE").unlink()
    with pytest.raises(adarl.UsageError, match="cannot resume this run exactly.*Drift"):
        trainer("sac")(config, tmp_path / "run", resume=True, progress=False)


MUJOCO_V5 = (
    "Ant-v5", "HalfCheetah-v5", "Hopper-v5", "Humanoid-v5", "HumanoidStandup-v5",
    "InvertedDoublePendulum-v5", "InvertedPendulum-v5", "Pusher-v5", "Reacher-v5",
    "Swimmer-v5", "Walker2d-v5",
)  # fmt: skip


@pytest.mark.alltasks
@pytest.mark.parametrize("algo", ["adarl", "sac"])
@pytest.mark.parametrize("task", MUJOCO_V5)
def test_every_gymnasium_mujoco_task_trains_and_resumes_exactly(task, algo, tmp_path):
    element = folder_element(task)
    fields = {**TINY, "task": task, "dynamics": f"uniform:mass_scale=0.8..1.2,{element}"}
    if algo == "sac":
        fields.pop("truncate_every"), fields.pop("warmup_steps")
    config = registry.resolve_config(algo, "smoke", fields)
    trainer(algo)(config, tmp_path / "full", progress=False)
    _train_killed_then_resumed(config, tmp_path / "killed", fields)
    assert_same_run(tmp_path / "full", tmp_path / "killed", algo)


def folder_element(task: str) -> str:
    """An addressed parameter of `task`'s model, varied around its default: its first named
    body's mass (x0.8 to x1.2)."""
    from adarl.envs import get_task
    from adarl.envs.elements import address_default, element_names

    xml = get_task(task).xml_path
    body = element_names(xml)["body"][0]
    mass = address_default(xml, f"body:{body}.mass")
    return f"body:{body}.mass={0.8 * mass!r}..{1.2 * mass!r}"
