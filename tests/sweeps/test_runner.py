"""The sweep loop against a fake backend (no training): bounded retries, what is not retried,
failures reported in the manifest and the summary, exit status 1."""

import concurrent.futures as cf
import json

import pytest

from adarl.sweeps import estimate, runner, spec
from adarl.sweeps.estimate import Measurement
from adarl.train import launch


class FakeBackend:
    """An executor that finishes every job at once with the next outcome: an exit status or an
    exception."""

    where = "a fake backend"
    slots = 1  # units handed over at once

    def __init__(self, *outcomes):
        self.outcomes = list(outcomes)
        self.jobs = []

    def submit(self, fn, job):
        self.jobs.append(job)
        future = cf.Future()
        outcome = self.outcomes.pop(0)
        if isinstance(outcome, Exception):
            future.set_exception(outcome)
        else:
            future.set_result({"returncode": outcome, "host": "h"})
        return future

    def close(self, cancel=False):
        pass


def _sweep(tmp_path, backend, max_retries=2):
    doc = {"tasks": ["hopper"], "algos": ["sac"], "seeds": [0], "budget": 100}
    sweep = spec.parse(doc, source="t.yaml", default_name="t")
    options = runner.Options(max_retries=max_retries, progress_every=1e9)
    code = runner.run_sweep(sweep, tmp_path / "out", backend, options)
    record = json.loads((tmp_path / "out" / "manifest.json").read_text())["units"]
    return code, record["hopper/sac/seeds-0"]


def test_a_crashing_unit_is_retried_a_bounded_number_of_times(tmp_path, capsys):
    backend = FakeBackend(-9, RuntimeError("worker lost"), 1)
    code, record = _sweep(tmp_path, backend, max_retries=2)
    assert code == 1 and len(backend.jobs) == 3
    assert (record["status"], record["attempts"], record["returncode"]) == ("failed", 3, 1)
    assert [j["worker_args"][j["worker_args"].index("--attempt") + 1] for j in backend.jobs] == [
        "1", "2", "3"]  # fmt: skip
    text = capsys.readouterr().out
    assert "killed by SIGKILL; retrying (2 attempts left)" in text
    assert "RuntimeError: worker lost; retrying (1 attempt left)" in text
    assert "0 done (0 before this run), 1 failed" in text
    assert "failed: hopper/sac/seeds-0 after 3 attempts: exit 1" in text

    code, record = _sweep(tmp_path, FakeBackend(0), max_retries=0)  # re-run: tried again
    assert code == 1 and record["attempts"] == 4  # attempts count over every invocation
    assert record["error"].startswith("exited without finishing (no DONE)")


def test_bad_input_is_not_retried(tmp_path, capsys):
    backend = FakeBackend(2)
    code, record = _sweep(tmp_path, backend)
    assert code == 1 and len(backend.jobs) == 1 and record["status"] == "failed"
    assert "(bad input, not retried)" in capsys.readouterr().out


class WritingBackend(FakeBackend):
    """Finishes every job with exit 0 as a real unit would leave its folder: DONE, and for the
    units in `fork_points` (id -> step) the checkpoint they keep before that truncation."""

    def __init__(self, out, fork_points=(), codes=None):
        super().__init__()
        self.out, self.fork_points, self.codes = out, dict(fork_points), codes or {}

    def submit(self, fn, job):
        args = job["worker_args"]
        run_dir = args[args.index("--run-dir") + 1]
        uid = str(run_dir).removeprefix(str(self.out.resolve()) + "/")
        self.jobs.append(job)
        code = self.codes.get(uid, 0)
        if code == 0:
            from pathlib import Path

            run = Path(run_dir)
            run.mkdir(parents=True, exist_ok=True)
            if uid in self.fork_points:
                point = run / "checkpoints/pre_truncation" / f"step_{self.fork_points[uid]:012d}"
                point.mkdir(parents=True)
                (point / "meta.json").write_text("{}")
                (point / "arrays.npz").write_bytes(b"")
            (run / "DONE").write_text("done\n")
        future = cf.Future()
        future.set_result({"returncode": code, "host": "h"})
        return future


def _uids(backend):
    return [j["worker_args"][j["worker_args"].index("--run-dir") + 1].split("/out/")[1]
            for j in backend.jobs]  # fmt: skip


def test_the_longest_units_start_first(tmp_path):
    doc = {"tasks": ["hopper", "walker2d"], "algos": ["sac"], "seeds": [0], "preset": "smoke",
           "budget": {"hopper": 1000, "walker2d": 5000}}  # fmt: skip
    sweep = spec.parse(doc, source="t.yaml", default_name="t")
    backend = WritingBackend(tmp_path / "out")
    runner.run_sweep(sweep, tmp_path / "out", backend, runner.Options(progress_every=1e9))
    assert _uids(backend) == ["walker2d/sac/seeds-0", "hopper/sac/seeds-0"]  # file order reversed


@pytest.mark.parametrize("measured", [True, False], ids=["with-rates", "without-rates"])
def test_resumed_units_start_first_the_nearest_to_done_first(tmp_path, monkeypatch, measured):
    """walker2d is the longest unit, but hopper (500 of 1,000 steps left) and ant (1,000 of 2,000)
    hold checkpoints: they resume first, hopper first (fewer steps, and a faster task)."""
    if not measured:
        monkeypatch.setattr(estimate, "read_measurements", lambda: [])
    doc = {"tasks": ["walker2d", "ant", "hopper"], "algos": ["sac"], "seeds": [0],
           "preset": "smoke", "budget": {"hopper": 1000, "walker2d": 5000, "ant": 2000}}  # fmt: skip
    sweep = spec.parse(doc, source="t.yaml", default_name="t")
    for uid, step in [("hopper/sac/seeds-0", 500), ("ant/sac/seeds-0", 1000)]:
        point = tmp_path / "out" / uid / "checkpoints" / f"step_{step:012d}"
        point.mkdir(parents=True)
        (point / "meta.json").write_text("{}")
        (point / "arrays.npz").write_bytes(b"")
    plan = runner.plan_text(sweep, tmp_path / "out", "here")
    assert "resumed first, the nearest to done first: hopper/sac/seeds-0, ant/sac/seeds-0\n" in plan
    backend = WritingBackend(tmp_path / "out")
    runner.run_sweep(sweep, tmp_path / "out", backend, runner.Options(progress_every=1e9))
    assert _uids(backend) == ["hopper/sac/seeds-0", "ant/sac/seeds-0", "walker2d/sac/seeds-0"]


