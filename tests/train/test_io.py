"""Run-folder I/O helpers that the trainer tests do not reach directly, and the run folder's
safety (docs/reliability.md): the lock, checkpoint checksums and fallback, file-system errors,
output checks, the divergence watch."""

import errno
import json
import os
import signal
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from adarl.algos import registry
from adarl.errors import Diverged, RunFailed, UsageError
from adarl.train import io

# one algorithm per config class, so per training loop
ONE_PER_TRAINER = [
    next(a for a in registry.ALGOS if registry.get(a).config_class is cls)
    for cls in registry.config_classes()
]

PROBE = """
import importlib.util, sys, tempfile
from adarl.train.io import Scalars
writer = Scalars(tempfile.mkdtemp())
writer.write(1, {"x": 1.0})
writer.close()
assert "torch" not in sys.modules, "tensorboardX pulled torch in"
if importlib.util.find_spec("torch") is not None:
    import torch  # hidden only while tensorboardX was imported
print("ok")
"""


def test_tensorboard_writer_does_not_import_torch_but_leaves_it_importable():
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


# ----------------------------------------------------------------------------- hardening (issue 17)
HOLD = """
import sys, time
from adarl.train.io import RunLock
lock = RunLock(sys.argv[1])
lock.acquire(new=False)
print("locked", flush=True)
time.sleep(600)
"""


