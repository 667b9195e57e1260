"""The run lock: one process writes a run folder at a time (docs/reliability.md)."""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from adarl.errors import UsageError
from adarl.files import fs_errors, open_in_place
from adarl.runs.layout import LOCK_FILE


def lock_holder(run_dir: str | os.PathLike) -> str | None:
    """The PID (as written, or "?") of the process holding `run_dir`'s lock, or None."""
    try:
        with open(Path(run_dir) / LOCK_FILE, "rb") as handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:  # the pid, as written; any bytes shown, never many
                return handle.read(64).decode("utf-8", errors="replace").strip() or "?"
            return None  # closing the file drops the shared lock just taken
    except OSError:
        return None


def refuse_non_empty(run_dir: Path) -> None:
    """A one-line UsageError if `run_dir` holds anything but its lock file."""
    if run_dir.exists() and any(p.name != LOCK_FILE for p in run_dir.iterdir()):
        raise UsageError(
            f"run folder {run_dir} already exists and is not empty; "
            f"resume it with --resume {run_dir} or choose another --out"
        )


class RunLock:
    """An exclusive `flock` on RUN_DIR/.lock: one process writes a run folder at a time.

    Use as `with RunLock(run_dir) as lock:` around a trainer and call `lock.acquire(new)` after
    validating the input and before the first write. The kernel drops the lock when the process
    ends, however it ends, so a killed run never leaves a stale lock. The file holds the PID of
    the holder, which the one-line error of a second writer names (exit code 2).
    """

    def __init__(self, run_dir: str | os.PathLike):
        self.run_dir = Path(run_dir)
        self._handle = None

    def acquire(self, new: bool) -> None:
        """Take the lock (creating the folder of a `new` run); a UsageError if another process
        holds it or, for a new run, if the folder filled up meanwhile."""
        path = self.run_dir / LOCK_FILE
        with fs_errors(path):
            if new:
                self.run_dir.mkdir(parents=True, exist_ok=True)
            handle = open_in_place(path, "a+")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            pid = handle.read().strip() or "?"
            handle.close()
            raise UsageError(
                f"run folder {self.run_dir} is being written by another adarl process "
                f"(pid {pid}); wait for it to end or stop it"
            ) from None
        self._handle = handle
        if new:  # it may have filled up since the check before the lock
            try:
                refuse_non_empty(self.run_dir)
            except UsageError:
                self.release()
                raise
        with fs_errors(path):
            handle.seek(0)
            handle.truncate()
            handle.write(f"{os.getpid()}\n")
            handle.flush()

    def release(self) -> None:
        if self._handle is not None:
            self._handle.close()  # closing the file drops the lock
            self._handle = None

    def __enter__(self) -> RunLock:
        return self

    def __exit__(self, *exc) -> None:
        self.release()
