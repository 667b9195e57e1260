"""A sweep on a real two-node Ray cluster on this machine (`ray start --head`, then a second
`ray start --address` as a worker node, one CPU each): the worker node is killed while it trains
a unit, and the sweep still finishes, that unit resumed from its checkpoint on the head node,
with results bit-identical to an uninterrupted local run.

Ray's processes are found and stopped by this cluster's own temp folder and ports, never by name,
so Ray instances of other tests or users on the machine are left alone."""

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from adarl.runs import checkpoints
from adarl.runs.logs import read_csv

pytestmark = pytest.mark.cluster  # not in the default run: `pytest -m cluster` (pyproject.toml)
pytest.importorskip("ray")
if not Path("/proc/self/cmdline").exists():
    pytest.skip("finds the cluster's processes in /proc (Linux)", allow_module_level=True)

RAY = str(Path(sys.executable).with_name("ray"))
BUDGET = 2000


# ----------------------------------------------------------------------------- processes (/proc)
def _processes() -> dict[int, tuple[int, list[str]]]:
    """pid -> (parent pid, command line) of every process."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes().split(b"\0")
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        ppid = int(stat[stat.rindex(")") + 2 :].split()[1])
        found[int(entry.name)] = (ppid, [part.decode(errors="replace") for part in cmdline])
    return found


def _with_descendants(roots: set[int], table: dict) -> set[int]:
    pids, grew = set(roots), True
    while grew:
        more = {pid for pid, (ppid, _) in table.items() if ppid in pids} - pids
        pids |= more
        grew = bool(more)
    return pids


def _ancestors(pid: int, table: dict) -> set[int]:
    out = set()
    while pid in table and pid > 1:
        pid = table[pid][0]
        out.add(pid)
    return out


def _kill(pids: set[int], timeout_s: float = 10) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and pids & set(_processes()):
        time.sleep(0.05)


# ----------------------------------------------------------------------------- the cluster
def _free_ports(n: int) -> list[int]:
    sockets = [socket.socket() for _ in range(n)]
    for s in sockets:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in sockets]
    for s in sockets:
        s.close()
    return ports


def _node_flags(ports: list[int]) -> list[str]:
    names = (
        "--node-manager-port",
        "--object-manager-port",
        "--dashboard-agent-grpc-port",
        "--dashboard-agent-listen-port",
        "--metrics-export-port",
        "--runtime-env-agent-port",
    )
    return [f"{name}={port}" for name, port in zip(names, ports)]


class Cluster:
    """A head node and one worker node, each with one CPU, in their own temp folder."""

    def __init__(self, env: dict):
        # short: Ray's unix socket paths live under it and must stay below 108 characters
        self.temp = Path(tempfile.mkdtemp(prefix="adarl-ray-", dir="/tmp"))
        self.env = env
        gcs, dashboard, *ports = _free_ports(14)
        self.address = f"127.0.0.1:{gcs}"
        self.head_ports, self.worker_ports = ports[:6], ports[6:12]
        self.dashboard_port = dashboard

    def start(self) -> None:
        common = ["--num-cpus=1", "--node-ip-address=127.0.0.1", "--disable-usage-stats"]
        self._start(
            "--head",
            f"--port={self.address.rpartition(':')[2]}",
            f"--temp-dir={self.temp}",
            "--include-dashboard=false",
            f"--dashboard-port={self.dashboard_port}",
            *common,
            *_node_flags(self.head_ports),
        )
        self._start(f"--address={self.address}", *common, *_node_flags(self.worker_ports))

    def _start(self, *flags: str) -> None:
        done = subprocess.run(
            [RAY, "start", *flags], env=self.env, capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 0, done.stdout + done.stderr

    def worker_raylet(self, table: dict) -> int:
        flag = f"--node_manager_port={self.worker_ports[0]}"
        found = [pid for pid, (_, cmdline) in table.items() if flag in cmdline]
        assert len(found) == 1, found
        return found[0]

    def kill_worker_node(self) -> None:
        """SIGKILL the worker node's raylet and everything under it (its Ray workers and the
        training process they started), as when a machine goes down."""
        table = _processes()
        _kill(_with_descendants({self.worker_raylet(table)}, table))

    def stop(self) -> None:
        """Kill this cluster's processes: those that name its temp folder, and everything under
        them (`ray stop` would stop every Ray instance on the machine)."""
        table = _processes()
        mine = {
            pid for pid, (_, cmdline) in table.items() if any(str(self.temp) in c for c in cmdline)
        }
        _kill(_with_descendants(mine, table))
        shutil.rmtree(self.temp, ignore_errors=True)


@pytest.fixture
def cluster(tmp_path, monkeypatch):
    token = tmp_path / "ray-token"  # Ray's token authentication, with a token of the test's own
    token.write_text(secrets.token_hex(32))
    monkeypatch.setenv("RAY_AUTH_MODE", "token")
    monkeypatch.setenv("RAY_AUTH_TOKEN_PATH", str(token))
    monkeypatch.setenv("RAY_USAGE_STATS_ENABLED", "0")
    started = Cluster(dict(os.environ))
    try:
        started.start()
        yield started
    finally:
        started.stop()


def _unit_on_worker_node(out: Path, cluster: Cluster, sweep, units, timeout_s: float = 240):
    """The unit that trains on the worker node, once its run has a complete checkpoint."""
    deadline = time.monotonic() + timeout_s
    raylet = cluster.worker_raylet(_processes())
    while time.monotonic() < deadline:
        assert sweep.poll() is None, sweep.stdout.read()
        table = _processes()
        for uid in units:
            marker = out / ".state" / f"{uid.replace('/', '__')}.started.json"
            if not marker.exists():
                continue
            pid = json.loads(marker.read_text())["pid"]
            if raylet in _ancestors(pid, table) and checkpoints.checkpoint_dirs(out / uid):
                assert not (out / uid / "DONE").exists(), "the unit finished before the kill"
                return uid
        time.sleep(0.1)
    raise AssertionError("no unit reached a checkpoint on the worker node in time")


def _csv(run_dir: Path, name: str) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "steps_per_s"} for r in read_csv(run_dir / name)]


def test_a_sweep_survives_losing_a_cluster_node(tmp_path, cluster, write_spec, assert_complete):
    spec = write_spec(
        tmp_path / "s.yaml",
        algos=["sac", "adarl"],
        budget=BUDGET,
        overrides={"checkpoint_every": 500, "log_every": 250},
    )
    units = ["hopper/sac/seeds-0-1", "hopper/adarl/seeds-0-1"]
    out = tmp_path / "cluster"
    sweep = subprocess.Popen(
        [sys.executable, "-m", "adarl.cli.main", "sweep", str(spec), "--out", str(out)]
        + ["--backend", "ray", "--address", cluster.address, "--progress-every", "5"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        lost = _unit_on_worker_node(out, cluster, sweep, units)
        cluster.kill_worker_node()
        text, _ = sweep.communicate(timeout=400)
    finally:
        if sweep.poll() is None:
            sweep.send_signal(signal.SIGINT)
            sweep.wait(timeout=30)
    assert sweep.returncode == 0, text
    assert "on Ray cluster at 127.0.0.1:" in text and "(2 CPUs)" in text
    assert f"{lost}" in text and "running  attempt 2, resuming from step" in text, text
    record = json.loads((out / "manifest.json").read_text())["units"][lost]
    assert (record["status"], record["attempts"]) == ("done", 2)
    for uid in units:
        assert_complete(out / uid, BUDGET)

    # the same unit, trained locally without interruption
    reference = tmp_path / "reference"
    from adarl.sweeps import spec as spec_mod

    unit = next(u for u in spec_mod.load(str(spec)).units if u.id == lost)
    done = subprocess.run(
        [sys.executable, "-m", "adarl.cli.main", "train", *unit.train_args]
        + ["--out", str(reference), "--no-progress"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    for name in ("episodes.csv", "train.csv", "eval.csv"):
        assert _csv(out / lost, name) == _csv(reference, name), name
    a, _ = checkpoints.load_checkpoint(checkpoints.latest_checkpoint(out / lost))
    b, _ = checkpoints.load_checkpoint(checkpoints.latest_checkpoint(reference))
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
