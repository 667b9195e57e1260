"""`adarl evaluate`: a sweep written into the run folder, and bad input (exit code 2)."""

import json

import pandas as pd
import pytest
from synthetic_runs import write_run

from adarl.cli.main import main

pytest.importorskip("mujoco")

FAST = ["--episodes", "1", "--max-episode-steps", "15", "--workers", "1"]


def test_sweep_is_written_into_the_run_folder(tmp_path, capsys):
    run = write_run(tmp_path, "r", seeds=(0, 1))
    argv = [
        "evaluate",
        str(run),
        "--sweep",
        "torso_length=0.3:0.5:3",
        "--hold",
        "foot_length=0.39",
        *FAST,
    ]
    assert main(argv) == 0
    name = "sweep-torso_length-0.3-0.5-3_hold-foot_length-0.39"
    table = pd.read_csv(run / "evaluations" / f"{name}.csv")
    assert len(table) == 3 * 2 and sorted(table["seed"].unique()) == [0, 1]
    assert sorted(table["p_torso_length"].unique()) == [0.3, 0.4, 0.5]
    assert list(table.columns[:6]) == ["step", "seed", "dynamics", "episode", "return", "length"]
    meta = json.loads((run / "evaluations" / f"{name}.json").read_text())
    assert meta["sweep"] == {"torso_length": [0.3, 0.4, 0.5]} and meta["hold"] == {
        "foot_length": 0.39
    }
    assert meta["command"].startswith(f"adarl evaluate {run} --sweep torso_length=0.3:0.5:3")
    out = capsys.readouterr().out
    assert "nominal:torso_length=0.4,foot_length=0.39:" in out and "over 2 seed(s)" in out


def test_fewer_episodes_do_not_replace_more(tmp_path, capsys):
    run = write_run(tmp_path, "r", seeds=(0,))
    argv = ["evaluate", str(run), "--dynamics", "fixed:torso_length=0.3", *FAST]
    path = run / "evaluations" / "fixed-torso_length=0.3.csv"
    assert main([*argv, "--episodes", "2"]) == 0 and len(pd.read_csv(path)) == 2
    stored = path.read_bytes()
    capsys.readouterr()
    assert main(argv) == 2  # FAST's 1 episode
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path} holds 2 episodes, more than the 1 of this" in err
    assert path.read_bytes() == stored
    assert main([*argv, "--episodes", "3"]) == 0 and len(pd.read_csv(path)) == 3  # more replaces


def test_out_and_the_dynamics_sweep_form(tmp_path):
    run = write_run(tmp_path, "r", seeds=(0,))
    out = tmp_path / "custom.csv"
    assert (
        main(["evaluate", str(run), "--dynamics", "sweep:mass_scale=0.5,mass_scale=", *FAST]) == 2
    )
    assert (
        main(
            [
                "evaluate",
                str(run),
                "--dynamics",
                "sweep:mass_scale=0.5:1.5:2",
                "--out",
                str(out),
                *FAST,
            ]
        )
        == 0
    )
    assert sorted(pd.read_csv(out)["p_mass_scale"]) == [0.5, 1.5]
    assert out.with_suffix(".json").is_file()


