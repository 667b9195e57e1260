"""adarl's one executor (`adarl.executor`), local part: results in the order of the tasks, a
cancel that drops queued tasks and stops running ones, one-line errors for bad settings, and
spawned workers that exit when the process that started them dies (issue 38, class 5: two idle
workers outlived a killed parent by 41 minutes). Ray: tests/evaluation/test_suites.py and
tests/sweeps (a local instance and a two-node cluster)."""

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from adarl import executor
from adarl.errors import UsageError

PARENT = """
import os, sys
from adarl.executor import process_pool
pool = process_pool(2)
pids = {pool.submit(os.getpid).result() for _ in range(8)}
while len(pids) < 2:  # both workers started (each takes a task once it is up)
    pids |= {f.result() for f in [pool.submit(os.getpid) for _ in range(4)]}
print(" ".join(map(str, sorted(pids))), flush=True)
sys.stdin.read()  # idle until killed
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie (exited, not yet reaped) is gone too
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(") ", 1)[1][0] != "Z"
    except OSError:
        return True


def test_idle_workers_exit_when_their_parent_is_killed():
    parent = subprocess.Popen(
        [sys.executable, "-c", PARENT], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        workers = [int(p) for p in parent.stdout.readline().split()]
        assert len(workers) == 2 and all(map(_alive, workers)), workers
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    deadline = time.monotonic() + 10
    while any(map(_alive, workers)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(map(_alive, workers)), [p for p in workers if _alive(p)]


def _square_after(x):
    time.sleep(0.02 * (3 - x))  # the first task finishes last
    return x * x


def test_results_come_in_the_order_of_the_tasks():
    done = []
    with executor.start("local", 3, threads=True) as pool:
        got = executor.run_in_order(pool, _square_after, [0, 1, 2], lambda: done.append(1))
    assert got == [0, 1, 4] and len(done) == 3


def test_one_worker_without_threads_runs_in_this_process():
    with executor.start("local", 1) as pool:
        assert pool.inline
        assert executor.run_in_order(pool, lambda _: os.getpid(), [0, 1]) == [os.getpid()] * 2
        future = pool.submit(int, "x")
    assert isinstance(future.exception(), ValueError)


def test_cancel_drops_queued_tasks_and_stops_running_ones():
    started, release = threading.Event(), threading.Event()

    def wait(_):
        started.set()
        release.wait(10)
        return "stopped"

    pool = executor.start("local", 1, threads=True, stop_running=release.set)
    running, queued = pool.submit(wait, 0), pool.submit(wait, 1)
    assert started.wait(10)
    pool.close(cancel=True)  # returns once the running task has ended
    assert queued.cancelled() and running.result(timeout=0) == "stopped"


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"backend": "slurm"}, "unknown backend 'slurm'; allowed: local, ray"),
        ({"workers": 0}, "--workers must be ≥ 1, got 0"),
        ({"address": "h:1"}, "--address is for --backend ray; allowed: --backend ray"),
    ],
)
def test_bad_settings_are_one_line_errors(kwargs, message):
    with pytest.raises(UsageError) as info:
        executor.start(**kwargs)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_ray_address_that_is_not_host_port():
    with pytest.raises(UsageError, match="is not HOST:PORT, ray://HOST:PORT or auto"):
        executor.check_reachable("nowhere")
