"""Sizes with no ceiling (issue 27, class 2): networks, seeds, evaluation grids, sweep seeds and
bootstrap resamples are counted from the input before anything is built, and what cannot fit is
one line on stderr naming the value and the estimate, exit code 2, nothing written."""

from __future__ import annotations

import os
import socket
import subprocess

import pytest
from synthetic_runs import write_run

from adarl.algos import registry
from adarl.cli.main import main

ONE_PER_TRAINER = [
    next(a for a in registry.ALGOS if registry.get(a).config_class is cls)
    for cls in registry.config_classes()
]
SMOKE = ["--preset", "smoke", "--no-progress"]
GIB = 2**30


def error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err


@pytest.mark.parametrize("algo", ONE_PER_TRAINER)
def test_a_network_that_cannot_fit_is_refused_before_anything_is_written(algo, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", *SMOKE, "--algo", algo, "--hidden", "64646464,64646464", "--out", str(out)]
    assert main(argv) == 2
    err = error_line(capsys)
    # one 64646464² float32 matrix alone is 15,569 TiB
    assert "networks" in err and "--hidden (64646464,64646464)" in err, err
    assert "GiB of memory; lower" in err
    assert not out.exists()  # no .lock, config.yaml or environment.json


@pytest.mark.parametrize("algo", ONE_PER_TRAINER)
def test_seeds_are_estimated_before_their_environments_are_built(
    algo, tmp_path, capsys, monkeypatch
):
    from adarl import envs
    from adarl.train import guards

    made = []
    make = envs.make
    monkeypatch.setattr(envs, "make", lambda *a, **k: made.append(1) or make(*a, **k))
    monkeypatch.setattr(guards, "machine_memory", lambda: 2 * GIB)
    out = tmp_path / "run"
    assert main(["train", *SMOKE, "--algo", algo, "--seeds", "0-2047", "--out", str(out)]) == 2
    err = error_line(capsys)
    # 2048 environments at 2 MiB each: 4.0 GiB, more than the 2 GiB the machine is said to have
    assert "2048 seeds" in err and "environments 4.0 GiB" in err, err
    assert "this machine has 2.0 GiB of memory" in err and "train fewer seeds per run" in err
    assert len(made) == 1  # the first seed's, for the sizes; not one per seed
    assert not out.exists()


def test_a_list_flag_is_counted_before_it_is_expanded(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", *SMOKE, "--seeds", "0-100000000", "--out", str(out)]) == 2
    assert "--seeds '0-100000000' is 100,000,001 numbers; allowed: at most 1,000,000" in (
        error_line(capsys)
    )
    assert not out.exists()


def test_a_sweep_of_too_many_seeds_is_refused_before_its_units_exist(tmp_path, capsys):
    spec = tmp_path / "s.yaml"
    spec.write_text("tasks: [hopper]\nalgos: [sac]\nseeds: 0-100000000\nbudget: 1000\n")
    out = tmp_path / "out"
    assert main(["sweep", str(spec), "--dry-run", "--out", str(out)]) == 2
    err = error_line(capsys)
    assert "seeds '0-100000000' are 100,000,001 seeds; allowed: at most 10,000" in err
    assert not out.exists()
    # within the seed ceiling, units are counted too: 2 algorithms x 6,000 one-seed units
    spec.write_text(
        "tasks: [hopper]\nalgos: [sac, adarl]\nseeds: 0-5999\nseeds_per_unit: 1\nbudget: 1000\n"
    )
    assert main(["sweep", str(spec), "--dry-run", "--out", str(out)]) == 2
    assert "12,000 units" in error_line(capsys)
    assert not out.exists()


@pytest.mark.parametrize(
    "argv, needle",
    [
        (  # one axis: refused before its values are computed
            ["--sweep", "torso_length=0.2:0.6:100000000"],
            "100,000,000 points x 10 episodes are 1,000,000,000 episodes",
        ),
        (  # the grid: 1000 x 1000 points x 2 seeds x 10 episodes
            ["--sweep", "torso_length=0.2:0.6:1000", "--sweep", "foot_length=0.2:0.6:1000"],
            "1,000,000 points x 2 seeds x 10 episodes are 20,000,000 episodes",
        ),
        (  # a suite's grid, --points 1000 on 3 parameters: 10⁹ points x 2 seeds x 30 episodes
            ["--suite", "m2td3-3d", "--points", "1000"],
            "1,000,000,000 points x 2 seeds x 30 episodes are 60,000,000,000 episodes",
        ),
    ],
)
def test_an_evaluation_grid_is_counted_before_it_is_built(argv, needle, tmp_path, capsys):
    run = write_run(tmp_path, "r", seeds=(0, 1))
    before = sorted(p.name for p in run.iterdir())
    assert main(["evaluate", str(run), *argv]) == 2
    err = error_line(capsys)
    assert needle in err and "allowed: at most 10,000,000 per command" in err, err
    assert sorted(p.name for p in run.iterdir()) == before  # no evaluations/ folder


def test_evaluation_rows_beyond_the_memory_are_refused(tmp_path, capsys, monkeypatch):
    from adarl.train import guards

    monkeypatch.setattr(guards, "machine_memory", lambda: GIB)
    run = write_run(tmp_path, "r", seeds=(0, 1))
    # 1000 points x 2 seeds x 200 episodes = 400,000 episodes of 4 KiB: 1.5 GiB
    argv = ["evaluate", str(run), "--sweep", "torso_length=0.2:0.6:1000", "--episodes", "200"]
    assert main(argv) == 2
    err = error_line(capsys)
    assert "(400,000 episodes) need 1.5 GiB but this machine has 1.0 GiB" in err, err
    assert not (run / "evaluations").exists()


def test_bootstrap_reps_that_cannot_fit_are_refused_before_anything_is_written(tmp_path, capsys):
    write_run(tmp_path / "runs", "r", seeds=(0, 1))
    out = tmp_path / "report"
    argv = ["report", str(tmp_path / "runs"), "--out", str(out), "--bootstrap-reps", str(10**12)]
    assert main(argv) == 2
    err = error_line(capsys)
    # 10¹² resamples x 101 profile points x 16 bytes = 1.616e15 bytes
    assert (
        "--bootstrap-reps 1,000,000,000,000 (x 101 profile points) need 1,505,017.3 GiB" in err
    ), err
    assert "lower --bootstrap-reps" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]  # no report, no temp folder


def test_a_report_removes_the_temporary_folders_a_killed_report_left(tmp_path, capsys):
    write_run(tmp_path / "runs", "r", seeds=(0, 1))
    gone = subprocess.Popen(["true"])
    gone.wait()  # a process that no longer runs, as a killed report's
    host = socket.gethostname()
    orphan = tmp_path / f".report.tmp-{gone.pid}-{host}-0123456789ab"
    live = tmp_path / f".report.tmp-{os.getpid()}-{host}-0123456789ab"
    other_host = tmp_path / f".report.tmp-{gone.pid}-{host}x-0123456789ab"
    for folder in (orphan, live, other_host):
        (folder / "tables").mkdir(parents=True)
    argv = ["report", str(tmp_path / "runs"), "--out", str(tmp_path / "report")]
    assert main([*argv, "--bootstrap-reps", "100"]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == sorted(["runs", "report", live.name, other_host.name])
