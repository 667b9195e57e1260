"""The sweep manifest: one written before units carried their configs (tests/data) is read, the
same sweep is accepted as compatible, and its done units stay done."""

import shutil
from pathlib import Path

import pytest

from adarl.errors import UsageError
from adarl.sweeps import manifest, spec

OLD = Path(__file__).parents[1] / "data" / "sweep-manifest-1"


def test_a_manifest_written_before_configs_resumes_the_same_sweep(tmp_path):
    shutil.copy(OLD / "manifest.json", tmp_path / "manifest.json")
    sweep = spec.load(str(OLD / "spec.yaml"))
    data = manifest.read(tmp_path)
    manifest.check_compatible(data, sweep, tmp_path)
    for unit in sweep.units:  # the flags it recorded are the units' `adarl train` flags
        assert data["units"][unit.id]["train_args"] == list(unit.train_args)
    opened = manifest.Manifest.open(tmp_path, sweep, "adarl sweep spec.yaml")
    assert {uid: opened.unit(uid)["status"] for uid in data["units"]} == dict.fromkeys(
        data["units"], "done"
    )


def test_a_changed_unit_is_refused(tmp_path):
    changed = (OLD / "spec.yaml").read_text().replace("log_every: 250", "log_every: 500")
    (tmp_path / "spec.yaml").write_text(changed)
    shutil.copy(OLD / "manifest.json", tmp_path / "manifest.json")
    sweep = spec.load(str(tmp_path / "spec.yaml"))
    with pytest.raises(UsageError, match="holds a different sweep: unit hopper/a/seeds-0-1"):
        manifest.check_compatible(manifest.read(tmp_path), sweep, tmp_path)
