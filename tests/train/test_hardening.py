"""Both trainers (the SAC-family loop and RNAC's) under the failures of docs/reliability.md, through
`adarl train`: a run folder another process writes, a damaged newest checkpoint, a full disk
during a checkpoint, divergence, and a hand-edited config.yaml."""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from adarl.algos import rnac_config, sac_config
from adarl.algos.sac_config import SAC_FAMILY
from adarl.cli.main import main
from adarl.runs import checkpoints, npz
from adarl.runs.layout import LOCK_FILE
from adarl.runs.logs import read_csv
from adarl.train import trainers

HOLD = """
import sys, time
from adarl.runs.lock import RunLock
lock = RunLock(sys.argv[1])
lock.acquire(new=False)
print("locked", flush=True)
time.sleep(600)
"""


def csv_rows(run_dir: Path, name: str) -> list[dict]:
    rows = read_csv(run_dir / name)
    for row in rows:
        row.pop("steps_per_s", None)
    return rows


def final_arrays(run_dir: Path) -> dict:
    return checkpoints.load_checkpoint(checkpoints.latest_checkpoint(run_dir))[0]


def unfinished_copy(base: Path, dest: Path, drop_last_checkpoint: bool = False) -> Path:
    """A copy of a finished run as a kill before its end would leave it (no DONE)."""
    shutil.copytree(base, dest)
    (dest / "DONE").unlink()
    if drop_last_checkpoint:
        shutil.rmtree(checkpoints.checkpoint_dirs(dest)[-1])
    return dest


