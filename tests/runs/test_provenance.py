"""environment.json: what produced a run, written by both trainers, listed by `adarl report`."""

import json
import subprocess
from importlib import metadata
from pathlib import Path
from types import SimpleNamespace

import pytest

from adarl import __version__
from adarl.algos import rnac_config, sac_config
from adarl.algos.sac_config import SAC_FAMILY
from adarl.errors import UsageError
from adarl.report.scores import environment_section
from adarl.runs import provenance
from adarl.train import rnac_learner, sac_learner, trainers

ROOT = Path(provenance.__file__).resolve().parents[2]


def test_record_has_versions_cpu_and_flags(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=2")
    record = provenance.environment_record()
    assert record["format_version"] == provenance.FORMAT_VERSION
    assert record["adarl"]["version"] == __version__
    for name in ("jax", "jaxlib", "mujoco", "gymnasium", "numpy", "optax"):
        assert record["packages"][name] == metadata.version(name)
    assert record["python"]["version"].count(".") == 2
    assert record["cpu"]["cores"] >= 1 and record["cpu"]["usable_cores"] >= 1
    assert record["xla_flags"] == "--xla_force_host_platform_device_count=2"
    json.dumps(record)  # JSON-ready


def test_git_commit_from_a_checkout():
    if not (ROOT / ".git").exists():
        pytest.skip("adarl is not imported from a git checkout")
    try:
        head = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pytest.skip("git is not available")
    record = provenance.environment_record()
    assert record["adarl"]["git_commit"] == head
    assert record["adarl"]["git_dirty"] in (True, False)


@pytest.mark.parametrize(
    "failure",
    [FileNotFoundError("git"), subprocess.TimeoutExpired("git", 2.0)],
    ids=["no-git", "timeout"],
)
def test_git_failure_is_tolerated(monkeypatch, failure):
    def run(*args, **kwargs):
        raise failure

    monkeypatch.setattr(provenance.subprocess, "run", run)
    adarl = provenance.environment_record()["adarl"]
    assert adarl == {"version": __version__, "git_commit": None, "git_dirty": None}


def test_write_and_read(tmp_path):
    provenance.write_environment(tmp_path)
    record = json.loads((tmp_path / "environment.json").read_text())
    assert provenance.read_environment(tmp_path) == record
    assert provenance.read_environment(tmp_path / "missing") is None
    (tmp_path / "environment.json").write_text("{not json")  # damaged: named, not ignored
    with pytest.raises(UsageError, match="environment.json is unreadable"):
        provenance.read_environment(tmp_path)
    (tmp_path / "environment.json").write_text('{"packages": ["jax"]}')
    with pytest.raises(UsageError, match="field 'packages'"):
        provenance.read_environment(tmp_path)


def _record(**packages):
    return {"packages": {"jax": "0.10.2", "mujoco": "4.0.0", "gymnasium": "1.4.0", **packages}}


def test_mismatches_one_line_per_package():
    records = {
        "a": _record(),
        "b": _record(jax="0.4.30", gymnasium="1.2.0", numpy="1.0"),
        "c": None,  # no environment.json: not compared
    }
    assert provenance.mismatches(records) == [
        "runs were made with different jax versions: 0.10.2 (a); 0.4.30 (b)",
        "runs were made with different gymnasium versions: 1.4.0 (a); 1.2.0 (b)",
    ]
    assert provenance.mismatches({"a": _record(), "b": _record(numpy="9"), "c": None}) == []


def test_report_lists_environments_and_warns(tmp_path, capsys):
    runs = []
    for name, record in [("r1", _record()), ("r2", _record(mujoco="3.2.0")), ("old", None)]:
        path = tmp_path / name
        path.mkdir()
        if record is not None:
            (path / "environment.json").write_text(json.dumps(record))
        runs.append(SimpleNamespace(path=path))
    (tmp_path / "out" / "tables").mkdir(parents=True)
    notes = []
    section = environment_section(runs, tmp_path / "out", notes)
    line = f"runs were made with different mujoco versions: 4.0.0 ({runs[0].path}); 3.2.0 ({runs[1].path})"
    assert notes == [f"Warning: {line}."]
    assert capsys.readouterr().err == f"adarl: warning: {line}\n"
    table = (tmp_path / "out" / "tables" / "environments.csv").read_text().splitlines()
    assert table[0].startswith("run,adarl,python,jax,jaxlib,mujoco,gymnasium")
    assert len(table) == 4 and table[3].startswith(f"{runs[2].path},unknown,unknown")
    assert "3.2.0" in section.text and section.title == "Environments"


class Stop(Exception):
    pass


def _stop(*args, **kwargs):
    raise Stop


def test_sac_trainer_writes_it_at_creation(tmp_path, monkeypatch):
    monkeypatch.setattr(
        sac_learner.SACLearner, "fresh", _stop
    )  # stop right after the run is created
    values = {**SAC_FAMILY["sac"], **sac_config.PRESETS["smoke"], "algo": "sac", "task": "hopper"}
    with pytest.raises(Stop):
        trainers.train(sac_config.SACConfig(**values), tmp_path / "run", progress=False)
    record = provenance.read_environment(tmp_path / "run")
    assert record["packages"]["jax"] == metadata.version("jax")


def test_rnac_trainer_writes_it_at_creation(tmp_path, monkeypatch):
    monkeypatch.setattr(
        rnac_learner.RNACLearner, "fresh", _stop
    )  # stop right after the run is created
    with pytest.raises(Stop):
        trainers.train(
            rnac_config.RNACConfig(**rnac_config.PRESETS["smoke"]), tmp_path / "run", progress=False
        )
    record = provenance.read_environment(tmp_path / "run")
    assert record["packages"]["mujoco"] == metadata.version("mujoco")


def _code(commit, dirty=False, **packages):
    return {
        "adarl": {"version": "0.1.0", "git_commit": commit, "git_dirty": dirty},
        **_record(**packages),
    }


def test_a_resume_is_appended_with_its_step_and_code(tmp_path, monkeypatch, capsys):
    provenance.record_resume(tmp_path, 500)  # a run made before environment.json: left alone
    assert not (tmp_path / "environment.json").exists()
    (tmp_path / "environment.json").write_text(json.dumps({**_code("a" * 40), "cpu": {}}))
    monkeypatch.setattr(
        provenance, "_git_state", lambda: {"git_commit": "b" * 40, "git_dirty": False}
    )
    provenance.record_resume(tmp_path, 1_050_000)
    provenance.record_resume(tmp_path, 1_600_000)
    record = provenance.read_environment(tmp_path)
    assert record["adarl"]["git_commit"] == "a" * 40 and record["cpu"] == {}  # creation kept
    assert [r["step"] for r in record["resumes"]] == [1_050_000, 1_600_000]
    assert record["resumes"][0]["adarl"]["git_commit"] == "b" * 40
    assert record["resumes"][0]["packages"]["jax"] == metadata.version("jax")
    damaged = json.dumps({"resumes": [{"step": "5"}]})
    (tmp_path / "environment.json").write_text(damaged)
    with pytest.raises(UsageError, match="field 'resumes'"):
        provenance.read_environment(tmp_path)
    provenance.record_resume(tmp_path, 1_700_000)  # a resume goes on, the damage is left as is
    assert (tmp_path / "environment.json").read_text() == damaged
    assert "field 'resumes'" in capsys.readouterr().err


def test_code_changes_name_what_changed_and_from_which_step():
    record = {
        **_code("a" * 40),
        "resumes": [
            {"step": 50_000, **_code("a" * 40)},  # same code: no change
            {"step": 100_000, **_code(None)},  # not a git checkout: unknown, not a change
            {"step": 150_000, **_code("b" * 40, mujoco="4.1.0", numpy="3")},
            {"step": 200_000, **_code("b" * 40, dirty=True, mujoco="4.1.0")},
        ],
    }
    assert provenance.code_changes(record) == [
        f"adarl 0.1.0 ({'a' * 12}) → 0.1.0 ({'b' * 12}), mujoco 4.0.0 → 4.1.0 from step 150,000",
        f"adarl 0.1.0 ({'b' * 12}) → 0.1.0 ({'b' * 12}+dirty) from step 200,000",
    ]
    assert provenance.code_changes(_code("a" * 40)) == [] and provenance.code_changes(None) == []


class StopTraining(Exception):
    pass


def test_the_trainer_records_each_resume_and_the_report_warns(tmp_path, monkeypatch, capsys):
    """A run created by one commit and resumed by another says so in the report."""
    from adarl.train import loop

    def stop(self, *args):
        raise StopTraining

    monkeypatch.setattr(loop.Loop, "run", stop)  # create (or resume), then stop at once
    values = {**SAC_FAMILY["sac"], **sac_config.PRESETS["smoke"], "algo": "sac", "task": "hopper"}
    config, run = sac_config.SACConfig(**values), tmp_path / "run"
    monkeypatch.setattr(
        provenance, "_git_state", lambda: {"git_commit": "a" * 40, "git_dirty": False}
    )
    with pytest.raises(StopTraining):
        trainers.train(config, run, progress=False)
    assert "resumes" not in provenance.read_environment(run)
    monkeypatch.setattr(
        provenance, "_git_state", lambda: {"git_commit": "c" * 40, "git_dirty": False}
    )
    with pytest.raises(StopTraining):
        trainers.train(config, run, resume=True, progress=False)
    record = provenance.read_environment(run)
    assert [(r["step"], r["adarl"]["git_commit"]) for r in record["resumes"]] == [(0, "c" * 40)]

    (tmp_path / "out" / "tables").mkdir(parents=True)
    notes = []
    environment_section([SimpleNamespace(path=run)], tmp_path / "out", notes)
    line = (
        f"run {run} was resumed with other code: "
        f"adarl {__version__} ({'a' * 12}) → {__version__} ({'c' * 12}) from step 0"
    )
    assert notes == [f"Warning: {line}."]
    assert capsys.readouterr().err.endswith(f"adarl: warning: {line}\n")
