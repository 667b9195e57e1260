"""Issue 55 §3: inputs that gave tracebacks or wrote where they should not, each one line and
exit 2 with nothing written."""

from __future__ import annotations

import os

import pytest
from cli_errors import one_line_exit_2
from synthetic_runs import write_run


@pytest.mark.parametrize(
    "value", ["²,4", "4,²", "99999999999999999999,4", "4,10001", "0,4", "1,4,5", "a,4", "", " ,4"]
)
def test_a_bad_device_solver_is_one_line(value, tmp_path, capsys):
    out = tmp_path / "run"
    one_line_exit_2(
        ["train", "--backend", "device", "--preset", "smoke", "--device-solver", value]
        + ["--out", str(out)],
        capsys,
        f"device-solver must be 'xml' or 'ITERATIONS,LS_ITERATIONS' (integers from 1 to 10,000, "
        f"e.g. 100,4), got {value!r}",
    )
    assert not out.exists()


def test_device_solvers_in_range_are_accepted():
    from adarl.algos.sac_config import check_device_solver

    for value in ("xml", "1,4", "100,4", " 10000 , 1"):
        check_device_solver(value)


@pytest.mark.parametrize("command", ["report", "train", "sweep", "export", "evaluate", "theory"])
def test_an_output_name_that_is_not_utf8_is_one_line(command, tmp_path, capsys):
    run = write_run(tmp_path, "r", algo="sac", seeds=(0,))
    bad = os.fsdecode(os.fsencode(str(tmp_path)) + b"/out\xff")
    argv = {
        "report": ["report", str(run), "--out", bad],
        "train": ["train", "--preset", "smoke", "--out", bad],
        "sweep": ["sweep", "smoke", "--out", bad, "--dry-run"],
        "export": ["export", str(run), "--out", bad + ".npz"],
        "evaluate": ["evaluate", str(run), "--out", bad + ".csv"],
        "theory": ["theory", "--out", bad],
    }[command]
    one_line_exit_2(argv, capsys, "is not a UTF-8 name (byte 0xff at offset", "out\\xff")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r"]


@pytest.mark.parametrize("inside", [False, True])
def test_a_sweep_into_a_run_folder_is_refused(inside, tmp_path, capsys):
    run = write_run(tmp_path, "r", algo="sac", seeds=(0,))
    before = sorted(p.relative_to(run) for p in run.rglob("*"))
    out = run / "sweep" if inside else run
    for dry in ([], ["--dry-run"]):
        one_line_exit_2(
            ["sweep", "smoke", "--out", str(out), *dry],
            capsys,
            "the folder of a finished run (it holds config.yaml)",
        )
    assert sorted(p.relative_to(run) for p in run.rglob("*")) == before


def test_a_sweep_under_a_project_with_its_own_config_yaml_is_not_refused(tmp_path, capsys):
    from adarl.cli.main import main

    (tmp_path / "config.yaml").write_text("project: mine\n")  # not a run: no DONE, no checkpoints
    assert main(["sweep", "smoke", "--out", str(tmp_path / "sweeps" / "s"), "--dry-run"]) == 0
