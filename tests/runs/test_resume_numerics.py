"""Issue 55: a resume under other numeric settings (x64, matmul precision, platform, XLA flags
that change results) would silently not continue the run exactly: the settings are recorded in
environment.json and such a resume is refused in one line naming both values, nothing written."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import jax
import pytest
from cli_errors import one_line_exit_2

from adarl.algos import sac_config
from adarl.algos.sac_config import SAC_FAMILY
from adarl.runs import checkpoints, provenance
from adarl.train import trainers


@pytest.fixture(scope="module")
def unfinished_run(tmp_path_factory) -> Path:
    """A one-seed SAC smoke run stopped after its first checkpoint (step 100 of 200)."""
    values = {**SAC_FAMILY["sac"], **sac_config.PRESETS["smoke"], "algo": "sac", "task": "hopper"}
    values.update(seeds=(0,), total_steps=100, checkpoint_every=100, eval_every=100)
    values.update(start_steps=50, update_after=50, log_every=100)
    run_dir = tmp_path_factory.mktemp("numerics") / "run"
    trainers.train(sac_config.SACConfig(**values), run_dir, progress=False)
    (run_dir / "DONE").unlink()
    config = (run_dir / "config.yaml").read_text().replace("total_steps: 100", "total_steps: 200")
    (run_dir / "config.yaml").write_text(config)
    return run_dir


def snapshot(run_dir: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(run_dir)): p.read_bytes()
        for p in sorted(run_dir.rglob("*"))
        if p.is_file() and p.name != ".lock"
    }


def test_the_numeric_settings_are_recorded_as_jax_has_them(unfinished_run, monkeypatch):
    record = json.loads((unfinished_run / "environment.json").read_text())
    assert record["numerics"] == provenance.numerics()
    assert record["numerics"]["jax_enable_x64"] is False
    assert record["numerics"]["platform"] == jax.default_backend()
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=7 --xla_b=1 --xla_a=0")
    assert provenance.numerics()["xla_flags"] == "--xla_a=0 --xla_b=1"  # the device count left out
    previous = jax.config.jax_default_matmul_precision
    jax.config.update("jax_default_matmul_precision", "highest")
    try:
        assert provenance.numerics()["jax_default_matmul_precision"] == "highest"
    finally:
        jax.config.update("jax_default_matmul_precision", previous)


@pytest.mark.parametrize(
    "name, value",
    [
        ("jax_enable_x64", True),
        ("platform", "gpu"),
        ("xla_flags", "--xla_cpu_enable_fast_math=true"),
    ],
)
def test_a_resume_under_other_settings_is_refused_naming_both(
    name, value, unfinished_run, tmp_path, capsys
):
    run_dir = tmp_path / "run"
    shutil.copytree(unfinished_run, run_dir)
    path = run_dir / "environment.json"
    record = json.loads(path.read_text())
    now = record["numerics"][name]
    record["numerics"][name] = value  # as if the run had been made under `value`
    path.write_text(json.dumps(record))
    before = snapshot(run_dir)
    one_line_exit_2(
        ["train", "--resume", str(run_dir)],
        capsys,
        f"{name} {value!r} but this process has {now!r}",
    )
    assert snapshot(run_dir) == before  # nothing written, no checkpoint renamed


def test_the_newest_resume_record_is_the_one_compared(unfinished_run, tmp_path, capsys):
    """A run made before settings were recorded and resumed since: its resume's settings count."""
    run_dir = tmp_path / "run"
    shutil.copytree(unfinished_run, run_dir)
    path = run_dir / "environment.json"
    record = json.loads(path.read_text())
    del record["numerics"]
    provenance.check_resume_numerics(run_dir)  # nothing recorded: nothing to compare
    path.write_text(json.dumps(record))
    provenance.check_resume_numerics(run_dir)
    resumed = dict(record["numerics"] if "numerics" in record else provenance.numerics())
    resumed["jax_enable_x64"] = True
    record["resumes"] = [{"step": 100, "numerics": resumed}]
    path.write_text(json.dumps(record))
    one_line_exit_2(["train", "--resume", str(run_dir)], capsys, "jax_enable_x64 True but")


def test_jax_enable_x64_in_the_environment_is_refused_on_resume(unfinished_run, tmp_path):
    """The auditor's case, end to end: `JAX_ENABLE_X64=1 adarl train --resume RUN`."""
    run_dir = tmp_path / "run"
    shutil.copytree(unfinished_run, run_dir)
    before = snapshot(run_dir)
    done = subprocess.run(
        [sys.executable, "-m", "adarl.cli.main", "train", "--resume", str(run_dir)],
        capture_output=True,
        text=True,
        env={**os.environ, "JAX_ENABLE_X64": "1"},
        timeout=300,
    )
    assert done.returncode == 2, done.stderr[-2000:]
    assert done.stderr.count("\n") == 1, done.stderr
    assert "jax_enable_x64 False but this process has True (JAX_ENABLE_X64)" in done.stderr
    assert snapshot(run_dir) == before
    assert [p.name for p in checkpoints.checkpoint_dirs(run_dir)] == ["step_000000000100"]
