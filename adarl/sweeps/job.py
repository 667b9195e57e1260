"""One attempt at one sweep unit, as the sweep hands it to adarl's executor (`adarl.executor`):
`run_job` starts one `adarl.sweeps.worker` subprocess with its output appended to the unit's log
and waits for it. Locally the executor's workers are threads, each waiting on its unit's
subprocess (the subprocesses use the cores; `stop_children` ends them on Ctrl-C); on Ray each
job is a task declaring `cpus_per_unit` CPUs. Run folders are written by the node that trains
them, so on a cluster the sweep folder must be on a shared filesystem.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

from adarl.runtime import with_xla_flags


def thread_env(cpus: int, cache_dir: Path | None = None) -> dict[str, str]:
    """Environment for a unit's process: XLA (one thread per computation, `cpus` CPU devices),
    OpenMP and BLAS limited to `cpus` threads so that concurrent units do not fight over cores; JAX's compilation cache in `cache_dir` (unless the
    caller's environment already names one) so resumed and retried units skip recompiling."""
    env = {"XLA_FLAGS": with_xla_flags(os.environ.get("XLA_FLAGS", ""), cpus)}
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        env[name] = str(cpus)
    if cache_dir is not None and "JAX_COMPILATION_CACHE_DIR" not in os.environ:
        env["JAX_COMPILATION_CACHE_DIR"] = str(cache_dir)
        env.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
    return env


_children: set[subprocess.Popen] = set()
_children_lock = threading.Lock()


def run_job(job: dict) -> dict:
    """Run one attempt of one unit and wait for it. `job`: `worker_args` (after
    `python -m adarl.sweeps.worker`), `log` (appended to) and `env` (added to this process's).
    Returns the exit status (negative: killed by that signal) and the host."""
    log = Path(job["log"])
    log.parent.mkdir(parents=True, exist_ok=True)
    command = [
        sys.executable,
        "-m",
        "adarl.sweeps.worker",
        "--parent",
        str(os.getpid()),
        *job["worker_args"],
    ]
    with open(log, "ab") as out:
        proc = subprocess.Popen(
            command,
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env={**os.environ, **job["env"]},
            start_new_session=True,
        )  # Ctrl-C reaches the sweep, not units
        # a new session is a new scheduling group at nice 0: give the unit the sweep's own, so a
        # sweep started at the lowest CPU share (shared/tools/background) keeps its units there
        nice = autogroup_nice("self")
        if nice is not None:
            set_autogroup_nice(proc.pid, nice)
        with _children_lock:
            _children.add(proc)
        try:
            returncode = proc.wait()
        finally:
            with _children_lock:
                _children.discard(proc)
    return {"returncode": returncode, "host": socket.gethostname()}


def autogroup_nice(pid: int | str) -> int | None:
    """The nice value of `pid`'s scheduling group (Linux autogroup: one per session, and the
    scheduler shares the CPU between groups by this value, not by the processes' own nice);
    None where the kernel has no autogroups."""
    try:
        text = Path(f"/proc/{pid}/autogroup").read_text()
    except OSError:
        return None
    _, _, value = text.strip().rpartition(" ")
    return int(value) if value.lstrip("-").isdigit() else None


def set_autogroup_nice(pid: int, nice: int) -> None:
    """Set `pid`'s scheduling-group nice (best effort: nothing where it cannot be set)."""
    try:
        Path(f"/proc/{pid}/autogroup").write_text(str(nice))
    except OSError:
        pass


def stop_children(grace_s: float = 60.0) -> None:
    """SIGTERM every unit process this process started, then SIGKILL what is left after
    `grace_s`: time for each to finish its step and write its checkpoint (a run's checkpoint
    holds its replay buffers; Humanoid's at 140k steps × 5 seeds is 1.1 GB)."""
    with _children_lock:
        procs = list(_children)
    for proc in procs:
        _signal(proc, signal.SIGTERM)
    for proc in procs:
        try:
            proc.wait(timeout=grace_s)
        except subprocess.TimeoutExpired:
            _signal(proc, signal.SIGKILL)
            proc.wait()


def _signal(proc: subprocess.Popen, sig: int) -> None:
    try:
        proc.send_signal(sig)
    except ProcessLookupError:
        pass


def start_executor(backend: str, address: str | None, workers: int | None, cpus_per_unit: int):
    """adarl's executor (`adarl.executor.start`) for a sweep's jobs: locally one thread per
    unit at once (the unit's subprocess does the work, and Ctrl-C stops it), on Ray one task of
    `cpus_per_unit` CPUs per job, never retried by Ray (the sweep retries its units itself)."""
    from adarl import executor

    return executor.start(
        backend,
        workers,
        address,
        cpus_per_task=cpus_per_unit,
        threads=True,
        stop_running=stop_children,
        retry_lost=False,
    )