def snapshot(run_dir: Path) -> dict:
    return {
        str(p.relative_to(run_dir)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in sorted(run_dir.rglob("*"))
    }


@pytest.fixture(scope="module")
def sac_run(tmp_path_factory) -> Path:
    """A finished two-seed SAC smoke run with checkpoints at steps 500 and 1000."""
    values = {**SAC_FAMILY["sac"], **sac_config.PRESETS["smoke"], "algo": "sac", "task": "hopper"}
    config = sac_config.SACConfig(
        **{**values, "seeds": (0, 1), "total_steps": 1000, "checkpoint_every": 500}
    )
    run_dir = tmp_path_factory.mktemp("sac") / "run"
    trainers.train(config, run_dir, progress=False)
    assert [p.name for p in checkpoints.checkpoint_dirs(run_dir)] == [
        "step_000000000500",
        "step_000000001000",
    ]
    return run_dir


def unlocked(snap: dict) -> dict:
    """A snapshot without the lock file (taking the lock writes the PID into it)."""
    return {name: stat for name, stat in snap.items() if name != LOCK_FILE}


def resume(run_dir: Path) -> int:
    return main(["train", "--resume", str(run_dir), "--no-progress"])


# ----------------------------------------------------------------------------- the lock
def test_resume_of_a_run_another_process_writes_is_refused_and_writes_nothing(
    sac_run, tmp_path, capsys
):
    run_dir = unfinished_copy(sac_run, tmp_path / "run")
    (run_dir / LOCK_FILE).touch()
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(run_dir)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        before = snapshot(run_dir)
        assert resume(run_dir) == 2
        err = capsys.readouterr().err
        assert f"pid {holder.pid}" in err and err.count("\n") == 1, err
        assert snapshot(run_dir) == before
    finally:
        os.kill(holder.pid, signal.SIGKILL)  # its lock goes with it
        holder.wait()
    assert resume(run_dir) == 0
    assert (run_dir / "DONE").exists()


# ----------------------------------------------------------------------------- checkpoints
def test_a_damaged_newest_checkpoint_is_reported_and_the_older_one_resumes_exactly(
    sac_run, tmp_path, capsys
):
    run_dir = unfinished_copy(sac_run, tmp_path / "run")
    newest = checkpoints.checkpoint_dirs(run_dir)[-1] / "arrays.npz"
    newest.write_bytes(newest.read_bytes()[:5000])  # a short file
    assert resume(run_dir) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "step_000000001000" in err and "older" in err, err
    for name in ("episodes.csv", "train.csv", "eval.csv"):
        assert csv_rows(run_dir, name) == csv_rows(sac_run, name), name
    full, resumed = final_arrays(sac_run), final_arrays(run_dir)
    assert full.keys() == resumed.keys()
    for key in full:
        np.testing.assert_array_equal(full[key], resumed[key], err_msg=key)


def test_no_intact_checkpoint_is_exit_2(sac_run, tmp_path, capsys):
    run_dir = unfinished_copy(sac_run, tmp_path / "run")
    for path in checkpoints.checkpoint_dirs(run_dir):
        (path / "arrays.npz").write_bytes(b"garbage")
    assert resume(run_dir) == 2
    assert "no intact checkpoint" in capsys.readouterr().err.splitlines()[-1]
    assert not (run_dir / "DONE").exists()


def test_a_config_error_aborts_the_resume_before_a_damaged_checkpoint_is_renamed(
    sac_run, tmp_path, capsys
):
    run_dir = unfinished_copy(sac_run, tmp_path / "run")
    newest = checkpoints.checkpoint_dirs(run_dir)[-1]
    (newest / "arrays.npz").write_bytes(b"garbage")
    doc = yaml.safe_load((run_dir / "config.yaml").read_text())
    (run_dir / "config.yaml").write_text(yaml.safe_dump({**doc, "seeds": [0, 2]}, sort_keys=False))
    before = snapshot(run_dir)
    assert resume(run_dir) == 2
    assert "field 'seeds'" in capsys.readouterr().err.splitlines()[-1]
    assert unlocked(snapshot(run_dir)) == unlocked(before)  # the damaged one keeps its name
    assert not list((run_dir / "checkpoints").glob("damaged_*"))


def test_a_learner_error_aborts_the_resume_before_a_damaged_checkpoint_is_renamed(
    sac_run, tmp_path, capsys
):
    """The learner (environments, evaluation dynamics, memory) is built before any checkpoint is
    read: an edit a resume allows but the learner refuses changes nothing."""
    run_dir = unfinished_copy(sac_run, tmp_path / "run")
    newest = checkpoints.checkpoint_dirs(run_dir)[-1]
    (newest / "arrays.npz").write_bytes(b"garbage")
    doc = yaml.safe_load((run_dir / "config.yaml").read_text())
    doc["eval_dynamics"] = ["nominal", "no-such-dynamics"]  # eval_dynamics may change on resume
    (run_dir / "config.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    before = snapshot(run_dir)
    assert resume(run_dir) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no-such-dynamics" in err, err  # no "damaged" warning first
    assert unlocked(snapshot(run_dir)) == unlocked(before)
    assert not list((run_dir / "checkpoints").glob("damaged_*"))


def test_a_damaged_policy_file_is_a_damaged_checkpoint(sac_run, tmp_path, capsys):
    run_dir = unfinished_copy(sac_run, tmp_path / "run")
    newest = checkpoints.checkpoint_dirs(run_dir)[-1]
    data = bytearray((newest / "policy_seed_1.npz").read_bytes())
    data[len(data) // 2] ^= 0x01  # one flipped bit: only the checksum in meta.json sees it
    (newest / "policy_seed_1.npz").write_bytes(bytes(data))
    assert resume(run_dir) == 0
    err = capsys.readouterr().err
    assert "policy_seed_1.npz does not match its sha256" in err and err.count("\n") == 1, err
    assert (run_dir / "checkpoints" / f"damaged_{newest.name}").is_dir()
    assert csv_rows(run_dir, "eval.csv") == csv_rows(sac_run, "eval.csv")


def test_resume_of_a_run_whose_checkpoints_were_deleted_is_refused(sac_run, tmp_path, capsys):
    run_dir = unfinished_copy(sac_run, tmp_path / "run")
    shutil.rmtree(run_dir / "checkpoints")
    before = snapshot(run_dir)
    assert resume(run_dir) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    last = max(int(row["step"]) for row in csv_rows(sac_run, "episodes.csv"))
    assert f"no checkpoint but episodes.csv has rows up to step {last}" in err  # not a restart
    assert unlocked(snapshot(run_dir)) == unlocked(before)  # the CSVs keep their rows


def test_a_run_killed_before_its_first_checkpoint_starts_again(sac_run, tmp_path):
    run_dir = unfinished_copy(sac_run, tmp_path / "run")
    shutil.rmtree(run_dir / "checkpoints")
    for name in ("episodes.csv", "train.csv", "eval.csv"):  # the rows a kill at step 500 leaves
        header, *lines = (run_dir / name).read_text().splitlines(keepends=True)
        kept = [line for line in lines if int(float(line.split(",")[0])) <= 500]
        (run_dir / name).write_text(header + "".join(kept))
    assert resume(run_dir) == 0
    for name in ("episodes.csv", "train.csv", "eval.csv"):
        assert csv_rows(run_dir, name) == csv_rows(sac_run, name), name


def test_disk_full_during_a_checkpoint_is_exit_1_and_the_run_resumes(
    sac_run, tmp_path, monkeypatch, capsys
):
    run_dir = unfinished_copy(sac_run, tmp_path / "run", drop_last_checkpoint=True)
    previous = checkpoints.checkpoint_dirs(run_dir)[-1]
    sha = checkpoints.file_sha256(previous / "arrays.npz")

    def full_disk(file, arrays):  # the disk fills part way through arrays.npz
        file.write(b"PK\x03\x04")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(npz, "write", full_disk)
    assert resume(run_dir) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "step_000000001000" in err and "No space left on device" in err
    monkeypatch.undo()
    assert checkpoints.checkpoint_dirs(run_dir) == [previous]
    assert checkpoints.file_sha256(previous / "arrays.npz") == sha
    assert not (run_dir / "DONE").exists()
    assert resume(run_dir) == 0
    for name in ("episodes.csv", "train.csv", "eval.csv"):
        assert csv_rows(run_dir, name) == csv_rows(sac_run, name), name


# ----------------------------------------------------------------------------- config.yaml edits
@pytest.mark.parametrize(
    "field, value", [("seeds", [0, 2]), ("task", "walker2d"), ("hidden", [32, 32])]
)
def test_resume_names_the_edited_config_field(sac_run, tmp_path, capsys, field, value):
    run_dir = unfinished_copy(sac_run, tmp_path / "run")
    doc = yaml.safe_load((run_dir / "config.yaml").read_text())
    doc[field] = value
    (run_dir / "config.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    assert resume(run_dir) == 2
    err = capsys.readouterr().err
    assert f"field '{field}'" in err and err.count("\n") == 1, err


def test_resume_rejects_an_unknown_config_key(sac_run, tmp_path, capsys):
    run_dir = unfinished_copy(sac_run, tmp_path / "run")
    with open(run_dir / "config.yaml", "a") as f:
        f.write("lr_actr: 0.1\n")
    assert resume(run_dir) == 2
    assert "unknown field 'lr_actr'" in capsys.readouterr().err


# ----------------------------------------------------------------------------- divergence
def test_sac_divergence_stops_at_the_next_log_with_exit_3(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "--preset", "smoke", "--algo", "sac", "--seeds", "0,1", "--lr-actor", "1e6"]
    argv += ["--lr-critic", "1e6", "--total-steps", "1000", "--checkpoint-every", "250"]
    assert main([*argv, "--out", str(out), "--no-progress"]) == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "diverged at step 500" in err and "loss_q (seed" in err, err
    assert "step_000000000250" in err  # the last good checkpoint, named and kept
    assert not (out / "DONE").exists()
    assert [p.name for p in checkpoints.checkpoint_dirs(out)] == ["step_000000000250"]
    arrays = final_arrays(out)
    assert all(np.isfinite(a).all() for a in arrays.values() if a.dtype.kind == "f")


def test_rnac_divergence_stops_with_exit_3(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "--algo", "rnac", "--preset", "smoke", "--lr", "1e6", "--total-steps", "512"]
    assert main([*argv, "--out", str(out), "--no-progress"]) == 3
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "diverged at step 256" in err and "seed 0" in err, err
    assert not (out / "DONE").exists()


# ----------------------------------------------------------------------------- RNAC
def test_rnac_falls_back_to_an_older_checkpoint_and_resumes_exactly(tmp_path, capsys):
    config = rnac_config.RNACConfig(
        **{**rnac_config.PRESETS["smoke"], "total_steps": 512, "checkpoint_every": 256}
    )
    base = tmp_path / "base"
    trainers.train(config, base)
    run_dir = unfinished_copy(base, tmp_path / "run")
    newest = checkpoints.checkpoint_dirs(run_dir)[-1] / "arrays.npz"
    data = bytearray(newest.read_bytes())
    data[len(data) // 2] ^= 0xFF
    newest.write_bytes(bytes(data))
    assert resume(run_dir) == 0
    err = capsys.readouterr().err
    assert "step_000000000512" in err and "older" in err, err
    for name in ("episodes.csv", "train.csv", "eval.csv"):
        assert csv_rows(run_dir, name) == csv_rows(base, name), name
