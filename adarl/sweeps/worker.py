"""One attempt at one sweep unit, as its own process:

    python -m adarl.sweeps.worker --run-dir RUN --lock LOCK --marker MARKER --attempt K \
        [--parent PID] [--track --wandb-group G ...] --unit UNIT_JSON --train-flags TEXT

UNIT_JSON is what the unit trains (`unit_record`): `{"algo", "config"}` (the config's fields),
or for a fork `{"fork": {"from", "at", "changes"}}`. The worker dies with the process that
started it (Linux), holds the unit's lock file while it trains (so two processes can never train
into the same run folder), then decides, under the lock, what the attempt does: nothing if the run
is DONE, resume RUN if it has a complete checkpoint, and otherwise start it from scratch (removing
a run folder that a kill left without any checkpoint). It writes MARKER (JSON: attempt, pid, host,
mode, step) once it has decided, which is how the sweep learns that the unit is running. It calls
the algorithm's trainer as `adarl train` does, with the same exit codes (2 bad input, 3 diverged).
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


def unit_record(unit, out: Path) -> dict:
    """What `unit` (an `adarl.sweeps.spec.Unit`) trains, as the worker's --unit takes it; a
    fork starts from its parent's run folder in the sweep folder `out`."""
    from adarl.runs.checkpoints import config_record

    if unit.fork_of:
        fork = {"from": str(out / unit.fork_of), "at": unit.fork_step, "changes": unit.flags}
        return {"fork": fork}
    return {"algo": unit.algo, "config": config_record(unit.config)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m adarl.sweeps.worker")
    parser.add_argument("--run-dir", required=True)
    parser.add_argument("--lock", required=True)
    parser.add_argument("--marker", required=True)
    parser.add_argument("--attempt", type=int, required=True)
    parser.add_argument("--parent", type=int, default=None)
    parser.add_argument("--unit", required=True, type=json.loads, help="see unit_record")
    parser.add_argument(
        "--train-flags",
        default="",
        help="the `adarl train` flags of the same run (`Unit.train_args`), which it records",
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
    tracking = [
        *(["--track"] if args.track else []),
        *(
            word
            for name in ("wandb_project", "wandb_entity", "wandb_group")
            if getattr(args, name) is not None
            for word in (f"--{name.replace('_', '-')}", getattr(args, name))
        ),
    ]
    if mode == "resume":
        words = ["--resume", str(run_dir), "--no-progress", *tracking]
    else:  # the `adarl train` command that trains the same run, which the run records
        words = [*shlex.split(args.train_flags), "--out", str(run_dir), "--no-progress", *tracking]
    command = "adarl train " + shlex.join(words)
    print("$ " + command, flush=True)
    from adarl.runtime import configure_xla

    configure_xla()
    try:
        _train(args, run_dir, mode == "resume", command)
    except REPORTED as exc:
        code, message = failure("adarl train", exc)
        print(message, file=sys.stderr, flush=True)
        return code
    return 0


def _train(args: argparse.Namespace, run_dir: Path, resume: bool, command: str) -> None:
    """Train (or resume, or fork then train) the unit into `run_dir`, then print the summary
    `adarl train` prints."""
    from adarl.algos import registry
    from adarl.report.summary import training_summary
    from adarl.runs import folder, tracking
    from adarl.train import fork
    from adarl.train.trainers import trainer

    started = time.monotonic()
    unit = args.unit
    if resume:
        algo, config = folder.config_from_run(run_dir)
    elif "fork" in unit:
        planned = fork.prepare(unit["fork"]["from"], unit["fork"]["at"], unit["fork"]["changes"])
        fork.write(planned, run_dir, command)
        algo, config = folder.config_from_run(run_dir)
        resume = True  # a written fork trains as a resumed run
    else:
        record = {**unit["config"], "algo": unit["algo"]}
        algo, config = registry.config_from_record(record, "the sweep unit's config")
    with tracking.tracked(
        args.track,
        run_dir,
        config,
        project=args.wandb_project,
        entity=args.wandb_entity,
        group=args.wandb_group,
        command=command,
    ):
        trainer(algo)(config, run_dir, resume, False, command)
    print(training_summary(run_dir, time.monotonic() - started), flush=True)


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
