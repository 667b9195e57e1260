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

from adarl.errors import UsageError
from adarl.runtime import with_xla_flags

RAY_INSTALL = "pip install 'adarl[ray]'"


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
        with _children_lock:
            _children.add(proc)
        try:
            returncode = proc.wait()
        finally:
            with _children_lock:
                _children.discard(proc)
    return {"returncode": returncode, "host": socket.gethostname()}


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
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, (cores or 1) // cpus_per_unit)


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


def connect_ray(address: str | None, cpus: int):
    """`ray.init` on the cluster at `address` (checked to answer first), or on a local instance
    with `cpus` CPUs; returns the `ray` module. Any failure is a one-line `UsageError`."""
    ray = import_ray()
    if address:
        check_reachable(address)
    try:
        if address:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        else:
            ray.init(num_cpus=cpus, include_dashboard=False, log_to_driver=False)
    except (ConnectionError, OSError, RuntimeError, ValueError, ray.exceptions.RayError) as exc:
        ray.shutdown()
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        where = f"the Ray cluster at {address}" if address else "a local Ray instance"
        raise UsageError(f"cannot start or reach {where}: {message}") from None
    return ray


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


def import_ray():
    try:
        import ray
    except ImportError:
        raise UsageError(
            f"--backend ray needs Ray, which is not installed; install it with: {RAY_INSTALL}"
        ) from None
    return ray


CONNECT_TIMEOUT_S = 5.0  # for the TCP connection and for the first HTTP/2 frame
# An HTTP/2 client's connection preface and an empty SETTINGS frame: every gRPC server (Ray's GCS,
# its client server) answers with a SETTINGS frame of its own.
_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])


def check_reachable(address: str, timeout_s: float | None = None) -> None:
    """A one-line UsageError unless a gRPC server answers at a Ray address within `timeout_s`
    (default CONNECT_TIMEOUT_S): ray.init would otherwise wait minutes on a host that drops
    packets or a port that accepts and never answers. `auto` is left to Ray, which fails fast
    when it finds no cluster."""
    if address == "auto":
        return
    timeout_s = CONNECT_TIMEOUT_S if timeout_s is None else timeout_s
    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise UsageError(f"Ray address {address!r} is not HOST:PORT, ray://HOST:PORT or auto")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s) as conn:
            if os.environ.get("RAY_USE_TLS", "0").lower() in ("0", "false", ""):
                conn.sendall(_HTTP2_PREFACE)
                frame = _read_exactly(conn, 9)
                if len(frame) < 9 or frame[3] != 4:  # frame type 4: SETTINGS
                    raise UsageError(
                        f"the Ray cluster at {address} does not answer: something listens "
                        f"there but it is not a Ray head node (no gRPC reply)"
                    )
    except TimeoutError:
        raise UsageError(
            f"the Ray cluster at {address} does not answer (no reply in {timeout_s:g} s)"
        ) from None
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise UsageError(f"cannot reach the Ray cluster at {address}: {reason}") from None


def _read_exactly(conn: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = conn.recv(n - len(data))
        if not chunk:
            break
        data += chunk
    return data


def make_backend(kind: str, address: str | None, workers: int | None, cpus_per_unit: int):
    """A started backend; a one-line UsageError (nothing started) if it cannot start."""
    if kind == "local":
        if address:
            raise UsageError("--address is for --backend ray")
        return LocalBackend(workers or default_workers(cpus_per_unit))
    return RayBackend(address, workers or default_workers(cpus_per_unit), cpus_per_unit)
