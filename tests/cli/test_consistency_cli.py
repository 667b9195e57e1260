"""One flag, one meaning, one clear error (issue 27, class 5): bad values every command rejects
alike, with a one-line message naming the value and what is allowed, and exit code 2."""

from __future__ import annotations

import os

import mujoco  # noqa: F401  (imported with this process's MUJOCO_GL, before `adarl play` sets one)
import pytest
import yaml
from synthetic_runs import write_run

from adarl.algos import registry
from adarl.cli.main import main


def error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err


@pytest.mark.parametrize("value", ["-5", "0", "nan"])
def test_sweep_progress_every_must_be_positive(value, tmp_path, capsys):
    argv = ["sweep", "smoke", "--dry-run", "--progress-every", value, "--out", str(tmp_path / "s")]
    assert main(argv) == 2
    assert f"--progress-every must be seconds > 0, got {float(value):g}" in error_line(capsys)
    assert not (tmp_path / "s").exists()


def test_sweep_and_evaluate_both_refuse_an_address_without_ray(tmp_path, capsys):
    address = ["--backend", "local", "--address", "10.0.0.1:6379"]
    assert main(["sweep", "smoke", "--dry-run", *address, "--out", str(tmp_path / "s")]) == 2
    err = error_line(capsys)
    assert "--address is for --backend ray, got --address 10.0.0.1:6379 with --backend local" in err
    assert "allowed: --backend ray --address HOST:PORT, or no --address" in err
    run = write_run(tmp_path, "r", seeds=(0,))
    assert main(["evaluate", str(run), "--suite", "m2td3-1d", *address]) == 2
    assert "--address is for --backend ray" in error_line(capsys)
    assert main(["evaluate", str(run), *address]) == 2
    assert "--address" in error_line(capsys)


@pytest.mark.parametrize("algo", registry.ALGOS)
def test_eval_episodes_zero_is_refused_by_every_algorithm(algo, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "--algo", algo, "--preset", "smoke", "--eval-episodes", "0", "--out", str(out)]
    assert main([*argv, "--no-progress"]) == 2
    assert "eval-episodes must be > 0, got 0" in error_line(capsys)
    assert not out.exists()


@pytest.mark.parametrize("algo", registry.ALGOS)
def test_empty_eval_dynamics_is_refused_not_a_silent_no_evaluation(algo, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "--algo", algo, "--preset", "smoke", "--eval-dynamics", "", "--out", str(out)]
    assert main([*argv, "--no-progress"]) == 2
    err = error_line(capsys)
    assert "eval-dynamics is empty" in err and "allowed: one or more dynamics" in err, err
    assert not out.exists()


@pytest.mark.parametrize("algo", registry.ALGOS)
def test_seeds_given_as_a_number_in_config_yaml(algo, tmp_path, capsys):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    config = {"algo": algo, "format_version": 1, "task": "hopper", "seeds": 0}
    (run_dir / "config.yaml").write_text(yaml.safe_dump(config))
    assert main(["train", "--resume", str(run_dir), "--no-progress"]) == 2
    err = error_line(capsys)
    assert "field 'seeds' is 0; allowed: a list of integers" in err and "is empty" not in err, err


@pytest.mark.parametrize("algo", ["sac", "rnac"])
@pytest.mark.parametrize(
    "line, message",
    [
        ("total_steps: 1e4", "field 'total_steps' is '1e4'; allowed: an integer"),  # YAML: text
        ("total_steps: 2000.5", "field 'total_steps' is 2000.5; allowed: an integer"),
        ("total_steps: true", "field 'total_steps' is True; allowed: an integer"),
        ("gamma: abc", "field 'gamma' is 'abc'; allowed: a number"),
        ("hidden: 64", "field 'hidden' is 64; allowed: a list of integers"),
        ("hidden: [64, x]", "field 'hidden' is [64, 'x']; allowed: a list of integers"),
        ("task: 5", "field 'task' is 5; allowed: text"),
        ("eval_every: 0", "eval-every must be > 0, got 0"),  # the range, as for --eval-every
    ],
)
def test_a_hand_edited_config_yaml_value_is_checked_like_its_flag(
    algo, line, message, tmp_path, capsys
):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text(f"algo: {algo}\nformat_version: 1\n{line}\n")
    assert main(["train", "--resume", str(run_dir), "--no-progress"]) == 2
    err = error_line(capsys)
    assert message in err, err
    assert [p.name for p in run_dir.iterdir()] == ["config.yaml"]  # nothing written


@pytest.mark.parametrize(
    "line", ["total_steps: '2000'", "gamma: 0.9", "gamma: 1", "seeds: [0, 1]", "lr_alpha: 3e-4"]
)
def test_config_yaml_values_a_flag_would_accept_are_accepted(line, tmp_path):
    from adarl.algos import registry as reg

    values = yaml.safe_load(f"algo: sac\nformat_version: 1\n{line}\n")
    name = line.partition(":")[0]
    _, config = reg.config_from_record(values, "config.yaml")
    flag = reg.resolve_config("sac", flags={name: str(values[name]).strip("[]")})
    assert getattr(config, name) == getattr(flag, name)


def test_play_wider_than_the_framebuffer_names_the_flag_not_the_gl_backend(
    tmp_path, capsys, monkeypatch
):
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))  # play sets these
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    run = write_run(tmp_path, "r", seeds=(0,))
    video = tmp_path / "v.gif"
    for flag, value in (("--width", "4000"), ("--height", "3000")):
        assert main(["play", str(run), "--video", str(video), flag, value]) == 2
        err = error_line(capsys)
        assert f"{flag} {value} is larger than the model's offscreen framebuffer" in err, err
        assert "allowed: 16 to" in err and "MUJOCO_GL" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r"]  # no video, no temp file


@pytest.mark.parametrize("command", ["evaluate", "export"])
def test_a_newer_run_format_is_named_as_such(command, tmp_path, capsys):
    run = write_run(tmp_path, "r", seeds=(0,))
    config = yaml.safe_load((run / "config.yaml").read_text())
    (run / "config.yaml").write_text(yaml.safe_dump({**config, "format_version": 2}))
    for checkpoint in (run / "checkpoints").iterdir():  # a layout this adarl does not know
        for file in checkpoint.iterdir():
            file.rename(file.with_suffix(".v2"))
    argv = {
        "evaluate": ["evaluate", str(run), "--episodes", "1"],
        "export": ["export", str(run), "--out", str(tmp_path / "p.npz")],
    }[command]
    assert main(argv) == 2
    err = error_line(capsys)
    assert "written in run format 2 by a newer adarl" in err and "reads format 1" in err, err
    assert "no complete checkpoint" not in err


@pytest.mark.parametrize("value", ["-1", "0"])
def test_a_length_out_of_range_names_the_range(value, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "--preset", "smoke", "--dynamics", f"fixed:torso_length={value}"]
    assert main([*argv, "--out", str(out), "--no-progress"]) == 2
    err = error_line(capsys)
    assert f"bad value '{value}' for torso_length; allowed: 0.02 to 2 " in err, err
    assert not out.exists()
    argv[-1] = "fixed:torso_length=5"
    assert main([*argv, "--out", str(out), "--no-progress"]) == 2
    assert "implausible value 5 for torso_length; allowed: 0.02 to 2 " in error_line(capsys)
