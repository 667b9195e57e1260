"""`adarl evaluate --suite`: end to end on tiny runs (files, report), and bad input (exit 2,
nothing written)."""

import json

import pandas as pd
import pytest
from synthetic_runs import write_run

from adarl.cli.main import main
from adarl.evaluation import suites

pytest.importorskip("mujoco")

FAST = ["--episodes", "1", "--max-episode-steps", "10", "--no-progress"]


@pytest.fixture
def tiny_suite(monkeypatch):
    """m2td3-2d's parameters on a 2 x 2 grid, so that the test stays fast."""
    full = suites.get_suite("m2td3-2d", "hopper")
    small = suites.Suite("tiny-2d", "hopper", full.ranges, "test", points=2, episodes=2)
    monkeypatch.setitem(suites.SUITES, "tiny-2d", {"hopper": small})
    return small


def test_suite_is_written_and_reported(tmp_path, capsys, tiny_suite):
    runs = tmp_path / "runs"
    sac = write_run(runs, "sac", algo="sac", seeds=(0, 1), quality=0.8)
    adarl = write_run(runs, "adarl", algo="adarl", seeds=(0, 1))
    argv = ["evaluate", str(runs), "--suite", "tiny-2d", "--workers", "1", *FAST]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "suite tiny-2d" in out and "worst-case" in out and "over 4 points and 2 seed(s)" in out
    for run in (sac, adarl):
        summary = pd.read_csv(run / "suites" / "tiny-2d.csv")
        assert list(summary.columns) == suites.SUMMARY_COLUMNS
        assert list(summary["seed"]) == [0, 1] and set(summary["points"]) == {4}
        table = pd.read_csv(run / "evaluations" / "suite-tiny-2d.csv")
        assert len(table) == 4 * 2 * 1  # points x seeds x episodes (--episodes 1)
        means = table.groupby(["seed", "dynamics"])["return"].mean().groupby("seed")
        assert list(summary["worst"]) == pytest.approx(list(means.min()), rel=1e-5)
        assert list(summary["average"]) == pytest.approx(list(means.mean()), rel=1e-5)
        meta = json.loads((run / "evaluations" / "suite-tiny-2d.json").read_text())
        assert meta["suite"] == "tiny-2d" and meta["name"] == "suite-tiny-2d"
        assert meta["command"].startswith(f"adarl evaluate {runs} --suite tiny-2d")
    report = tmp_path / "report"
    assert main(["report", str(runs), "--out", str(report), "--bootstrap-reps", "100"]) == 0
    text = (report / "index.md").read_text()
    assert "## Robustness suites" in text and "| hopper | tiny-2d | adarl | 2 | 4 × 1 |" in text
    rows = pd.read_csv(report / "tables" / "suites.csv")
    assert sorted(rows["method"]) == ["adarl", "sac"]
    assert (report / "figures" / "suite_hopper_tiny-2d_adarl.png").is_file()


def test_points_gives_a_coarser_grid_over_the_same_ranges(tmp_path, capsys):
    run = write_run(tmp_path, "hopper", seeds=(0,))
    argv = ["evaluate", str(run), "--suite", "paper", "--points", "2", "--workers", "1", *FAST]
    assert main(argv) == 0
    table = pd.read_csv(run / "evaluations" / "suite-paper.csv")
    corners = {(0.2, 0.19), (0.2, 0.59), (0.6, 0.19), (0.6, 0.59)}  # the ranges' ends
    assert set(zip(table["p_torso_length"], table["p_foot_length"])) == corners
    assert len(table) == 4  # 2 x 2 points, 1 seed, 1 episode
    meta = json.loads((run / "evaluations" / "suite-paper.json").read_text())
    assert meta["suite_points"] == 2 and " --points 2 " in meta["command"]
    assert "over 4 points and 1 seed(s)" in capsys.readouterr().out


def test_a_smaller_evaluation_does_not_replace_a_larger_one(tmp_path, capsys):
    run = write_run(tmp_path, "hopper", seeds=(0,))
    argv = ["evaluate", str(run), "--suite", "paper", "--workers", "1", *FAST]
    assert main([*argv, "--points", "2"]) == 0  # a coarse look: 4 points x 1 episode
    assert main([*argv, "--points", "3"]) == 0  # a larger one replaces it
    stored = {p: p.read_bytes() for p in run.glob("*/*paper*")}  # the episodes and summary
    assert pd.read_csv(run / "suites/paper.csv")["points"].tolist() == [9]
    capsys.readouterr()
    for smaller in (["--points", "2"], ["--points", "2", "--episodes", "2"]):  # 4 and 8 < 9
        assert main([*argv, *smaller]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1
        assert f"{run}/evaluations/suite-paper.csv holds 9 episodes, more than the" in err
    assert {p: p.read_bytes() for p in run.glob("*/*paper*")} == stored
    assert main([*argv, "--points", "3"]) == 0  # the same again: a rerun replaces it


def _files(root):
    return sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file())


