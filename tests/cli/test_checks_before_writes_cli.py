"""Issue 61 §4: every check that can fail runs before a run folder's first byte is written.

Dynamics that parse but that the model refuses when it is built (a massless body's mass, a
parameter given twice under two spellings) were found at the first reset, after `.lock`,
`config.yaml` and `environment.json` were written. Each is now one line, exit 2, and the
`--out` folder does not exist afterwards (or is as it was)."""

from __future__ import annotations

import pytest
from cli_errors import one_line_exit_2

import adarl

TINY = ["--preset", "smoke", "--total-steps", "200", "--no-progress"]
#: (task, dynamics flags, what the line says)
BAD = [
    ("HalfCheetah-v5", ["--dynamics", "fixed:body:world.mass=5"], "body:world.mass"),
    ("hopper", ["--dynamics", "fixed:body:world.mass=5"], "body:world.mass"),
    ("HalfCheetah-v5", ["--dynamics", "uniform:body:world.mass=2..5"], "body:world.mass"),
    (
        "hopper",
        ["--dynamics", "fixed:body:torso.mass=5,body:torso.mass[0]=60"],
        "given twice",
    ),
    (
        "HalfCheetah-v5",
        ["--dynamics", "fixed:geom:floor.friction=0.5,geom:floor.friction[0]=0.8"],
        "given twice",
    ),
    ("hopper", ["--eval-dynamics", "nominal,fixed:body:world.mass=5"], "body:world.mass"),
]


@pytest.mark.parametrize("task, flags, needle", BAD)
@pytest.mark.parametrize("algo", ["sac", "rnac"])
def test_dynamics_the_model_refuses_write_nothing(task, flags, needle, algo, tmp_path, capsys):
    out = tmp_path / "run"
    one_line_exit_2(
        ["train", "--algo", algo, "--task", task, *flags, *TINY, "--out", str(out)], capsys, needle
    )
    assert not out.exists()
    out.mkdir()  # an empty --out stays empty
    one_line_exit_2(
        ["train", "--algo", algo, "--task", task, *flags, *TINY, "--out", str(out)], capsys, needle
    )
    assert list(out.iterdir()) == []


def test_the_twice_given_parameter_is_named(tmp_path, capsys):
    err = one_line_exit_2(
        ["train", "--task", "hopper", "--dynamics", "fixed:body:torso.mass=5,body:torso.mass[0]=60"]
        + [*TINY, "--out", str(tmp_path / "run")],
        capsys,
    )
    assert not (tmp_path / "run").exists()
    assert "'body:torso.mass[0]' given twice" in err and "as 'body:torso.mass'" in err, err


@pytest.mark.parametrize("task, flags, needle", BAD[:4])
def test_the_python_api_writes_nothing_either(task, flags, needle, tmp_path):
    fields = {flags[0][2:].replace("-", "_"): flags[1]}
    with pytest.raises(adarl.UsageError, match=needle.replace("[", r"\[")):
        adarl.train("sac", task, out=tmp_path / "run", preset="smoke", total_steps=200, **fields)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("dry", [[], ["--dry-run"]])
def test_a_sweep_checks_its_units_dynamics_before_its_folder_exists(dry, tmp_path, capsys):
    sweep = tmp_path / "s.yaml"
    sweep.write_text(
        "tasks: [HalfCheetah-v5]\nalgos: [sac]\nseeds: 0\nbudget: 200\npreset: smoke\n"
        "dynamics: fixed:body:world.mass=5\n"
    )
    out = tmp_path / "sweep"
    one_line_exit_2(["sweep", str(sweep), "--out", str(out), *dry], capsys, "body:world.mass")
    assert not out.exists()


def test_what_only_building_the_model_finds_is_found_before_writing(tmp_path, capsys):
    """A box set by its fromto has no half-length to stretch: only the model's builder knows
    (its geom type and fromto), so the model is built once when the first env is made."""
    import user_env

    xml = tmp_path / "box.xml"
    arm = '<geom name="arm" type="box" fromto="0 0 0.1 0.2 0 0.1" size="0.02" mass="0.1"/>'
    xml.write_text(user_env.XML.replace('<geom name="ball_geom"', f'{arm}\n<geom name="ball_geom"'))
    out = tmp_path / "run"
    argv = ["train", "--algo", "sac", "--task", user_env.ENV_ID, "--env-module", "user_env"]
    argv += ["--env-kwargs", f"xml_file={xml}", "--dynamics", "fixed:geom:arm.size[1]=0.2"]
    one_line_exit_2([*argv, *TINY, "--out", str(out)], capsys, "is set by its fromto")
    assert not out.exists()


def test_a_fork_checks_its_evaluation_dynamics_before_its_folder_exists(tmp_path, capsys):
    from adarl.algos import sac_config
    from adarl.algos.sac_config import SAC_FAMILY
    from adarl.train import trainers

    values = {**SAC_FAMILY["sac"], **sac_config.PRESETS["smoke"], "algo": "sac", "task": "hopper"}
    fields = {"seeds": (0,), "total_steps": 400, "checkpoint_every": 200, "keep_checkpoints": 0}
    parent = tmp_path / "parent"
    trainers.train(sac_config.SACConfig(**{**values, **fields}), parent, progress=False)
    capsys.readouterr()  # the parent's own start line and budget warning
    out = tmp_path / "fork"
    for bad in ("fixed:body:world.mass=5", "fixed:body:torso.mass=5,body:torso.mass[0]=6"):
        argv = ["train", "--fork", str(parent), "--at", "200", "--eval-dynamics", bad]
        one_line_exit_2([*argv, "--out", str(out)], capsys, "body:")
        assert not out.exists()
