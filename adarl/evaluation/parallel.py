"""The one evaluation engine: running evaluation units (one seed's policy at one grid point,
`adarl.evaluation.evaluate.Unit`) in parallel, with a progress bar, over a pool of local
processes or over Ray. `adarl evaluate` and `adarl evaluate --suite` both run through it.

Local workers are started with `spawn`: a forked child of a process that has loaded JAX (a test
run, a notebook) can deadlock on JAX's threads, and a spawned one costs only its imports (no JAX:
policies are NumPy files). Results come back in the order of the units whatever the backend and
the number of workers, so the files written do not depend on them.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed

from adarl.errors import UsageError, check_choice
from adarl.runtime import available_cores

BACKENDS = ("local", "ray")


def run_unit(unit) -> list[dict]:
    """Run one unit's episodes; rows carry `step, seed, dynamics` in front."""
    from adarl.envs.rollout import run_episodes
    from adarl.policy import load

    policy = load(unit.policy_path)
    rows = run_episodes(
        policy,
        unit.task,
        unit.dynamics,
        unit.episodes,
        unit.eval_seed,
        max_steps=unit.max_steps,
        **dict(unit.point),
        **dict(unit.env),
    )
    head = {"step": unit.step, "seed": unit.seed, "dynamics": unit.label}
    return [{**head, **row} for row in rows]


def run_units(
    units: Sequence,
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    progress: bool = True,
    desc: str = "evaluate",
) -> list[list[dict]]:
    """Each unit's episode rows (`run_unit`), in the order of `units`.

    `backend`: `local` (a `spawn` process pool of `workers`, default all cores; one worker runs
    in this process) or `ray` (one Ray task per unit, on a local Ray instance of `workers` CPUs
    or on the cluster at `address`)."""
    check_choice("backend", backend, BACKENDS)
    workers = available_cores() if workers is None else workers
    if workers < 1:
        raise UsageError(f"--workers must be ≥ 1, got {workers}")
    if address and backend != "ray":
        raise UsageError(
            "--address is for --backend ray; allowed: --backend ray --address HOST:PORT"
        )
    bar = _progress(len(units), desc, progress)
    try:
        if backend == "ray":
            return _run_ray(units, workers, address, bar)
        return _run_local(units, min(workers, max(len(units), 1)), bar)
    finally:
        if bar is not None:
            bar.close()


def _run_local(units: Sequence, workers: int, bar) -> list[list[dict]]:
    if workers <= 1:
        results = []
        for unit in units:
            results.append(run_unit(unit))
            _tick(bar)
        return results
    results: list = [None] * len(units)
    pool = local_pool(workers)
    try:
        futures = {pool.submit(run_unit, unit): i for i, unit in enumerate(units)}
        for future in as_completed(futures):
            results[futures[future]] = future.result()
            _tick(bar)
    except BaseException:  # an error or Ctrl-C: drop the queued units rather than run them all
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    return results


def local_pool(workers: int) -> ProcessPoolExecutor:
    """A `spawn` pool of `workers` processes that exit when this process dies (killed, it cannot
    shut them down; idle ones would otherwise wait on their queue for ever)."""
    return ProcessPoolExecutor(
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


def _run_ray(units: Sequence, workers: int, address: str | None, bar) -> list[list[dict]]:
    from adarl.cluster import connect_ray

    ray = connect_ray(address, workers)
    try:
        remote = ray.remote(num_cpus=1)(run_unit)
        refs = [remote.remote(unit) for unit in units]
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            _tick(bar, len(done))
        return ray.get(refs)
    finally:
        ray.shutdown()


def _progress(total: int, desc: str, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="unit", dynamic_ncols=True, file=sys.stderr)


def _tick(bar, n: int = 1) -> None:
    if bar is not None:
        bar.update(n)