@pytest.mark.parametrize(
    "make_runs, extra, fragment",
    [
        (["hopper"], ["--suite", "m2td3-9d"], "unknown suite 'm2td3-9d'; allowed: m2td3-1d"),
        (
            ["hopper", "humanoid"],
            ["--suite", "m2td3-1d"],
            "suite 'm2td3-1d' does not apply to task 'humanoid'",
        ),
        (["hopper"], ["--suite", "paper", "--sweep", "mass_scale=1:2:2"], "without --sweep"),
        (["hopper"], ["--backend", "ray"], "apply to --suite evaluations"),
        (["hopper"], ["--suite", "paper", "--episodes", "0"], "--episodes must be ≥ 1"),
        (["hopper"], ["--suite", "paper", "--points", "1"], "--points must be ≥ 2"),
        (["hopper"], ["--points", "3"], "--points applies to --suite evaluations"),
    ],
)
def test_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, make_runs, extra, fragment):
    for task in make_runs:
        write_run(tmp_path, task, task=task, seeds=(0,))
    before = _files(tmp_path)
    assert main(["evaluate", str(tmp_path), *FAST, *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("adarl evaluate: error:") and err.count("\n") == 1 and fragment in err, (
        err
    )
    assert _files(tmp_path) == before


def test_a_ray_address_that_does_not_answer(tmp_path, capsys, tiny_suite):
    pytest.importorskip("ray")
    write_run(tmp_path, "hopper", seeds=(0,))
    before = _files(tmp_path)
    argv = ["evaluate", str(tmp_path), *FAST, "--suite", "tiny-2d", "--backend", "ray"]
    assert main([*argv, "--address", "127.0.0.1:1"]) == 2
    err = capsys.readouterr().err
    assert "cannot reach the Ray cluster at 127.0.0.1:1" in err and err.count("\n") == 1
    assert _files(tmp_path) == before


def task_run(root, name, task, dims, algo):
    """A synthetic run of a Gymnasium id (`synthetic_runs` knows the paper's four only)."""
    import synthetic_runs

    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(synthetic_runs.DIMS, task, dims)
        patch.setitem(synthetic_runs.PARAMS, task, {"mass_scale": 1.0})
        return write_run(root, name, algo=algo, task=task, seeds=(0, 1))


def test_rrls_suites_of_gymnasium_tasks_and_a_report_grouped_by_task(tmp_path, capsys):
    runs = tmp_path / "runs"
    task_run(runs, "pendulum-sac", "InvertedPendulum-v5", (4, 1), "sac")
    task_run(runs, "cheetah-sac", "HalfCheetah-v5", (17, 6), "sac")
    write_run(runs, "hopper-sac", algo="sac", seeds=(0, 1))
    argv = ["evaluate", str(runs), "--suite", "rrls-2d", "--points", "2", "--workers", "1", *FAST]
    assert main(argv) == 0
    table = pd.read_csv(runs / "pendulum-sac" / "evaluations" / "suite-rrls-2d.csv")
    grid = sorted(set(zip(table["p_body:pole.mass"], table["p_body:cart.mass"])))
    assert grid == [(1.0, 1.0), (1.0, 11.0), (31.0, 1.0), (31.0, 11.0)]  # RRLS's ends, both
    cheetah = pd.read_csv(runs / "cheetah-sac" / "evaluations" / "suite-rrls-2d.csv")
    assert sorted(set(cheetah["p_friction_scale"])) == [0.25, 10.0]  # world friction 0.1, 4.0
    meta = json.loads((runs / "cheetah-sac" / "evaluations" / "suite-rrls-2d.json").read_text())
    assert meta["suite_ranges"] == {"friction_scale": [0.25, 10.0], "body:torso.mass": [0.1, 7.0]}
    assert "half_cheetah.py HalfCheetahParamsBound.TWO_DIM" in meta["suite_source"]
    capsys.readouterr()
    report = tmp_path / "report"
    assert main(["report", str(runs), "--out", str(report), "--bootstrap-reps", "100"]) == 0
    rows = pd.read_csv(report / "tables" / "suites.csv")
    assert list(dict.fromkeys(rows["task"])) == ["hopper", "HalfCheetah-v5", "InvertedPendulum-v5"]
    text = (report / "index.md").read_text()
    assert "| InvertedPendulum-v5 | rrls-2d | sac | 2 | 4 × 1 |" in text
    assert (report / "figures" / "suite_HalfCheetah-v5_rrls-2d_sac.png").is_file()
    from adarl.results.runs import sort_tasks  # the order every report section uses

    tasks = ["Reacher-v5", "gym:Pendulum-v1", "ant", "adarltest/Bot-v0", "hopper", "Ant-v5"]
    assert sort_tasks(tasks) == [
        "hopper", "ant", "adarltest/Bot-v0", "Ant-v5", "gym:Pendulum-v1", "Reacher-v5",
    ]  # fmt: skip
