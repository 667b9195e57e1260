"""Bad values and bad paths are caught before anything is written (docs/reliability.md): one line
on stderr, exit code 2, no run folder left behind."""

import os

import pytest

from adarl.algos import registry
from adarl.cli.main import main

# one algorithm per config class, so per training loop
ONE_PER_TRAINER = [
    next(a for a in registry.ALGOS if registry.get(a).config_class is cls)
    for cls in registry.config_classes()
]

SMOKE = ["--preset", "smoke", "--no-progress"]


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--lr-actor", "inf"], "lr-actor must be a finite number, got inf"),
        (["--lr-critic", "nan"], "lr-critic must be a finite number, got nan"),
        (["--total-steps", str(2**63)], "total-steps must fit in a 64-bit integer"),
        (["--on-divergence", "maybe"], "unknown on-divergence 'maybe'; allowed: stop, continue"),
        (["--buffer-size", str(10**15)], "GiB of memory; lower --buffer-size"),
        # checked up front, not at the first evaluation (and not after training started)
        (["--eval-dynamics", "fixed:bogus=1"], "unknown hopper parameter 'bogus'"),
        (["--eval-dynamics", "nominal,fixed:mass_scale=50"], "implausible value 50"),
        (["--dynamics", "fixed:torso_length=1e9"], "implausible value 1e+09 for torso_length"),
        (["--algo", "rnac", "--lr", "inf"], "lr must be a finite number, got inf"),
        (["--algo", "rnac", "--dynamics", "fixed:mass_scale=0.001"], "implausible value 0.001"),
    ],
)
def test_bad_values_are_one_line_exit_2_and_write_nothing(argv, needle, tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["train", *SMOKE, *argv, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err, err
    assert err.count("\n") == 1
    assert not out.exists()


@pytest.mark.parametrize("algo", ONE_PER_TRAINER)
def test_out_that_is_a_file_or_not_writable_is_one_line_exit_2(algo, tmp_path, capsys, monkeypatch):
    afile = tmp_path / "afile"
    afile.write_text("mine\n")
    argv = ["train", *SMOKE, "--algo", algo, "--out"]
    assert main([*argv, str(afile)]) == 2
    assert "is a file" in capsys.readouterr().err
    assert main([*argv, str(afile / "run")]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err
    assert afile.read_text() == "mine\n"
    # /proc: `os.access` says root may write there, but no one can create a file in it
    assert main([*argv, "/proc/adarl-run"]) == 2
    err = capsys.readouterr().err
    assert "/proc is not writable" in err and err.count("\n") == 1


@pytest.mark.parametrize(
    "command", ["train", "sweep", "evaluate", "export", "play", "report", "theory"]
)
def test_an_output_root_cannot_write_is_one_line_exit_2(command, tmp_path, capsys, monkeypatch):
    from synthetic_runs import write_run

    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    run = write_run(tmp_path / "runs", "r", seeds=(0,))
    out = "/proc/adarl-out/x"  # a missing folder under one that cannot be written
    argv = {
        "train": ["train", *SMOKE, "--out", out],
        "sweep": ["sweep", "smoke", "--dry-run", "--out", out],  # a dry run too
        "evaluate": ["evaluate", str(run), "--episodes", "1", "--out", f"{out}.csv"],
        "export": ["export", str(run), "--out", f"{out}.npz"],
        "play": ["play", str(run), "--video", f"{out}.gif"],
        "report": ["report", str(tmp_path / "runs"), "--out", out],
        "theory": ["theory", "--out", out],
    }[command]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "cannot be written: /proc is not writable" in err and err.count("\n") == 1, err


def test_a_missing_output_folder_is_created_and_the_probe_leaves_nothing(tmp_path):
    from synthetic_runs import write_run

    run = write_run(tmp_path / "runs", "r", seeds=(0,))
    assert main(["export", str(run), "--out", str(tmp_path / "new" / "dir" / "p.npz")]) == 0
    assert (tmp_path / "new" / "dir" / "p.npz").is_file()
    assert not list(tmp_path.rglob(".adarl-probe-*"))  # the probe leaves nothing behind


def test_sweep_dry_run_checks_out(tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("x")
    assert main(["sweep", "smoke", "--dry-run", "--out", str(afile)]) == 2
    err = capsys.readouterr().err
    assert "is a file" in err and err.count("\n") == 1
    assert main(["sweep", "smoke", "--dry-run", "--out", str(tmp_path / "sweep")]) == 0
    assert not (tmp_path / "sweep").exists()


@pytest.mark.parametrize("command", ["evaluate", "export", "play"])
def test_an_output_file_under_a_file_is_one_line_exit_2(command, tmp_path, capsys, monkeypatch):
    from synthetic_runs import write_run

    # `adarl play` sets these for MuJoCo; monkeypatch restores them afterwards
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    run = write_run(tmp_path, "r", seeds=(0,))
    afile = tmp_path / "afile"
    afile.write_text("x")
    argv = {
        "evaluate": ["evaluate", str(run), "--episodes", "1", "--out", str(afile / "x.csv")],
        "export": ["export", str(run), "--out", str(afile / "p.npz")],
        "play": ["play", str(run), "--video", str(afile / "v.gif")],
    }[command]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "is a file, not a folder" in err and err.count("\n") == 1, err
    assert afile.read_text() == "x"
