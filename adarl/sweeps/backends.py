"""Where units run. Both backends run the same job, `run_job`: one `adarl.sweeps.worker`
subprocess with its output appended to the unit's log, and both hand back a
`concurrent.futures.Future` per job, so the sweep's loop (adarl.sweeps.runner) does not care which
one it talks to.

* `LocalBackend`: a pool of `workers` slots on this machine. The slots are threads, each waiting
  on its unit's training subprocess: the subprocesses are the workers that use the cores.
* `RayBackend`: each job is a Ray task declaring `cpus_per_unit` CPUs, on a local Ray instance
  it starts (sized to `workers`) or on the cluster at `address`. Run folders are written by the
  node that trains them, so on a cluster the sweep folder must be on a shared filesystem.
"""

from __future__ import annotations

import concurrent.futures as cf
import os
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

from adarl.cluster import connect_ray
from adarl.errors import UsageError
from adarl.runtime import available_cores, with_xla_flags


# ----------------------------------------------------------------------------- the job
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


def stop_children(grace_s: float = 10.0) -> None:
    """SIGTERM every unit process this process started, then SIGKILL what is left."""
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


# ----------------------------------------------------------------------------- backends
def default_workers(cpus_per_unit: int = 1) -> int:
    """Units at once on this machine: its available cores over `cpus_per_unit`."""
    return max(1, available_cores() // cpus_per_unit)


class LocalBackend:
    name = "local"

    def __init__(self, workers: int):
        self.workers = workers
        self.slots = workers  # units at once
        self.where = f"{workers} local worker{'s' * (workers != 1)}"
        self._pool = cf.ThreadPoolExecutor(max_workers=workers, thread_name_prefix="unit")

    def submit(self, job: dict) -> cf.Future:
        return self._pool.submit(run_job, job)

    def close(self, interrupted: bool = False) -> None:
        if interrupted:
            self._pool.shutdown(wait=False, cancel_futures=True)
            stop_children()
        self._pool.shutdown(wait=True, cancel_futures=True)


class RayBackend:
    name = "ray"

    def __init__(self, address: str | None, workers: int, cpus_per_unit: int):
        ray = connect_ray(address, workers * cpus_per_unit)
        self._ray = ray
        self._remote = ray.remote(num_cpus=cpus_per_unit, max_retries=0)(run_job)
        self._refs: dict[cf.Future, object] = {}
        cpus = int(ray.cluster_resources().get("CPU", 0))
        self.slots = max(1, cpus // cpus_per_unit)  # units at once
        self.where = (
            f"Ray cluster at {address} ({cpus} CPUs)"
            if address
            else f"local Ray instance ({cpus} CPUs)"
        )

    def submit(self, job: dict) -> cf.Future:
        ref = self._remote.remote(job)
        future = ref.future()
        self._refs[future] = ref
        return future

    def close(self, interrupted: bool = False) -> None:
        if interrupted:
            for future, ref in self._refs.items():
                if not future.done():
                    self._ray.cancel(ref, force=True)
        self._refs.clear()
        self._ray.shutdown()  # stops the local instance it started; only disconnects otherwise


def make_backend(kind: str, address: str | None, workers: int | None, cpus_per_unit: int):
    """A started backend; a one-line UsageError (nothing started) if it cannot start."""
    if kind == "local":
        if address:
            raise UsageError("--address is for --backend ray")
        return LocalBackend(workers or default_workers(cpus_per_unit))
    return RayBackend(address, workers or default_workers(cpus_per_unit), cpus_per_unit)
