"""One attempt at one sweep unit, as its own process:

    python -m adarl.sweeps.worker --run-dir RUN --lock LOCK --marker MARKER --attempt K \
        [--parent PID] [--train-extra=FLAG ...] -- TRAIN_ARGS...

It dies with the process that started it (Linux), holds the unit's lock file while it trains (so
two processes can never train into the same run folder), then decides, under the lock, what the
attempt does: nothing if the run is DONE, `adarl train --resume RUN` if the run has a complete
checkpoint, and otherwise `adarl train TRAIN_ARGS --out RUN` from scratch (removing a run folder
that a kill left without any checkpoint). It writes MARKER (JSON: attempt, pid, host, mode, step)
once it has decided, which is how the sweep learns that the unit is running.
"""

from __future__ import annotations

import argparse
import ctypes
import fcntl
import os
import shutil
import signal
import socket
import sys
import time
from pathlib import Path

from adarl.runs.layout import DONE_FILE

EXIT_BUSY = 75  # another process holds the unit's lock


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m adarl.sweeps.worker")
    parser.add_argument("--run-dir", required=True)
    parser.add_argument("--lock", required=True)
    parser.add_argument("--marker", required=True)
    parser.add_argument("--attempt", type=int, required=True)
    parser.add_argument("--parent", type=int, default=None)
    parser.add_argument(
        "--train-extra",
        action="append",
        default=[],
        help="an `adarl train` flag for fresh and resumed attempts alike (--train-extra=--track)",
    )
    parser.add_argument("train_args", nargs=argparse.REMAINDER)
    args = parser.parse_args(argv)
    train_args = args.train_args[1:] if args.train_args[:1] == ["--"] else args.train_args

    if args.parent is not None and not _die_with_parent(args.parent):
        print("the sweep that started this unit is gone; not starting", flush=True)
        return 1
    lock = _take_lock(Path(args.lock))  # held until this process ends
    if lock is None:
        print(
            f"{args.run_dir} is being trained by another process (lock {args.lock} is held)",
            flush=True,
        )
        return EXIT_BUSY

    from adarl.files import atomic_write_json
    from adarl.runs.checkpoints import checkpoint_dirs

    run_dir = Path(args.run_dir)
    step = 0
    if (run_dir / DONE_FILE).exists():
        mode = "done"
    elif checkpoint_dirs(run_dir):
        mode, step = "resume", int(checkpoint_dirs(run_dir)[-1].name.split("_")[1])
    else:
        mode = "fresh"
        if run_dir.exists():  # killed before its first checkpoint: nothing to keep
            shutil.rmtree(run_dir)
    atomic_write_json(
        args.marker,
        {
            "attempt": args.attempt,
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "mode": mode,
            "step": step,
            "time": time.time(),
        },
    )
    stamp = time.strftime("%Y-%m-%d %H:%M:%S")
    print(
        f"=== {stamp} attempt {args.attempt} on {socket.gethostname()} (pid {os.getpid()}): "
        f"{mode}{f' from step {step}' if mode == 'resume' else ''}",
        flush=True,
    )
    if mode == "done":
        return 0
    if mode == "resume":
        command = ["train", "--resume", str(run_dir), "--no-progress", *args.train_extra]
    else:
        command = ["train", *train_args, "--out", str(run_dir), "--no-progress", *args.train_extra]
    print("$ adarl " + " ".join(command), flush=True)
    sys.argv = ["adarl", *command]  # what `adarl train` records as the run's command
    from adarl.cli.main import main as adarl_main

    return adarl_main(command)


def _die_with_parent(parent: int) -> bool:
    """Ask Linux to SIGKILL this process when its parent dies; False if it already has."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    return os.getppid() == parent


def _take_lock(path: Path):
    """An open file holding an exclusive lock on `path`, or None if another process holds it.
    The lock goes with this process, however it ends."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle = open(path, "a")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        return None
    return handle


if __name__ == "__main__":
    sys.exit(main())
