"""The sweep loop against a fake backend (no training): bounded retries, what is not retried,
failures reported in the manifest and the summary, exit status 1."""

import concurrent.futures as cf
import json

from adarl.sweeps import runner, spec


class FakeBackend:
    """Finishes every job at once with the next outcome: an exit status or an exception."""

    where = "a fake backend"

    def __init__(self, *outcomes):
        self.outcomes = list(outcomes)
        self.jobs = []

    def submit(self, job):
        self.jobs.append(job)
        future = cf.Future()
        outcome = self.outcomes.pop(0)
        if isinstance(outcome, Exception):
            future.set_exception(outcome)
        else:
            future.set_result({"returncode": outcome, "host": "h"})
        return future

    def close(self, interrupted=False):
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
