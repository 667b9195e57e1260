"""One attempt at one sweep unit, as its own process:

    python -m adarl.sweeps.worker --run-dir RUN --lock LOCK --marker MARKER --attempt K \
        [--parent PID] [--track --wandb-group G ...] [--env-module PKG] --unit UNIT_JSON

UNIT_JSON is what the unit trains, as `adarl train` takes it (`adarl.train.launch.record`):
`{"algo", "preset", "flags"}`, or for a fork `{"fork": {"from", "at", "changes"}}`, the parent
being its run folder (`Unit.start_in`); PKG is the env-module the sweep file names, which
the unit may import (a run folder alone never makes adarl import one). The worker dies with the process that
started it (Linux), holds the unit's lock file while it trains (so two processes can never train
into the same run folder), then decides, under the lock, what the attempt does: nothing if the run
is DONE, resume RUN if it has a complete checkpoint, and otherwise start it from scratch (removing
a run folder that a kill left without any checkpoint). It writes MARKER (JSON: attempt, pid, host,
mode, step) once it has decided, which is how the sweep learns that the unit is running. It
trains through `adarl.train.launch.train`, as `adarl train` does, records the `adarl train`
command that trains the same run, and exits with the same codes (2 bad input, 3 diverged).
"""

from __future__ import annotations

import argparse
import ctypes
import fcntl
import json
import os
import shlex
import shutil
import signal
import socket
import sys
import time
from pathlib import Path

from adarl.errors import REPORTED, failure
from adarl.runs.layout import DONE_FILE

EXIT_BUSY = 75  # another process holds the unit's lock


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m adarl.sweeps.worker")
    parser.add_argument("--run-dir", required=True)
    parser.add_argument("--lock", required=True)
    parser.add_argument("--marker", required=True)
    parser.add_argument("--attempt", type=int, required=True)
    parser.add_argument("--parent", type=int, default=None)
    parser.add_argument("--unit", required=True, type=json.loads, help="see launch.record")
    parser.add_argument(
        "--env-module", default="", help="the module the sweep file names, which it may import"
    )
    parser.add_argument("--track", action="store_true", help="as adarl train --track")
    parser.add_argument("--wandb-project", default=None)
    parser.add_argument("--wandb-entity", default=None)
    parser.add_argument("--wandb-group", default=None)
    args = parser.parse_args(argv)

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
    from adarl.envs.tasks import name_env_module
    from adarl.train import launch

    name_env_module(args.env_module)
    tracking = launch.Tracking(args.track, args.wandb_project, args.wandb_entity, args.wandb_group)
    start = launch.Resume(str(run_dir)) if mode == "resume" else launch.from_record(args.unit)
    out = [] if mode == "resume" else ["--out", str(run_dir)]
    # the `adarl train` command that trains the same run, which the run records
    words = [*start.argv(), *out, "--no-progress", *tracking.argv()]
    command = "adarl train " + shlex.join(words)
    print("$ " + command, flush=True)
    from adarl.runtime import configure_xla

    configure_xla()
    started = time.monotonic()
    try:
        launch.train(start, run_dir, command, progress=False, tracking=tracking)
    except REPORTED as exc:
        code, message = failure("adarl train", exc)
        print(message, file=sys.stderr, flush=True)
        return code
    from adarl.report.summary import training_summary

    print(training_summary(run_dir, time.monotonic() - started), flush=True)
    return 0


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