@pytest.mark.parametrize(
    "extra, fragment",
    [
        (["--sweep", "gravity=5:15:3"], "unknown parameter 'gravity' of task hopper"),
        (["--sweep", "torso_length=0.2:0.6:0"], "empty grid"),
        (["--dynamics", "sideways"], "unknown dynamics"),
        (["--episodes", "0"], "--episodes must be ≥ 1"),
        (["--checkpoint", "5"], "no checkpoint at step 5"),
        # one range grammar (issue 62): the error shows the forms --sweep and --hold take
        (["--sweep", "torso_length=0.2..x"], "allowed: torso_length=LO..HI[:N]"),
        (["--hold", "foot_length=0.2..0.4"], "use --sweep foot_length=0.2..0.4"),
    ],
)
def test_bad_requests_exit_2_and_write_nothing(tmp_path, capsys, extra, fragment):
    run = write_run(tmp_path, "r", seeds=(0,))
    assert main(["evaluate", str(run), *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("adarl evaluate: error:") and err.count("\n") == 1 and fragment in err, (
        err
    )
    assert not (run / "evaluations").exists()


def test_bad_folders_exit_2(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["evaluate", str(tmp_path / "empty")]) == 2
    assert "is not a run folder and holds none" in capsys.readouterr().err
    bare = write_run(tmp_path, "bare", checkpoint=False)
    assert main(["evaluate", str(bare)]) == 2
    assert f"{bare} has no complete checkpoint" in capsys.readouterr().err
    write_run(tmp_path / "two", "a")
    write_run(tmp_path / "two", "b", algo="sac")
    assert main(["evaluate", str(tmp_path / "two"), "--out", str(tmp_path / "x.csv")]) == 2
    assert "--out names one CSV but 2 runs" in capsys.readouterr().err


def cheetah_run(root, name="hc"):
    """A synthetic HalfCheetah-v5 run (a Gymnasium id outside the paper's four)."""
    import synthetic_runs

    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(synthetic_runs.DIMS, "HalfCheetah-v5", (17, 6))
        patch.setitem(synthetic_runs.PARAMS, "HalfCheetah-v5", {"mass_scale": 1.0})
        return write_run(root, name, algo="sac", task="HalfCheetah-v5", seeds=(0,))


def test_addressed_parameters_on_a_gymnasium_task_and_a_paper_task(tmp_path, capsys):
    cheetah = cheetah_run(tmp_path)
    argv = ["evaluate", str(cheetah), "--sweep", "body:torso.mass=4:9:3", *FAST]
    assert main([*argv, "--hold", "geom:floor.friction[0]=0.8"]) == 0
    name = "sweep-body-torso.mass-4-9-3_hold-geom-floor.friction.0-0.8"
    table = pd.read_csv(cheetah / "evaluations" / f"{name}.csv")
    assert list(table["p_body:torso.mass"]) == [4.0, 6.5, 9.0]
    assert set(table["p_geom:floor.friction[0]"]) == {0.8}
    meta = json.loads((cheetah / "evaluations" / f"{name}.json").read_text())
    assert meta["sweep"] == {"body:torso.mass": [4.0, 6.5, 9.0]}
    assert "--sweep body:torso.mass=4:9:3 --hold 'geom:floor.friction[0]=0.8'" in meta["command"]
    out = capsys.readouterr().out
    assert "nominal:body:torso.mass=6.5,geom:floor.friction[0]=0.8:" in out
    hopper = write_run(tmp_path, "hopper", seeds=(0,))
    argv = ["evaluate", str(hopper), "--dynamics", "sweep:body:thigh.mass=2:4:2,wind=0", *FAST]
    assert main(argv) == 2  # hopper has no wind
    assert "unknown parameter 'wind' of task hopper" in capsys.readouterr().err
    argv[3] = "sweep:body:thigh.mass=2:4:2,foot_length=0.3"
    assert main(argv) == 0
    table = pd.read_csv(
        hopper / "evaluations" / "sweep-body-thigh.mass-2-4-2_hold-foot_length-0.3.csv"
    )
    assert list(table["p_body:thigh.mass"]) == [2.0, 4.0]


@pytest.mark.parametrize(
    "extra, fragment",
    [
        (["--sweep", "body:tail.mass=1:2:2"], "unknown body 'tail' in 'body:tail.mass'; allowed: torso"),
        (["--sweep", "body:torso.volume=1:2:2"], "unknown attribute 'volume'"),
        (["--hold", "actuator:bthigh.gear=0"], "bad value"),
        (["--sweep", "torso_length=0.3:0.5:2"], "unknown parameter 'torso_length' of task HalfCheetah-v5"),
    ],
)  # fmt: skip
def test_bad_addressed_requests_exit_2_and_write_nothing(tmp_path, capsys, extra, fragment):
    run = cheetah_run(tmp_path)
    assert main(["evaluate", str(run), *extra, *FAST]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and fragment in err, err
    assert not (run / "evaluations").exists()
