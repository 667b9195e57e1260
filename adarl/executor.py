"""The one executor of adarl: tasks on a pool of local workers or on Ray, each handed back as a
`concurrent.futures.Future`, so a caller does not care which backend it talks to. The evaluation
engine (`adarl.evaluation.parallel`) runs its units through it, and sweeps
(`adarl.sweeps.runner`) their training jobs.

* `LocalExecutor`: `workers` spawned processes, for tasks that compute; or `workers` threads
  (`threads=True`), for tasks that only wait on a subprocess of their own (a sweep's units); or
  this process, for one worker without threads.
* `RayExecutor`: one Ray task per task, declaring `cpus_per_task` CPUs, on a local Ray instance
  it starts (`workers` × `cpus_per_task` CPUs) or on the cluster at `address`, checked first to
  answer (a one-line error otherwise).

Processes are started with `spawn`: a forked child of a process that has loaded JAX (a test run,
a notebook) can deadlock on JAX's threads; a spawned one costs only its imports.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Sequence

from adarl.errors import UsageError, check_choice
from adarl.runtime import available_cores

BACKENDS = ("local", "ray")
RAY_INSTALL = "pip install 'adarl[ray]'"


def start(
    backend: str = "local",
    workers: int | None = None,
    address: str | None = None,
    cpus_per_task: int = 1,
    threads: bool = False,
    stop_running: Callable[[], None] | None = None,
    retry_lost: bool = True,
):
    """A started executor; a one-line UsageError (nothing started) on a bad backend, worker count
    or address, or a Ray that cannot be reached. `workers` defaults to `default_workers`.
    Local only: `threads` and `stop_running` (`LocalExecutor`). Ray only: `address`,
    `retry_lost` (`RayExecutor`)."""
    check_choice("backend", backend, BACKENDS)
    if workers is not None and workers < 1:
        raise UsageError(f"--workers must be ≥ 1, got {workers}")
    if address and backend != "ray":
        raise UsageError(
            "--address is for --backend ray; allowed: --backend ray --address HOST:PORT"
        )
    workers = workers or default_workers(cpus_per_task)
    if backend == "ray":
        return RayExecutor(address, workers, cpus_per_task, retry_lost)
    return LocalExecutor(workers, threads, stop_running)


def default_workers(cpus_per_task: int = 1) -> int:
    """Tasks at once on this machine: its available cores over `cpus_per_task`."""
    return max(1, available_cores() // cpus_per_task)


def run_in_order(executor, fn: Callable, items: Sequence, each_done: Callable[[], None] = None):
    """`[fn(item) for item in items]` on `executor`, in the order of `items` whatever the order
    they finish in; `each_done()` after each. The first error stops the rest (`close(cancel=True)`
    on the executor is the caller's)."""
    done = each_done or (lambda: None)
    results: list = [None] * len(items)
    if executor.inline:  # one at a time, in this process
        for i, item in enumerate(items):
            results[i] = fn(item)
            done()
        return results
    futures = {executor.submit(fn, item): i for i, item in enumerate(items)}
    for future in cf.as_completed(futures):
        results[futures[future]] = future.result()
        done()
    return results


class LocalExecutor:
    """`workers` spawned processes, or threads (`threads=True`), or this process (one worker,
    no threads). `stop_running` ends the work of running tasks on `close(cancel=True)`, for tasks
    whose work is a subprocess of their own (a thread cannot be stopped; its subprocess can)."""

    name = "local"

    def __init__(
        self, workers: int, threads: bool = False, stop_running: Callable[[], None] | None = None
    ):
        self.workers = self.slots = workers  # tasks at once
        self.threads = threads
        self.where = f"{workers} local worker{'s' * (workers != 1)}"
        self._stop_running = stop_running
        self.inline = workers == 1 and not threads
        if self.inline:
            self._pool = None
        elif threads:
            self._pool = cf.ThreadPoolExecutor(max_workers=workers, thread_name_prefix="task")
        else:
            self._pool = process_pool(workers)

    def submit(self, fn: Callable, item) -> cf.Future:
        if self._pool is not None:
            return self._pool.submit(fn, item)
        future = cf.Future()
        try:
            future.set_result(fn(item))
        except Exception as exc:
            future.set_exception(exc)
        return future

    def close(self, cancel: bool = False) -> None:
        """Wait for the submitted tasks; with `cancel`, drop the queued ones and stop the running
        ones first (`stop_running`). Cancelled spawned processes are not waited for: their task
        runs to its end, or the process exits with this one (`exit_with_parent`)."""
        if self._pool is None:
            return
        if cancel:
            self._pool.shutdown(wait=False, cancel_futures=True)
            if self._stop_running is not None:
                self._stop_running()
            if not self.threads:
                return
        self._pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self):
        return self

    def __exit__(self, kind, value, traceback) -> None:
        self.close(cancel=kind is not None)


class RayExecutor:
    """One Ray task per task (`cpus_per_task` CPUs each), on the cluster at `address` or on a
    local Ray instance of `workers` × `cpus_per_task` CPUs, which `close` stops. `retry_lost`:
    Ray runs a task again when its worker dies (its default); off where the caller retries."""

    name = "ray"
    inline = False

    def __init__(
        self, address: str | None, workers: int, cpus_per_task: int = 1, retry_lost: bool = True
    ):
        self._ray = connect_ray(address, workers * cpus_per_task)
        self._options = {"num_cpus": cpus_per_task, **({} if retry_lost else {"max_retries": 0})}
        self._remote: dict[Callable, object] = {}
        self._refs: dict[cf.Future, object] = {}
        cpus = int(self._ray.cluster_resources().get("CPU", 0))
        self.slots = max(1, cpus // cpus_per_task)  # tasks at once
        self.where = (
            f"Ray cluster at {address} ({cpus} CPUs)"
            if address
            else f"local Ray instance ({cpus} CPUs)"
        )

    def submit(self, fn: Callable, item) -> cf.Future:
        if fn not in self._remote:
            self._remote[fn] = self._ray.remote(**self._options)(fn)
        ref = self._remote[fn].remote(item)
        future = ref.future()
        self._refs[future] = ref
        return future

    def close(self, cancel: bool = False) -> None:
        """With `cancel`, cancel the unfinished tasks (force: their workers are killed); then
        stop the local instance this started, or disconnect from the cluster."""
        if cancel:
            for future, ref in self._refs.items():
                if not future.done():
                    self._ray.cancel(ref, force=True)
        self._refs.clear()
        self._ray.shutdown()

    def __enter__(self):
        return self

    def __exit__(self, kind, value, traceback) -> None:
        self.close(cancel=kind is not None)


# ----------------------------------------------------------------------------- local processes
def process_pool(workers: int) -> cf.ProcessPoolExecutor:
    """A `spawn` pool of `workers` processes that exit when this process dies (killed, it cannot
    shut them down; idle ones would otherwise wait on their queue for ever)."""
    return cf.ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=exit_with_parent,
        initargs=(os.getpid(),),
    )


def exit_with_parent(parent: int, poll_s: float = 1.0) -> None:
    """In a worker process: exit as soon as process `parent` is gone. On Linux the kernel sends
    SIGKILL when the parent dies (PR_SET_PDEATHSIG); everywhere a daemon thread checks every
    `poll_s` seconds that the worker still has that parent."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # 1: PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # died before we could ask
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_s)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


# ----------------------------------------------------------------------------- Ray
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
