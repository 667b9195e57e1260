"""`--track`: a tiny run's TensorBoard scalars and config reach Weights & Biases (offline mode,
read back from its run file); without wandb installed, one line, exit 2, nothing written; sweeps
pass the flags to every attempt of every unit."""

import argparse
import json
import struct
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from adarl.cli.main import main
from adarl.cli.train import add_arguments, build_config
from adarl.report import summary
from adarl.runs import tracking
from adarl.sweeps import spec, worker
from adarl.train import launch

TINY = ["--algo", "adarl", "--preset", "smoke", "--seeds", "0", "--total-steps", "1000"]


def _one_line_error(capsys, argv) -> str:
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1, err
    return err


def tensorboard_scalars(tb_dir: Path) -> set[tuple[str, int, float]]:
    """(tag, step, value) of every scalar in a folder of TensorBoard event files (TFRecords:
    length, its CRC, an Event protobuf, its CRC)."""
    from tensorboardX.proto import event_pb2

    found = set()
    for path in sorted(tb_dir.glob("events.out.tfevents.*")):
        data, pos = path.read_bytes(), 0
        while pos < len(data):
            (length,) = struct.unpack("<Q", data[pos : pos + 8])
            event = event_pb2.Event()
            event.ParseFromString(data[pos + 12 : pos + 12 + length])
            pos += 12 + length + 4
            for value in event.summary.value:
                found.add((value.tag, int(event.step), float(value.simple_value)))
    return found


def wandb_records(path: Path) -> list:
    """The records of a W&B run file (`run-<id>.wandb`): a 7-byte header, then LevelDB-log
    chunks (CRC 4, length 2, type 1: 1 full, 2 first, 3 middle, 4 last) in 32 KiB blocks, each
    record a wandb_internal Record protobuf."""
    from wandb.proto import wandb_internal_pb2

    data = path.read_bytes()
    assert data[:4] == b":W&B"
    pos, block, parts, records = 7, 32768, b"", []
    while pos + 7 <= len(data):
        left = block - pos % block
        kind = data[pos + 6] if left >= 7 else 0
        if kind == 0:  # the padding at the end of a block
            pos += left
            continue
        length = int.from_bytes(data[pos + 4 : pos + 6], "little")
        chunk = data[pos + 7 : pos + 7 + length]
        pos += 7 + length
        parts = chunk if kind in (1, 2) else parts + chunk
        if kind in (1, 4):
            record = wandb_internal_pb2.Record()
            record.ParseFromString(parts)
            records.append(record)
    return records


def test_scalars_and_config_reach_wandb_offline(tmp_path, monkeypatch):
    pytest.importorskip("wandb")
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_DIR", str(tmp_path))
    monkeypatch.setenv("WANDB_SILENT", "true")
    run_dir = tmp_path / "run"
    argv = ["train", *TINY, "--out", str(run_dir), "--no-progress"]
    assert main([*argv, "--track", "--wandb-project", "adarl-tests", "--wandb-group", "g"]) == 0

    files = list((tmp_path / "wandb").glob("offline-run-*/run-*.wandb"))
    assert len(files) == 1, files
    deadline = time.monotonic() + 30  # W&B's service writes the file after finish() returns
    while "exit" not in {r.WhichOneof("record_type") for r in wandb_records(files[0])}:
        assert time.monotonic() < deadline, "the W&B run file never got its exit record"
        time.sleep(0.2)
    records = wandb_records(files[0])
    run = next(r.run for r in records if r.WhichOneof("record_type") == "run")
    assert (run.project, run.run_group, run.display_name) == ("adarl-tests", "g", "run")
    config = {i.key: json.loads(i.value_json) for i in run.config.update}
    assert config["algo"] == "adarl" and config["total_steps"] == 1000 and config["seeds"] == [0]
    assert config["run_dir"] == str(run_dir.resolve())

    mirrored = set()
    for record in records:
        if record.WhichOneof("record_type") != "history":
            continue
        row = {
            i.key or "/".join(i.nested_key): json.loads(i.value_json) for i in record.history.item
        }
        step = row.pop("global_step")
        for key, value in row.items():
            if not key.startswith("_"):  # W&B's own _step, _runtime, _timestamp
                mirrored.add((key, step, float(np.float32(value))))
    written = tensorboard_scalars(run_dir / "tb")
    tags = {tag for tag, _, _ in written}
    assert {"train/loss_q/seed0", "eval/nominal/return/seed0", "episode/return/seed0"} <= tags
    assert any(tag.startswith("train/rank_") for tag in tags)
    assert mirrored == written


