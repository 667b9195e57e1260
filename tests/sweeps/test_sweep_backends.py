"""The `smoke` preset end to end, on the local pool and on a real local Ray instance; a re-run
skips what is done; the output is what `adarl report` reads."""

import json

import pytest

from adarl.cli.main import main
from adarl.results.runs import find_runs
from adarl.sweeps import job

UNITS = ("hopper/adarl/seeds-0-1", "hopper/sac/seeds-0-1")


def _check_smoke_output(out, assert_complete):
    data = json.loads((out / "manifest.json").read_text())
    assert data["name"] == "smoke" and set(data["units"]) == set(UNITS)
    for uid in UNITS:
        record = data["units"][uid]
        assert (record["status"], record["attempts"], record["returncode"]) == ("done", 1, 0)
        assert_complete(out / uid, 1000)
    runs = find_runs([out])  # what `adarl report SWEEP_DIR` starts from
    assert sorted(r.label for r in runs) == ["adarl", "sac"]


def test_smoke_preset_on_the_local_pool(tmp_path, capsys, assert_complete):
    out = tmp_path / "sweep"
    assert (
        main(["sweep", "smoke", "--out", str(out), "--workers", "2", "--progress-every", "2"]) == 0
    )
    text = capsys.readouterr().out
    lines = [" ".join(line.split()[1:]) for line in text.splitlines()]  # no time, no padding
    for uid in UNITS:
        assert f"{uid} queued (start)" in lines
        assert any(line.startswith(f"{uid} running attempt 1, from scratch") for line in lines)
        assert any(line.startswith(f"{uid} done attempt 1") for line in lines)
    assert "2 units, 2 done (0 before this run), 0 failed" in text
    _check_smoke_output(out, assert_complete)

    assert main(["sweep", "smoke", "--out", str(out)]) == 0  # again: nothing to do
    text = capsys.readouterr().out
    assert text.count("(finished before; skipped)") == 2 and "running" not in text
    assert json.loads((out / "manifest.json").read_text())["units"][UNITS[0]]["attempts"] == 1


def test_smoke_preset_on_a_local_ray_instance(tmp_path, capsys, assert_complete, local_ray_turn):
    ray = pytest.importorskip("ray")
    out = tmp_path / "sweep"
    try:
        assert (
            main(["sweep", "smoke", "--backend", "ray", "--workers", "2", "--out", str(out)]) == 0
        )
    finally:
        ray.shutdown()
    text = capsys.readouterr().out
    assert "local Ray instance (2 CPUs)" in text
    assert "2 units, 2 done (0 before this run), 0 failed" in text
    assert not ray.is_initialized()  # the sweep stopped the instance it started
    _check_smoke_output(out, assert_complete)


@pytest.mark.skipif(job.autogroup_nice("self") is None, reason="no Linux autogroups here")
def test_a_unit_in_its_own_session_can_take_the_sweeps_cpu_share():
    """Units start in a new session, which the kernel schedules as a new group at nice 0; the
    sweep hands its own group's nice to the unit (read back from /proc)."""
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"],
                            start_new_session=True)  # fmt: skip
    try:
        assert job.autogroup_nice(proc.pid) == 0
        job.set_autogroup_nice(proc.pid, 7)
        assert job.autogroup_nice(proc.pid) == 7
    finally:
        proc.kill()
        proc.wait()
