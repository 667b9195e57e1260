"""The run lock (docs/reliability.md): one writer at a time, named in the error, freed when the
holder ends or its block ends."""

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from adarl.algos import registry
from adarl.errors import UsageError
from adarl.runs import folder
from adarl.runs.layout import LOCK_FILE
from adarl.runs.lock import RunLock, lock_holder

HOLD = """
import sys, time
from adarl.runs.lock import RunLock
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
            RunLock(run_dir).acquire(new=False)
        assert lock_holder(run_dir) == str(holder.pid)
        with pytest.raises(UsageError, match=f"\\(pid {holder.pid}\\); choose another --out"):
            folder.check_new_run_dir(run_dir)  # a second new run with the same --out
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
    assert lock_holder(run_dir) is None
    folder.check_new_run_dir(run_dir)  # only the killed run's lock file in it: usable as --out
    with RunLock(run_dir) as lock:  # the kernel dropped the killed holder's lock: not stale
        lock.acquire(new=False)
        assert (run_dir / LOCK_FILE).read_text().strip() == str(os.getpid())


def test_run_lock_of_a_new_run_refuses_a_folder_that_filled_up(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text("x: 1\n")
    with pytest.raises(UsageError, match="not empty"), RunLock(run_dir) as lock:
        lock.acquire(new=True)


# ----------------------------------------------------------------------------- the lock's release
class Crash(Exception):
    pass


def test_run_lock_is_released_when_its_block_ends_while_the_process_lives(tmp_path):
    """The lock goes at the end of the `with` block, however the block ends, and not only when
    the process ends or the RunLock object is collected (both stay alive here)."""
    run_dir = tmp_path / "run"
    lock = RunLock(run_dir)
    with lock:
        lock.acquire(new=True)
        assert lock_holder(run_dir) == str(os.getpid())
    assert lock_holder(run_dir) is None
    other = RunLock(run_dir)
    with pytest.raises(Crash) as info, other:
        other.acquire(new=False)
        raise Crash
    assert info.value is not None and other is not None  # the traceback holds the frame
    assert lock_holder(run_dir) is None
    with RunLock(run_dir) as again:  # this process can take it again
        again.acquire(new=False)


# one algorithm per config class, so per learner
ONE_PER_TRAINER = [
    next(a for a in registry.ALGOS if registry.get(a).config_class is cls)
    for cls in registry.config_classes()
]


@pytest.mark.parametrize("algo", ONE_PER_TRAINER)
def test_a_trainer_that_fails_leaves_its_run_folder_unlocked(algo, tmp_path, monkeypatch):
    """A trainer that raises after taking the lock (here: right after config.yaml) has released
    it by the time the exception reaches the caller, even while the caller keeps the exception
    (and so the trainer's frames) alive, as a sweep worker or a test does."""
    from adarl.train.trainers import trainer

    def crash(run_dir, extra=None):
        assert lock_holder(run_dir) == str(os.getpid())  # taken by then
        raise Crash

    monkeypatch.setattr(folder, "write_environment", crash)
    run_dir = tmp_path / "run"
    config = registry.resolve_config(algo, "smoke", {"task": "hopper"})
    with pytest.raises(Crash) as info:
        trainer(algo)(config, run_dir, progress=False)
    assert info.traceback  # kept
    assert lock_holder(run_dir) is None