FORK_SWEEP = {
    "tasks": ["hopper"],
    "algos": [
        {"algo": "adarl", "name": "a", "rank_rule": "cumulative"},
        {"algo": "adarl-control", "name": "c", "rank_rule": "cumulative",
         "fork": {"from": "a", "at": "first-truncation"}},
    ],
    "seeds": "0-1",
    "preset": "smoke",
    "budget": 2000,
}  # fmt: skip


def test_a_unit_that_others_fork_from_starts_before_a_longer_independent_unit(
    tmp_path, monkeypatch
):
    """One slot; 2 seeds × 2,000 steps each, fork at 950, 10 s start-up per unit. a at 100
    seed-steps/s: 50 s, its fork point after 10 + 40 × 950/2000 = 29 s; c from there: 10 +
    2 × 1,050/100 = 31 s, so a's critical path is 29 + 31 = 60 s. s at 4000/45 seed-steps/s:
    55 s. Longest first would start s (55 > 50); critical path first starts a (60 > 55)."""
    monkeypatch.setattr(runner, "POLL_S", 0.01)
    rates = {"adarl": (4000, 40.0), "adarl-control": (4000, 40.0), "sac": (4000, 45.0)}
    measured = [Measurement(a, "hopper", a, 1, n, s, "t") for a, (n, s) in rates.items()]
    monkeypatch.setattr(estimate, "read_measurements", lambda: measured)
    doc = {**FORK_SWEEP, "algos": [*FORK_SWEEP["algos"], {"algo": "sac", "name": "s"}]}
    sweep = spec.parse(doc, source="t.yaml", default_name="t")
    paths = estimate.unit_critical_paths(sweep, tmp_path / "out")
    assert paths == pytest.approx(
        {"hopper/a/seeds-0-1": 60.0, "hopper/c/seeds-0-1": 31.0, "hopper/s/seeds-0-1": 55.0}
    )
    backend = WritingBackend(tmp_path / "out", {"hopper/a/seeds-0-1": 950})
    options = runner.Options(max_retries=0, progress_every=1e9)
    assert runner.run_sweep(sweep, tmp_path / "out", backend, options) == 0
    assert _uids(backend) == ["hopper/a/seeds-0-1", "hopper/s/seeds-0-1", "hopper/c/seeds-0-1"]


def _fork_sweep(tmp_path, backend):
    sweep = spec.parse(FORK_SWEEP, source="t.yaml", default_name="t")
    options = runner.Options(max_retries=0, progress_every=1e9)
    code = runner.run_sweep(sweep, tmp_path / "out", backend, options)
    units = json.loads((tmp_path / "out" / "manifest.json").read_text())["units"]
    return code, units


def test_a_fork_unit_starts_once_its_parent_has_written_the_fork_point(tmp_path, monkeypatch):
    monkeypatch.setattr(runner, "POLL_S", 0.01)
    backend = WritingBackend(tmp_path / "out", {"hopper/a/seeds-0-1": 950})
    code, units = _fork_sweep(tmp_path, backend)
    assert code == 0 and _uids(backend) == ["hopper/a/seeds-0-1", "hopper/c/seeds-0-1"]
    args = backend.jobs[1]["worker_args"]
    (record,) = [json.loads(a.removeprefix("--unit=")) for a in args if a.startswith("--unit=")]
    parent = str((tmp_path / "out").resolve() / "hopper/a/seeds-0-1")
    assert record == {"fork": {"from": parent, "at": 950, "changes": {"apply_cuts": "false"}}}
    # the command its run records
    argv = ("--fork", parent, "--at", "950", "--apply-cuts", "false")
    assert launch.from_record(record).argv() == argv
    assert units["hopper/c/seeds-0-1"]["status"] == "done"


def test_a_fork_fails_with_its_parent_or_without_its_fork_point(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(runner, "POLL_S", 0.01)
    backend = WritingBackend(tmp_path / "out")  # the parent ends without the checkpoint
    code, units = _fork_sweep(tmp_path, backend)
    assert code == 1 and _uids(backend) == ["hopper/a/seeds-0-1"]
    assert units["hopper/c/seeds-0-1"]["error"] == (
        "its parent hopper/a/seeds-0-1 has no checkpoint at step 950"
    )
    backend = WritingBackend(tmp_path / "again", codes={"hopper/a/seeds-0-1": 1})
    sweep = spec.parse(FORK_SWEEP, source="t.yaml", default_name="t")
    options = runner.Options(max_retries=0, progress_every=1e9)
    assert runner.run_sweep(sweep, tmp_path / "again", backend, options) == 1
    units = json.loads((tmp_path / "again" / "manifest.json").read_text())["units"]
    assert units["hopper/c/seeds-0-1"]["status"] == "failed"
    assert units["hopper/c/seeds-0-1"]["error"] == "its parent hopper/a/seeds-0-1 failed"
    assert (
        "hopper/c/seeds-0-1  failed   its parent hopper/a/seeds-0-1 failed"
        in capsys.readouterr().out
    )
