"""Run a sweep: hand every unfinished unit to adarl's executor (`adarl.sweeps.job`), retry crashed ones a bounded number of
times, keep the manifest and print one line per unit event, then a summary.

The sweep folder:

    SWEEP_DIR/
      manifest.json                 state of every unit (adarl.sweeps.manifest)
      <task>/<label>/seeds-<s>/     one run folder per unit (docs/run-format.md)
      logs/<task>__<label>__seeds-<s>.log   output of every attempt of that unit
      .state/                       lock files and "attempt started" markers
      .jax-cache/                   JAX's compilation cache shared by the units

Re-running the same command is how a sweep resumes: units whose run folder has DONE are skipped,
the others are queued again and each attempt resumes from its run's newest checkpoint
(adarl.sweeps.worker decides that, under the unit's lock).

The runner hands the executor at most one unit per slot. Each free slot takes first a unit that
resumes from a checkpoint, the nearest to done first (a lost machine loses the training it
holds), then the ready unit with the longest critical path (by `adarl.sweeps.estimate`: its own
time left, or the time until it reaches a fork point plus that fork's time, when longer), so that
a long unit never starts last and runs alone at the end, and a unit that others fork from starts
before an independent unit of the same length. A fork unit (`fork: {from, at}`) becomes ready
when its parent unit has written the checkpoint it starts from, and fails if its parent fails or
finishes without it.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import dataclasses
import fcntl
import json
import os
import signal
import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from adarl.errors import UsageError
from adarl.files import read_json
from adarl.report.summary import duration
from adarl.runs.layout import CHECKPOINT_DIR, CONFIG_FILE, DONE_FILE, TRAIN_CSV
from adarl.sweeps import manifest as manifest_mod
from adarl.sweeps.job import run_job, thread_env
from adarl.sweeps.spec import Sweep, Unit
from adarl.sweeps.worker import EXIT_BUSY
from adarl.train import launch

POLL_S = 1.0  # how often the loop looks for finished and started units
NOT_RETRIED = {
    2: "bad input",
    3: "training diverged",  # deterministic: a retry diverges again
    EXIT_BUSY: "another process is training this unit",
}


@dataclass
class Options:
    max_retries: int = 2  # further attempts per unit after a crash, in one invocation
    progress_every: float = 60.0  # seconds between progress lines of running units
    command: str = ""
    # the tracking flags of every unit's worker, as `adarl train` takes them (--track ...)
    train_extra: tuple[str, ...] = ()
    train_env: dict[str, str] = dataclasses.field(default_factory=dict)  # added to the units'


def echo(line: str) -> None:
    print(line, flush=True)


# ----------------------------------------------------------------------------- plan
def unit_state(out: Path, unit: Unit) -> str:
    """What running `unit` would do now: 'done', 'resume from step N' or 'start'."""
    from adarl.runs.checkpoints import checkpoint_dirs

    run_dir = out / unit.id
    if (run_dir / DONE_FILE).exists():
        return "done"
    found = checkpoint_dirs(run_dir)
    return f"resume from step {int(found[-1].name.split('_')[1]):,}" if found else "start"


def plan_text(sweep: Sweep, out: Path, where: str) -> str:
    """The dry run: every unit, what it trains and what running it now would do."""
    from adarl.sweeps.estimate import remaining_steps, resumes, start_order

    width = max(len(u.id) for u in sweep.units)
    lines = [
        f"sweep {sweep.name} ({sweep.source}): {len(sweep.units)} units on {where}, output {out}"
    ]
    for unit in sweep.units:
        lines.append(
            f"  {unit.id:<{width}}  {unit_state(out, unit):<22} "
            f"adarl train {' '.join(unit.train_args)}"
        )
    first = [u.id for u in start_order(sweep, out) if resumes(u, remaining_steps(out, u))]
    if first:
        lines.append(f"resumed first, the nearest to done first: {', '.join(first)}")
    steps = sum((u.total_steps - u.fork_step) * len(u.seeds) for u in sweep.units)
    forks = " (a fork's from its fork point on)" if any(u.fork_of for u in sweep.units) else ""
    lines.append(f"total: {steps:,} environment steps over all seeds{forks}")
    return "\n".join(lines)


def check_not_a_run_folder(out: Path) -> None:
    """A one-line UsageError if the sweep's `out` is a run folder (holds config.yaml) or lies
    inside one: the sweep would write its manifest and unit folders into that run (as `train`
    refuses a non-empty --out and `report` a folder that is not a report). A folder above
    `out` counts as a run only with DONE or checkpoints/ beside its config.yaml (a project's
    own config.yaml is not a run)."""
    out = Path(out)
    for folder in (out, *Path(os.path.abspath(out)).parents):
        trained = (folder / DONE_FILE).exists() or (folder / CHECKPOINT_DIR).is_dir()
        if (folder / CONFIG_FILE).is_file() and (folder == out or trained):
            state = "a finished run" if (folder / DONE_FILE).exists() else "a run"
            where = "is the folder of" if folder == out else f"lies inside {folder}, the folder of"
            raise UsageError(
                f"--out {out} {where} {state} (it holds {CONFIG_FILE}); a sweep writes its "
                "manifest and run folders into --out: choose a new folder or an existing sweep's"
            )


def check_existing_runs(sweep: Sweep, out: Path) -> None:
    """A one-line UsageError if a unit's run folder already holds a run trained with other
    settings (the manifest aside, a sweep never resumes or skips someone else's run)."""
    from adarl.runs.folder import config_from_run

    for unit in sweep.units:
        run_dir = out / unit.id
        if not (run_dir / CONFIG_FILE).exists():
            continue
        _, found = config_from_run(run_dir)
        for f in dataclasses.fields(unit.config):
            old, new = getattr(found, f.name, None), getattr(unit.config, f.name)
            if old != new:
                raise UsageError(
                    f"{run_dir} holds a run with other settings ({f.name}: {old!r} there, "
                    f"{new!r} in this sweep); choose another --out"
                )


# ----------------------------------------------------------------------------- run
@contextlib.contextmanager
def sweep_lock(out: Path):
    """Hold `out/.state/sweep.lock`; a UsageError if another sweep process holds it."""
    path = out / ".state" / "sweep.lock"
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            pid = handle.read().strip() or "?"
            raise UsageError(f"{out} is in use by another adarl sweep (pid {pid})") from None
        handle.seek(0)
        handle.truncate()
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        yield


def run_sweep(sweep: Sweep, out: Path, executor, options: Options) -> int:
    """Run every unfinished unit of `sweep` into `out`; 0 if all are done, 1 if any failed."""
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    with sweep_lock(out), sigterm_as_interrupt():
        manifest = manifest_mod.Manifest.open(out, sweep, options.command)
        return SweepRun(sweep, out, executor, manifest, options).run()


class SweepRun:
    def __init__(self, sweep: Sweep, out: Path, executor, manifest, options: Options):
        self.sweep, self.out, self.executor = sweep, out, executor
        self.manifest, self.options = manifest, options
        self.env = {**options.train_env, **thread_env(sweep.cpus_per_unit, out / ".jax-cache")}
        self.width = max(len(u.id) for u in sweep.units)
        self.in_flight: dict[cf.Future, tuple[Unit, int]] = {}
        self.tries: Counter[str] = Counter()
        self.start_step: dict[str, int] = {}  # step each running attempt started from
        self.skipped = 0
        self.waiting: list[Unit] = []  # fork units whose parent has not reached the fork point
        self.ready: list[Unit] = []  # queued units not yet handed to the executor
        from adarl.sweeps.estimate import start_order

        self.order = {u.id: i for i, u in enumerate(start_order(sweep, out))}

    # ------------------------------------------------------------------ loop
    def run(self) -> int:
        start = time.monotonic()
        echo(
            f"sweep {self.sweep.name}: {len(self.sweep.units)} units on {self.executor.where}, "
            f"output {self.out}"
        )
        for unit in self.sweep.units:
            state = unit_state(self.out, unit)
            if state == "done":
                self.skipped += 1
                self.manifest.update(unit.id, status="done")
                self.line(unit, "done", "(finished before; skipped)")
            else:
                self.manifest.update(unit.id, status="queued", error=None)
                if state == "start" and unit.fork_of:
                    state = f"start: a fork of {unit.fork_of} at step {unit.fork_step:,}"
                self.line(unit, "queued", f"({state})")
        for unit in self.sweep.units:
            if self.manifest.unit(unit.id)["status"] == "queued":
                if unit.fork_of and not fork_ready(self.out, unit):
                    self.waiting.append(unit)
                else:
                    self.ready.append(unit)
        self.dispatch()
        self.manifest.save()
        last_progress = time.monotonic()
        try:
            while self.in_flight or self.waiting or self.ready:
                if self.in_flight:
                    finished, _ = cf.wait(
                        list(self.in_flight), timeout=POLL_S, return_when=cf.FIRST_COMPLETED
                    )
                else:
                    finished = []
                    time.sleep(POLL_S)
                self.notice_started()
                for future in finished:
                    self.finish(future)
                self.release_forks()
                self.dispatch()
                if time.monotonic() - last_progress >= self.options.progress_every:
                    self.progress_lines()
                    last_progress = time.monotonic()
                self.manifest.save()
        except BaseException as exc:  # Ctrl-C, SIGTERM (or a bug): stop the units, record where
            # they were; each running unit gets SIGTERM and writes a checkpoint where it stops
            self.executor.close(cancel=True)
            for unit, _ in self.in_flight.values():
                self.manifest.update(unit.id, status="queued", error="interrupted", pid=None)
            self.manifest.save()
            if isinstance(exc, KeyboardInterrupt):
                echo("sweep interrupted; run the same command again to resume it")
            raise
        return self.summary(time.monotonic() - start)

    def dispatch(self) -> None:
        """Hand ready units to the executor while it has a free slot, in `estimate.start_order`."""
        while self.ready and len(self.in_flight) < self.executor.slots:
            unit = min(self.ready, key=lambda u: self.order[u.id])
            self.ready.remove(unit)
            self.submit(unit)

    def submit(self, unit: Unit) -> None:
        record = self.manifest.unit(unit.id)
        attempt = int(record.get("attempts", 0)) + 1
        self.tries[unit.id] += 1
        self.manifest.update(unit.id, status="queued", attempts=attempt)
        self.in_flight[self.executor.submit(run_job, self.job(unit, attempt))] = (unit, attempt)

    def job(self, unit: Unit, attempt: int) -> dict:
        return {
            "worker_args": [
                "--run-dir",
                str(self.out / unit.id),
                "--lock",
                str(self.state_file(unit, "lock")),
                "--marker",
                str(self.state_file(unit, "started.json")),
                "--attempt",
                str(attempt),
                *self.options.train_extra,
                f"--env-module={unit.config.env_module}",  # the sweep file's: yours, named
                f"--unit={json.dumps(launch.record(unit.start_in(self.out)))}",
            ],
            "log": str(self.out / "logs" / f"{unit.flat_id}.log"),
            "env": self.env,
        }

    def state_file(self, unit: Unit, suffix: str) -> Path:
        return self.out / ".state" / f"{unit.flat_id}.{suffix}"

    # ------------------------------------------------------------------ events
    def notice_started(self) -> None:
        """Mark in-flight units whose worker has written this attempt's marker as running."""
        for unit, attempt in list(self.in_flight.values()):
            record = self.manifest.unit(unit.id)
            if record["status"] != "queued":
                continue
            marker = _read_json(self.state_file(unit, "started.json"))
            if not marker or marker.get("attempt") != attempt:
                continue
            self.manifest.update(
                unit.id,
                status="running",
                pid=marker.get("pid"),
                host=marker.get("host"),
                step=marker.get("step", 0),
                started=marker.get("time"),
            )
            self.start_step[unit.id] = int(marker.get("step", 0))
            how = {
                "fresh": "from scratch",
                "done": "already done",
                "resume": f"resuming from step {marker.get('step', 0):,}",
            }.get(marker["mode"])
            self.line(
                unit,
                "running",
                f"attempt {attempt}, {how}, on {marker.get('host')} pid {marker.get('pid')}",
            )

    def finish(self, future: cf.Future) -> None:
        unit, attempt = self.in_flight.pop(future)
        try:
            returncode, error = future.result()["returncode"], None
        except Exception as exc:  # a Ray worker that died, or a job that could not start
            returncode, error = None, _one_line(f"{type(exc).__name__}: {exc}")
        if error is None and returncode != 0:
            error = exit_text(returncode)
        done = (self.out / unit.id / DONE_FILE).exists()
        if returncode == 0 and not done:
            error = "exited without finishing (no DONE)"
        elapsed = self._elapsed(unit)
        if error is None:
            self.manifest.update(
                unit.id,
                status="done",
                returncode=0,
                error=None,
                pid=None,
                step=unit.total_steps,
                finished=time.time(),
            )
            self.line(unit, "done", f"attempt {attempt}{elapsed}")
            return
        last = _last_line(self.out / "logs" / f"{unit.flat_id}.log")
        detail = f"{error}{f': {last}' if last else ''}"
        self.manifest.update(unit.id, returncode=returncode, error=detail, pid=None)
        reason = NOT_RETRIED.get(returncode)
        if reason is None and self.tries[unit.id] <= self.options.max_retries:
            left = self.options.max_retries + 1 - self.tries[unit.id]
            self.line(
                unit,
                "failed",
                f"attempt {attempt}: {detail}; retrying ({left} attempt{'s' * (left != 1)} left)",
            )
            self.manifest.update(unit.id, status="queued")
            self.ready.append(unit)
        else:
            self.manifest.update(unit.id, status="failed", finished=time.time())
            why = f" ({reason}, not retried)" if reason else ""
            self.line(
                unit,
                "failed",
                f"attempt {attempt}{why}: {detail}; log "
                f"{self.out / 'logs' / (unit.flat_id + '.log')}",
            )

    def release_forks(self) -> None:
        """Submit the waiting forks whose parent has written their fork point; fail those whose
        parent failed or ended without it (they wait again when the sweep is re-run)."""
        running = {unit.id for unit, _ in self.in_flight.values()}
        for unit in list(self.waiting):
            parent = self.manifest.unit(unit.fork_of)
            if fork_ready(self.out, unit):
                self.waiting.remove(unit)
                self.line(unit, "queued", f"({unit.fork_of} reached step {unit.fork_step:,})")
                self.ready.append(unit)
            elif unit.fork_of not in running and parent["status"] in ("failed", "done"):
                self.waiting.remove(unit)
                why = (
                    f"its parent {unit.fork_of} failed"
                    if parent["status"] == "failed"
                    else f"its parent {unit.fork_of} has no checkpoint at step {unit.fork_step:,}"
                )
                self.manifest.update(unit.id, status="failed", error=why, finished=time.time())
                self.line(unit, "failed", why)

    def progress_lines(self) -> None:
        for unit, _ in self.in_flight.values():
            if self.manifest.unit(unit.id)["status"] != "running":
                continue
            found = last_train_row(self.out / unit.id / TRAIN_CSV)
            start = self.start_step.get(unit.id, 0)
            if found is None or found[0] <= start:  # nothing logged by this attempt yet
                self.line(unit, "running", f"starting at step {start:,} (compiling, loading)")
                continue
            step, rate = found
            self.manifest.update(unit.id, step=step, steps_per_s=rate)
            left = (unit.total_steps - step) / rate if rate > 0 else None
            eta = f", eta {duration(left)}" if left is not None else ""
            self.line(
                unit,
                "running",
                f"step {step:,}/{unit.total_steps:,} "
                f"({100 * step / unit.total_steps:.0f}%), "
                f"{rate:,.0f} steps/s{eta}",
            )

    def line(self, unit: Unit, status: str, detail: str) -> None:
        echo(f"{time.strftime('%H:%M:%S')} {unit.id:<{self.width}}  {status:<7}  {detail}")

    def summary(self, seconds: float) -> int:
        units = self.manifest.data["units"]
        ids = [u.id for u in self.sweep.units]
        done = [i for i in ids if units[i]["status"] == "done"]
        failed = [i for i in ids if units[i]["status"] == "failed"]
        echo(
            f"sweep {self.sweep.name}: {len(ids)} units, {len(done)} done "
            f"({self.skipped} before this run), {len(failed)} failed, in {duration(seconds)}"
        )
        for uid in failed:
            record = units[uid]
            echo(
                f"  failed: {uid} after {record['attempts']} attempt"
                f"{'s' * (record['attempts'] != 1)}: {record.get('error')}"
            )
        if failed:
            echo("re-run the same command to retry the failed units (finished ones are kept)")
        echo(f"manifest: {self.manifest.path}")
        echo(f"report:   adarl report {self.out} --out {self.out / 'report'}")
        return 1 if failed else 0

    def _elapsed(self, unit: Unit) -> str:
        started = self.manifest.unit(unit.id).get("started")
        return f" in {duration(time.time() - started)}" if started else ""


# ----------------------------------------------------------------------------- helpers
def fork_ready(out: Path, unit: Unit) -> bool:
    """Has the parent of fork unit `unit` written the checkpoint the fork starts from?"""
    from adarl.train import fork

    return unit.fork_step in fork.fork_points(out / unit.fork_of)


def last_train_row(path: Path) -> tuple[int, float] | None:
    """(step, steps_per_s) of the last complete row of a run's train.csv, if it has one."""
    try:
        with open(path, "rb") as f:
            header = f.readline(1 << 16).decode(errors="replace").strip().split(",")
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - 4096))
            tail = f.read().decode(errors="replace")
    except OSError:
        return None
    rows = [r for r in tail.split("\n")[:-1] if r and not r.startswith("step,")]
    if not rows or "step" not in header or "steps_per_s" not in header:
        return None
    cells = rows[-1].split(",")
    try:
        return (int(float(cells[header.index("step")])), float(cells[header.index("steps_per_s")]))
    except (IndexError, ValueError):
        return None


@contextlib.contextmanager
def sigterm_as_interrupt():
    """SIGTERM (`kill PID`, a batch system's preemption) stops a sweep as Ctrl-C does: its
    running units get SIGTERM in turn (`adarl.sweeps.job.stop_children`), each writes a
    checkpoint at the end of its current step (`adarl.train.loop.StopSignals`), and the same
    command resumes them from there. Only the main thread can take signals."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)


def exit_text(returncode: int | None) -> str:
    if returncode is not None and returncode < 0:
        try:
            return f"killed by {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"exit {returncode}"


def _read_json(path: Path):
    try:
        return read_json(path)
    except (OSError, ValueError):  # UnreadableFile is a ValueError
        return None


def _last_line(path: Path) -> str:
    """The last non-empty line of a log, shortened (the error message of a failed attempt)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - 2048))
            lines = [s.strip() for s in f.read().decode(errors="replace").splitlines()]
    except OSError:
        return ""
    lines = [s for s in lines if s and not s.startswith(("===", "$ "))]  # the worker's own
    return _one_line(lines[-1]) if lines else ""


def _one_line(text: str, limit: int = 200) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 1] + "…"
