"""The evaluation engine's local process pool (`adarl.evaluation.parallel`): its workers exit when
the process that started them dies (issue 38, class 5: two idle workers outlived a killed parent
by 41 minutes)."""

import os
import signal
import subprocess
import sys
import time

PARENT = """
import os, sys
from adarl.evaluation.parallel import local_pool
pool = local_pool(2)
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
