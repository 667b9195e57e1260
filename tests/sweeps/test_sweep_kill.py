"""Kills: a unit's training process killed after its first checkpoint is retried and resumes;
a sweep killed mid-run takes its units down with it, leaves a valid manifest, and the same
command resumes it; a sweep stopped by SIGTERM stops its units with a checkpoint where each
stops, and the same command resumes from there. Either way the results are complete and nothing
is written twice."""

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from adarl.cli.main import main
from adarl.sweeps import worker

UNIT = "hopper/sac/seeds-0-1"
MARKER = Path(".state") / "hopper__sac__seeds-0-1.started.json"
BUDGET = 1500


def _start_sweep(spec: Path, out: Path, *flags) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "adarl.cli.main", "sweep", str(spec), "--out", str(out), *flags],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def _wait_for_checkpoint(out: Path, sweep: subprocess.Popen, timeout_s: float = 150) -> int:
    """The pid of the unit's training process, once its run has a complete checkpoint."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert sweep.poll() is None, sweep.stdout.read()
        if list((out / UNIT / "checkpoints").glob("step_*/meta.json")):
            assert not (out / UNIT / "DONE").exists()
            return json.loads((out / MARKER).read_text())["pid"]
        time.sleep(0.05)
    sweep.kill()
    raise AssertionError("no checkpoint in time")


def _gone(pid: int, timeout_s: float = 10) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def test_a_killed_unit_is_retried_and_resumes(tmp_path, write_spec, assert_complete):
    out = tmp_path / "sweep"
    sweep = _start_sweep(write_spec(tmp_path / "s.yaml", budget=BUDGET), out, "--max-retries", "1")
    os.kill(_wait_for_checkpoint(out, sweep), signal.SIGKILL)
    text, _ = sweep.communicate(timeout=150)
    assert sweep.returncode == 0, text
    assert "failed   attempt 1: killed by SIGKILL" in text
    assert "running  attempt 2, resuming from step" in text
    record = json.loads((out / "manifest.json").read_text())["units"][UNIT]
    assert (record["status"], record["attempts"]) == ("done", 2)
    assert_complete(out / UNIT, BUDGET)


def test_a_killed_sweep_resumes_when_run_again(tmp_path, capsys, write_spec, assert_complete):
    out = tmp_path / "sweep"
    spec = write_spec(tmp_path / "s.yaml", budget=BUDGET)
    sweep = _start_sweep(spec, out)
    trainer = _wait_for_checkpoint(out, sweep)
    sweep.kill()
    sweep.wait()
    assert _gone(trainer)  # the unit died with the sweep: no orphan keeps writing
    record = json.loads((out / "manifest.json").read_text())["units"][UNIT]  # valid JSON
    assert record["status"] in ("queued", "running") and record["attempts"] == 1

    assert main(["sweep", str(spec), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "running  attempt 2, resuming from step" in text
    assert "1 units, 1 done (0 before this run), 0 failed" in text
    assert_complete(out / UNIT, BUDGET)
    assert not list(out.glob("**/*.tmp")) and not list(out.glob(".*.tmp"))


def test_a_sweep_stopped_by_sigterm_checkpoints_its_units_and_resumes_from_there(
    tmp_path, capsys, write_spec, assert_complete
):
    out = tmp_path / "sweep"
    spec = write_spec(tmp_path / "s.yaml", budget=BUDGET)
    sweep = _start_sweep(spec, out)
    trainer = _wait_for_checkpoint(out, sweep)
    sweep.send_signal(signal.SIGTERM)
    text, _ = sweep.communicate(timeout=150)
    assert sweep.returncode == 130, text  # as Ctrl-C
    assert "sweep interrupted; run the same command again to resume it" in text
    assert _gone(trainer)
    log = (out / "logs" / "hopper__sac__seeds-0-1.log").read_text()
    stopped = re.search(r"adarl train: stopped by SIGTERM at step ([\d,]+) with a checkpoint", log)
    assert stopped, log
    step = int(stopped.group(1).replace(",", ""))
    newest = sorted((out / UNIT / "checkpoints").glob("step_*/meta.json"))[-1]
    assert json.loads(newest.read_text())["step"] == step < BUDGET
    record = json.loads((out / "manifest.json").read_text())["units"][UNIT]
    assert (record["status"], record["error"]) == ("queued", "interrupted")

    assert main(["sweep", str(spec), "--out", str(out)]) == 0
    assert f"running  attempt 2, resuming from step {step:,}" in capsys.readouterr().out
    assert_complete(out / UNIT, BUDGET)


def test_a_unit_held_by_another_process_is_not_trained_twice(tmp_path):
    lock = tmp_path / "unit.lock"
    with open(lock, "a") as held:
        import fcntl

        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        code = worker.main(
            [
                "--run-dir",
                str(tmp_path / "run"),
                "--lock",
                str(lock),
                "--marker",
                str(tmp_path / "m.json"),
                "--attempt",
                "1",
                '--unit={"algo": "sac", "preset": null, "flags": {}}',
            ]
        )
    assert code == worker.EXIT_BUSY
    assert not (tmp_path / "run").exists() and not (tmp_path / "m.json").exists()