def test_a_resumed_run_continues_the_same_wandb_run(tmp_path):
    parser = argparse.ArgumentParser(add_help=False)
    add_arguments(parser)
    _, config = build_config(parser.parse_args(TINY))
    _, other = build_config(parser.parse_args([*TINY[:-1], "2000"]))
    same = tracking.run_id(tmp_path / "run", config)
    assert same == tracking.run_id(Path(str(tmp_path)) / "x" / ".." / "run", config)
    assert same != tracking.run_id(tmp_path / "other", config)
    assert same != tracking.run_id(tmp_path / "run", other)


def test_track_without_wandb_says_what_to_install(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "wandb", None)  # import wandb -> ImportError
    for argv in (
        ["train", *TINY, "--out", str(tmp_path / "run"), "--track"],
        ["sweep", "smoke", "--out", str(tmp_path / "sweep"), "--track"],
    ):
        err = _one_line_error(capsys, argv)
        assert "--track needs Weights & Biases" in err and "pip install 'adarl[track]'" in err
    assert list(tmp_path.iterdir()) == []


def test_wandb_that_cannot_start_a_run_is_one_line(tmp_path, capsys, monkeypatch):
    wandb = pytest.importorskip("wandb")

    def not_logged_in(**kwargs):
        raise wandb.errors.UsageError("No API key configured. Use `wandb login` to log in.")

    monkeypatch.setattr(wandb, "init", not_logged_in)
    err = _one_line_error(capsys, ["train", *TINY, "--out", str(tmp_path / "run"), "--track"])
    assert "did not start a run: No API key configured" in err and "WANDB_MODE=offline" in err
    assert list(tmp_path.iterdir()) == []


def test_wandb_flags_need_track(tmp_path, capsys):
    for argv in (
        ["train", *TINY, "--out", str(tmp_path / "run"), "--wandb-project", "p"],
        ["sweep", "smoke", "--out", str(tmp_path / "sweep"), "--wandb-entity", "me"],
    ):
        assert "is for --track" in _one_line_error(capsys, argv)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("resume", [False, True])
def test_a_sweep_unit_passes_the_tracking_flags_to_every_attempt(tmp_path, monkeypatch, resume):
    run_dir = tmp_path / "run"
    if resume:  # a complete checkpoint: the attempt resumes
        (run_dir / "checkpoints" / "step_000000000500").mkdir(parents=True)
        for name in ("meta.json", "arrays.npz"):
            (run_dir / "checkpoints" / "step_000000000500" / name).write_text("{}")
    seen = []
    monkeypatch.setattr(launch, "train", lambda *args, **kwargs: seen.append((args, kwargs)))
    monkeypatch.setattr(summary, "training_summary", lambda *args: "")
    state = ["--lock", str(tmp_path / "l"), "--marker", str(tmp_path / "m"), "--attempt", "1"]
    unit = spec.load("smoke").units[0]
    what = [f"--unit={json.dumps(launch.record(unit.start_in(tmp_path)))}"]
    extra = ["--track", "--wandb-group", "smoke"]
    assert worker.main(["--run-dir", str(run_dir), *state, *extra, *what]) == 0
    (start, _, command), kwargs = seen[0]
    assert kwargs["tracking"] == launch.Tracking(True, group="smoke")
    assert isinstance(start, launch.Resume) == resume
    assert command.endswith("--no-progress --track --wandb-group smoke")
    assert ("--resume" in command) == resume


def test_the_sweep_hands_the_flags_to_its_units(tmp_path, monkeypatch, capsys):
    pytest.importorskip("wandb")
    from adarl.sweeps import runner

    seen = []
    monkeypatch.setattr(runner, "run_sweep", lambda sweep, out, backend, opts: seen.append(opts))
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_API_KEY", "secret")
    argv = ["sweep", "smoke", "--out", str(tmp_path / "s"), "--workers", "1", "--track"]
    assert main([*argv, "--wandb-project", "p"]) == 0
    options = seen[0]
    assert options.train_extra == ("--track", "--wandb-group", "smoke", "--wandb-project", "p")
    assert "--track --wandb-project p" in options.command
    assert options.train_env["WANDB_MODE"] == "offline" and "WANDB_API_KEY" not in options.train_env
    job = runner.SweepRun(spec.load("smoke"), tmp_path, None, None, options).job(
        spec.load("smoke").units[0], 1
    )
    assert job["env"]["WANDB_MODE"] == "offline" and "XLA_FLAGS" in job["env"]
    assert "--track" in job["worker_args"]
