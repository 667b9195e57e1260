"""The sweep worker: what a unit hands over resolves to the config the sweep checked, and a unit
trains exactly what `adarl train` with the same settings trains."""

import csv
import json

import numpy as np
import pytest

from adarl.algos import registry
from adarl.cli.main import main
from adarl.sweeps import spec, worker
from adarl.train import launch

TIMING_COLUMNS = {"steps_per_s", "wall_s", "time", "seconds"}


@pytest.mark.parametrize("algo", registry.ALGOS)
def test_the_handed_over_config_is_the_units_config(algo, tmp_path):
    rank = {"rank": 16} if algo == "sac-fixed-rank" else {}
    doc = {"tasks": ["walker2d"], "algos": [{"algo": algo, **rank}], "seeds": "0-2"}
    unit = spec.parse({**doc, "budget": "1.5e5", "preset": "smoke"}).units[0]
    record = json.loads(
        json.dumps(launch.record(unit.start_in(tmp_path)))
    )  # as the worker reads it
    start = launch.from_record(record)
    assert (start.algo, start.config()) == (unit.algo, unit.config)


def _rows(path):
    with path.open(newline="") as f:
        return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in csv.DictReader(f)]


def _files(run_dir):
    """Every file of a run but TensorBoard's (named by the time it was made)."""
    paths = (p.relative_to(run_dir) for p in run_dir.rglob("*") if p.is_file())
    return sorted(p for p in paths if p.parts[0] != "tb")


def test_a_sweep_unit_and_adarl_train_give_the_same_bits(tmp_path, write_spec):
    unit = spec.load(str(write_spec(tmp_path / "s.yaml", algos=["adarl"]))).units[0]
    state = ["--lock", str(tmp_path / "l"), "--marker", str(tmp_path / "m"), "--attempt", "1"]
    record = f"--unit={json.dumps(launch.record(unit.start_in(tmp_path)))}"
    by_sweep, by_train = tmp_path / "sweep", tmp_path / "train"
    assert worker.main(["--run-dir", str(by_sweep), *state, record]) == 0
    argv = ["train", *unit.train_args, "--out", str(by_train), "--no-progress", "--no-report"]
    assert main(argv) == 0
    files = _files(by_train)
    assert files == _files(by_sweep)
    compared = 0
    for name in files:
        a, b = by_train / name, by_sweep / name
        if name.suffix == ".csv":
            assert _rows(a) == _rows(b), name
        elif name.suffix == ".npz":
            with np.load(a) as x, np.load(b) as y:
                assert sorted(x.files) == sorted(y.files), name
                for key in x.files:
                    assert x[key].dtype == y[key].dtype and np.array_equal(x[key], y[key]), key
        else:
            continue
        compared += 1
    assert compared > 5  # CSVs, checkpoints and policies