def hold_lock(run_dir: Path) -> subprocess.Popen:
    """Another process holding `run_dir`'s lock (until it is killed)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(run_dir)], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_run_lock_names_the_holder_and_is_freed_when_it_is_killed(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    holder = hold_lock(run_dir)
    try:
        with pytest.raises(UsageError, match=f"another adarl process \\(pid {holder.pid}\\)"):
            io.RunLock(run_dir).acquire(new=False)
        assert io.lock_holder(run_dir) == str(holder.pid)
        with pytest.raises(UsageError, match=f"\\(pid {holder.pid}\\); choose another --out"):
            io.check_new_run_dir(run_dir)  # a second new run with the same --out
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
    assert io.lock_holder(run_dir) is None
    io.check_new_run_dir(run_dir)  # only the killed run's lock file in it: usable as --out
    with io.RunLock(run_dir) as lock:  # the kernel dropped the killed holder's lock: not stale
        lock.acquire(new=False)
        assert (run_dir / io.LOCK_FILE).read_text().strip() == str(os.getpid())


def test_run_lock_of_a_new_run_refuses_a_folder_that_filled_up(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text("x: 1\n")
    with pytest.raises(UsageError, match="not empty"), io.RunLock(run_dir) as lock:
        lock.acquire(new=True)


def _save(run_dir, step, keep=3, value=0.0):
    arrays = {"w": np.full((3, 4), value, np.float32), "n": np.arange(5)}
    return io.save_checkpoint(run_dir, step, arrays, {"note": step}, keep=keep)


def _truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _flip_byte(path):
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def _garbage(path):
    path.write_bytes(b"not a zip file")


@pytest.mark.parametrize("damage", [_truncate, _flip_byte, _garbage])
def test_a_damaged_newest_checkpoint_falls_back_to_the_older_one(tmp_path, damage):
    _save(tmp_path, 100, value=1.0)
    newest = _save(tmp_path, 200, value=2.0)
    damage(newest / "arrays.npz")
    with pytest.raises(io.CheckpointDamaged):
        io.load_checkpoint(newest)
    lines = []
    path, arrays, meta = io.load_latest_intact(tmp_path, warn=lines.append)
    assert path.name == "step_000000000100" and meta["step"] == 100
    np.testing.assert_array_equal(arrays["w"], np.full((3, 4), 1.0, np.float32))
    assert len(lines) == 1 and "step_000000000200" in lines[0] and "\n" not in lines[0]
    # the damaged one is kept for inspection under another name, and never tried again
    assert [p.name for p in io.checkpoint_dirs(tmp_path)] == ["step_000000000100"]
    assert (tmp_path / "checkpoints" / "damaged_step_000000000200" / "arrays.npz").exists()


def test_no_intact_checkpoint_is_a_clear_usage_error(tmp_path):
    for step in (100, 200):
        _garbage(_save(tmp_path, step) / "arrays.npz")
    with pytest.raises(UsageError, match="no intact checkpoint") as err:
        io.load_latest_intact(tmp_path, warn=lambda line: None)
    assert "\n" not in str(err.value)
    assert len(io.checkpoint_dirs(tmp_path)) == 2  # nothing renamed: the error repeats
    assert io.load_latest_intact(tmp_path / "empty") is None  # no checkpoint at all: start


def test_checksum_is_stored_and_old_checkpoints_without_one_still_load(tmp_path):
    path = _save(tmp_path, 100)
    meta = json.loads((path / "meta.json").read_text())
    assert meta["arrays_sha256"] == io.file_sha256(path / "arrays.npz")
    del meta["arrays_sha256"]  # as written before checksums
    (path / "meta.json").write_text(json.dumps(meta))
    arrays, _ = io.load_checkpoint(path)
    assert arrays["w"].shape == (3, 4)


def test_checkpoint_folders_are_readable_like_the_rest_of_the_run(tmp_path):
    path = _save(tmp_path, 100)
    assert stat.S_IMODE(path.stat().st_mode) == 0o755


def test_disk_full_during_a_checkpoint_is_one_line_and_keeps_the_previous(tmp_path, monkeypatch):
    previous = _save(tmp_path, 100, value=1.0)

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(np, "savez", full)
    with pytest.raises(RunFailed) as err:
        _save(tmp_path, 200)
    message = str(err.value)
    assert "step_000000000200" in message and "No space left on device" in message
    assert err.value.exit_code == 1 and "\n" not in message
    monkeypatch.undo()
    assert io.checkpoint_dirs(tmp_path) == [previous]
    assert not list((tmp_path / "checkpoints").glob(".tmp_*"))
    arrays, _ = io.load_checkpoint(previous)
    np.testing.assert_array_equal(arrays["w"], np.full((3, 4), 1.0, np.float32))


def test_csv_write_error_is_one_line_naming_the_file(tmp_path, monkeypatch):
    log = io.CsvLog(tmp_path / "train.csv", ["step", "x"])

    def full():
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(log._file, "flush", full)
    with pytest.raises(RunFailed, match=r"train\.csv: No space left on device"):
        log.write({"step": 1, "x": 2.0})
    log.close()  # after a failed write, closing does not raise again


def test_output_folders_are_checked_before_anything_is_written(tmp_path, monkeypatch):
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(UsageError, match="is a file"):
        io.check_writable_dir(afile)
    with pytest.raises(UsageError, match="is a file, not a folder"):
        io.check_writable_dir(afile / "run")
    with pytest.raises(UsageError, match="is a file, not a folder"):
        io.check_writable_file(afile / "x.csv")
    io.check_writable_dir(tmp_path / "new" / "run")  # creatable
    assert not (tmp_path / "new").exists()
    monkeypatch.setattr(os, "access", lambda *a, **k: False)  # as a read-only file system
    with pytest.raises(UsageError, match="is not writable"):
        io.check_writable_dir(tmp_path / "new" / "run")


def test_divergence_watch_names_step_seeds_and_quantity(tmp_path, capsys):
    watch = io.DivergenceWatch(tmp_path, "stop")
    watch.check(10)  # nothing noted: nothing happens
    watch.note_values("loss_q", [0, 3, 5], [1.0, np.inf, np.nan])
    watch.note_values("actor parameters", [0, 3, 5], np.ones((3, 4)))
    with pytest.raises(Diverged) as err:
        watch.check(500)
    assert err.value.exit_code == 3
    assert "step 500" in str(err.value) and "loss_q (seeds 3, 5)" in str(err.value)
    assert "actor" not in str(err.value)
    keep_going = io.DivergenceWatch(tmp_path, "continue")
    for step in (500, 1000):
        keep_going.note("episode return", [1])
        keep_going.check(step)
    err_text = capsys.readouterr().err
    assert err_text.count("\n") == 1 and "episode return (seed 1)" in err_text


# ----------------------------------------------------------------------------- the lock's release
class Crash(Exception):
    pass


def test_run_lock_is_released_when_its_block_ends_while_the_process_lives(tmp_path):
    """The lock goes at the end of the `with` block, however the block ends, and not only when
    the process ends or the RunLock object is collected (both stay alive here)."""
    run_dir = tmp_path / "run"
    lock = io.RunLock(run_dir)
    with lock:
        lock.acquire(new=True)
        assert io.lock_holder(run_dir) == str(os.getpid())
    assert io.lock_holder(run_dir) is None
    other = io.RunLock(run_dir)
    with pytest.raises(Crash) as info, other:
        other.acquire(new=False)
        raise Crash
    assert info.value is not None and other is not None  # the traceback holds the frame
    assert io.lock_holder(run_dir) is None
    with io.RunLock(run_dir) as again:  # this process can take it again
        again.acquire(new=False)


@pytest.mark.parametrize("algo", ONE_PER_TRAINER)
def test_a_trainer_that_fails_leaves_its_run_folder_unlocked(algo, tmp_path, monkeypatch):
    """A trainer that raises after taking the lock (here: right after config.yaml) has released
    it by the time the exception reaches the caller, even while the caller keeps the exception
    (and so the trainer's frames) alive, as a sweep worker or a test does."""
    from adarl.train.trainers import trainer

    def crash(run_dir):
        assert io.lock_holder(run_dir) == str(os.getpid())  # taken by then
        raise Crash

    monkeypatch.setattr(io, "write_environment", crash)
    run_dir = tmp_path / "run"
    config = registry.resolve_config(algo, "smoke", {"task": "hopper"})
    train = trainer(algo)
    with pytest.raises(Crash) as info:
        train(config, run_dir, progress=False)
    assert info.traceback  # kept
    assert io.lock_holder(run_dir) is None


def test_divergence_is_noted_for_one_non_finite_value_among_finite_ones(tmp_path):
    watch = io.DivergenceWatch(tmp_path, "stop")
    values = np.ones((3, 5))
    values[1, 3] = np.nan  # seed 7: one value of five
    values[2, 0] = -np.inf  # seed 9: one value of five
    watch.note_values("critic parameters", [5, 7, 9], values)
    assert watch.found == {"critic parameters": [7, 9]}
    watch.note_values("loss_q", [5, 7, 9], [1.0, 2.0, 3.0])
    assert "loss_q" not in watch.found
    with pytest.raises(Diverged, match=r"critic parameters \(seeds 7, 9\)"):
        watch.check(100)
