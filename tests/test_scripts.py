"""Smoke tests of the scripts under bench/ and docs/experiments/ (issue 38: `python
bench/throughput.py`, the README's speed command, ended in a traceback in its RNAC part): each
runs at a tiny size and exits 0. bench/same_bits.py has its own tests (tests/test_same_bits.py);
bench/parity.py needs Stable-Baselines3 (skipped without it)."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def run_script(*argv: str, timeout: int = 600) -> str:
    done = subprocess.run(
        [sys.executable, *argv], cwd=ROOT, capture_output=True, text=True, timeout=timeout
    )
    assert done.returncode == 0, (done.stdout[-2000:], done.stderr[-3000:])
    assert "Traceback" not in done.stderr, done.stderr[-3000:]
    return done.stdout


def test_the_rnac_part_of_the_throughput_benchmark_runs(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "bench"))
    import throughput_rnac

    small = {"rollout_steps": 64, "minibatch_size": 32, "epochs": 1}
    result = throughput_rnac.train_throughput("hopper", 128, 1, **small)
    assert result["per_seed"] > 0 and result["episode_length"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("task, free_joint", [("hopper", False), ("ant", True)])
def test_mjx_rk4_is_the_textbook_rk4_and_mujoco_c_departs_only_with_a_free_joint(task, free_joint):
    """bench/device_physics.py rk4 (docs/envs.md, "Device physics"): one RK4 step in float64.
    Measured 2026-12-04 (mujoco 4.0.0, mujoco-mjx 3.17.0): MJX within 2.2e-16 of a textbook RK4
    built from C's own mj_forward and mj_integratePos; C's mj_step identical to it on Hopper and
    6.7e-8 apart in qpos on Ant (Humanoid 3.2e-8). A new MuJoCo that changes this fails here."""
    from adarl.device import missing_reason

    if missing_reason() is not None:
        pytest.skip(str(missing_reason()))
    # a process of its own: float64 compiles of MJX's RK4 in this one would be reused by later
    # float32 compiles of the same inner functions and fail them (seen in CI)
    out = {}
    for line in run_script("bench/device_physics.py", "rk4", task).splitlines():
        found = re.search(r"(mj_step|MJX) − textbook: qpos (\S+), qvel (\S+)$", line)
        if found:
            out[found[1]] = (float(found[2]), float(found[3]))
    assert set(out) == {"mj_step", "MJX"}
    assert max(out["MJX"]) < 1e-12
    assert (out["mj_step"][0] > 1e-9) == free_joint
    assert out["mj_step"][1] < 1e-8  # the velocities agree: the step's positions part


@pytest.mark.slow
def test_bench_throughput_runs_at_a_tiny_size():
    out = run_script("bench/throughput.py", "--steps", "30", "--warmup", "60", "--algos", "sac",
                     "--no-sb3", "--no-rnac")  # fmt: skip
    assert "sac    1 seed:" in out and "update at rank 7" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["bench/envs.py", "--steps", "50", "--rounds", "1", "--tasks", "hopper"],
        ["bench/ompo_refresh.py", "--steps", "50"],
        # policy files replaced after write_run: the checkpoint's checksums must follow
        ["bench/suites.py", "--suite", "m2td3-1d", "--workers", "1", "--steps", "100"],
        ["bench/throughput_rnac.py", "--steps", "256"],
        ["bench/checkpoint_memory.py", "--seeds", "2", "--rows", "1000", "--task", "hopper"],
    ],
)
def test_bench_scripts_run_at_a_tiny_size(argv):
    assert run_script(*argv)


def test_bench_parity_runs_at_a_tiny_size(tmp_path):
    pytest.importorskip("stable_baselines3")  # pip install -e .[bench]
    out = run_script("bench/parity.py", "--steps", "200", "--seeds", "0", "--eval-every", "100",
                     "--eval-episodes", "1", "--sb3-procs", "1", "--start-steps", "50",
                     "--update-after", "50", "--out", str(tmp_path / "parity"))  # fmt: skip
    assert (tmp_path / "parity" / "summary.md").is_file(), out


# ----------------------------------------------------------------------------- docs/experiments
EXPERIMENTS = ROOT / "docs" / "experiments"


def _sweep(root: Path, task: str, unit: str, algo: str, seeds=(0, 1, 2), **kwargs) -> Path:
    """A run of the sweep layout the experiment scripts read: SWEEP/<task>/<unit>/seeds-a-b."""
    from synthetic_runs import write_run

    name = f"seeds-{seeds[0]}-{seeds[-1]}"
    return write_run(root / task / unit, name, algo=algo, task=task, seeds=seeds, **kwargs)


def _control_of(method: Path, unit: str) -> Path:
    """The control of a synthetic AdaRL run: the same prefix, its proposals logged, not applied."""
    import shutil

    import pandas as pd

    control = method.parent.parent / unit / method.name
    shutil.copytree(method, control)
    cuts = pd.read_csv(control / "truncations.csv")
    cuts["new_rank"] = cuts["old_rank"]
    cuts["decision"] = "control"
    cuts.to_csv(control / "truncations.csv", index=False)
    return control


def test_physics_power_runs_on_a_sweep(tmp_path):
    for unit in ("sac_physics-consistent", "sac_physics-ompo", "sac_paper-ompo"):
        _sweep(tmp_path, "hopper", unit, "sac", quality=0.5 + len(unit) / 40)
    out = run_script(str(EXPERIMENTS / "physics_power.py"), str(tmp_path))
    assert "| ompo − consistent |" in out and "nan" not in out.split("comparison")[0]


def test_claim2_first_look_runs_on_a_sweep(tmp_path):
    _sweep(tmp_path, "hopper", "adarl_rank_rule-cumulative", "adarl")
    out = run_script(str(EXPERIMENTS / "claim2_first_look.py"), str(tmp_path))
    assert "| Hopper | 250k |" in out


def test_mechanism_and_paper_schedule_run_on_a_sweep(tmp_path):
    method = _sweep(tmp_path, "hopper", "adarl-eq5", "adarl")
    _control_of(method, "adarl-control-eq5")
    out = run_script(str(EXPERIMENTS / "mechanism.py"), str(tmp_path))
    assert "| True |" in out and "sign-flip p =" in out
    method = _sweep(tmp_path, "walker2d", "adarl_rank_rule-cumulative", "adarl")
    _control_of(method, "adarl-control-eq5")
    _sweep(tmp_path, "walker2d", "sac", "sac", quality=0.8)
    figure = tmp_path / "figure"
    out = run_script(str(EXPERIMENTS / "paper_schedule.py"), str(tmp_path), "10000", str(figure))
    assert out and figure.with_suffix(".png").is_file()


def test_recheck_runs_on_a_copy_of_the_committed_tables(tmp_path):
    import shutil

    copy = shutil.copytree(EXPERIMENTS, tmp_path / "experiments")
    run_script(str(copy / "recheck.py"))
    made = (copy / "recheck.md").read_text()
    assert "## Comparisons" in made and "## What cannot be recomputed" in made
    assert "| repro-hopper |" in made or "repro-hopper" in made
    # the committed report is what the script writes (timing line aside)
    committed = (EXPERIMENTS / "recheck.md").read_text()
    assert made.split("\n")[7:] == committed.split("\n")[7:]


@pytest.mark.parametrize(("n_x", "n_y"), [(3, 3), (5, 3), (5, 5), (12, 9)])
def test_recheck_welch_power_agrees_with_adarls(monkeypatch, n_x, n_y):
    """recheck.py averages Welch's power over random sample variances; adarl's `welch_power`
    integrates it by quadrature on χ² quantiles. Two methods, one number."""
    from adarl import stats

    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    import recheck

    ours = recheck.detectable(1000.0, n_x, n_y)
    theirs = stats.welch_minimum_detectable_difference(1000.0, 1000.0, n_x, n_y)
    assert ours == pytest.approx(theirs, rel=5e-3)
    assert recheck.power(theirs, 1000.0, n_x, n_y) == pytest.approx(0.8, abs=3e-3)


def _accelerator_check(tmp_path, **settings) -> list[list[str]]:
    """bench/accelerator.sh on this machine's CPU with `settings` (its environment variables);
    the rows of its two CSVs, training's then raw physics', headers included."""
    env = os.environ | {
        "WHEELS": "none",
        "PYTHON": sys.executable,
        "JAX_PLATFORMS": "cpu",
        "OUT": str(tmp_path),
        "CHUNKS": "1",
        "BUFFER": "1000",
        "STEPS": "2",
        **settings,
    }
    done = subprocess.run(
        ["bash", "bench/accelerator.sh"], cwd=ROOT, env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return [
        [row.split(",") for row in (tmp_path / name).read_text().splitlines()]
        for name in ("accelerator-learner.csv", "accelerator.csv")
    ]


def test_the_accelerator_check_runs_on_the_cpu_at_a_tiny_size(tmp_path):
    """bench/accelerator.sh, the prepared GPU check, on this machine's CPU in seconds: the host
    line and MuJoCo C's physics line measured, and each device measurement (MJX, whose compile
    alone takes minutes on a CPU: the test below) given settings it refuses at once, a solver
    cap of 0 iterations and a platform that does not exist, so that every loop of the script
    runs and each failure costs only its own row."""
    learner, physics = _accelerator_check(
        tmp_path,
        LEARNER_RUNS="hopper:nominal:2:0,4",
        PHYSICS="hopper:2",
        PLATFORM="no-such-platform",
        SOLVERS="100,4",
        LIMIT="120",
        BUDGET="600",
    )
    assert learner[0][:6] == ["task", "dynamics", "solver", "backend", "platform", "seeds"]
    assert [row[:6] for row in learner[1:]] == [
        ["hopper", "nominal", "0/4", "device", "failed", "2"],
        ["hopper", "nominal", "", "host", "cpu", "1"],
    ]
    assert "device-solver must be 'xml'" in ",".join(learner[1])  # its own error, in its row
    assert float(learner[2][9]) > 0  # the host's seed-steps/s
    assert physics[0][:2] == ["task", "kind"]
    assert [row[:4] for row in physics[1:]] == [
        ["hopper", "mujoco_c", "cpu", "1"],
        ["hopper", "mjx", "failed", "2"],
        ["hopper", "mjx-100/4", "failed", "2"],
    ]
    assert float(physics[1][7]) > 0  # MuJoCo C's env-steps/s


@pytest.mark.skipif(
    not os.environ.get("ADARL_ACCELERATOR_CHECK"),
    reason="compiles MJX on the CPU five times (17 min on a loaded 2-core machine, issue 57); "
    "run with ADARL_ACCELERATOR_CHECK=1",
)
@pytest.mark.timeout(3600)  # beyond the suite's per-test limit: five MJX compiles
def test_the_accelerator_check_measures_the_device_on_the_cpu(tmp_path):
    """The same check with every device measurement done: one device line (Hopper, 2 seeds, one
    timed chunk), one Walker2d line under the paper's per-episode physics with the solver's line
    search capped (1 seed), the host line; raw physics: MuJoCo C and MJX Hopper on 2 lanes, with
    the XML's solver and capped."""
    pytest.importorskip("mujoco.mjx")
    learner, physics = _accelerator_check(
        tmp_path,
        LEARNER_RUNS="hopper:nominal:2:xml walker2d:paper:1:100,4",
        PHYSICS="hopper:2",
        PLATFORM="cpu",
        SOLVERS="100,4",
        LIMIT="900",
        BUDGET="3600",
    )
    assert learner[0][:6] == ["task", "dynamics", "solver", "backend", "platform", "seeds"]
    device, paper, host = learner[1:]
    assert device[:6] == ["hopper", "nominal", "xml", "device", "cpu", "2"]
    assert paper[:6] == ["walker2d", "paper", "100/4", "device", "cpu", "1"]
    assert host[:6] == ["hopper", "nominal", "", "host", "cpu", "1"]
    assert all(float(row[9]) > 0 for row in (host, device, paper))  # seed-steps/s
    assert physics[0][:2] == ["task", "kind"]
    assert [row[:4] for row in physics[1:]] == [
        ["hopper", "mujoco_c", "cpu", "1"],
        ["hopper", "mjx", "cpu", "2"],
        ["hopper", "mjx-100/4", "cpu", "2"],
    ]
    assert all(float(row[7]) > 0 for row in physics[1:])  # env-steps/s


def test_device_parity_compares_the_final_evaluations(tmp_path):
    """bench/device_parity.py on two synthetic runs: the scores are the mean returns of each
    seed's last nominal evaluation, read back here from eval.csv by hand."""
    import csv

    from synthetic_runs import write_run

    host = write_run(tmp_path, "host", algo="sac", quality=1.0)
    device = write_run(tmp_path, "device", algo="sac", quality=1.5)

    def last(run):
        rows = [r for r in csv.DictReader((run / "eval.csv").open()) if r["dynamics"] == "nominal"]
        step = max(int(r["step"]) for r in rows)
        by_seed = {}
        for r in rows:
            if int(r["step"]) == step:
                by_seed.setdefault(int(r["seed"]), []).append(float(r["return"]))
        return [sum(v) / len(v) for _, v in sorted(by_seed.items())]

    difference = sum(last(device)) / 3 - sum(last(host)) / 3
    out = run_script(
        "bench/device_parity.py", str(host), str(device), "--copy", str(tmp_path / "c")
    )
    assert f"| {difference:+,.0f} | [" in out
    assert (tmp_path / "c" / "device" / "eval.csv").read_bytes() == (
        device / "eval.csv"
    ).read_bytes()


def test_device_parity_refuses_a_folder_without_runs_in_one_line(tmp_path):
    """A missing run folder, or runs of different budgets: one line on stderr, exit 2."""
    from synthetic_runs import write_run

    host = write_run(tmp_path, "host", algo="sac", quality=1.0)
    short = write_run(tmp_path, "short", algo="sac", quality=1.0, total_steps=1000)
    cases = [
        ((str(tmp_path / "nothing"), str(host)), "host run "),
        ((str(host), str(short)), "the runs' last evaluations differ"),
    ]
    for argv, words in cases:
        done = subprocess.run(
            [sys.executable, "bench/device_parity.py", *argv],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
        assert done.returncode == 2 and done.stdout == "", done
        assert done.stderr.count("\n") == 1 and words in done.stderr, done.stderr


@pytest.mark.parametrize("script", ["bench/accelerator.sh", "bench/accelerator_wheels.sh"])
def test_the_accelerator_scripts_have_help_and_refuse_arguments_in_one_line(script):
    shown = subprocess.run(["bash", script, "--help"], cwd=ROOT, capture_output=True, text=True)
    assert shown.returncode == 0 and "wheels" in shown.stdout and "set -" not in shown.stdout
    done = subprocess.run(["bash", script, "--bogus"], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "unknown argument '--bogus'" in done.stderr


def test_the_device_before_after_script_has_help_and_refuses_bad_arguments(tmp_path):
    """bench/device_before_after.sh (docs/benchmarks.md): --help, and a missing or bad checkout
    is one line, exit 2, nothing written (the measurement itself needs an idle machine)."""
    script = str(ROOT / "bench" / "device_before_after.sh")
    shown = subprocess.run(["bash", script, "--help"], capture_output=True, text=True)
    assert shown.returncode == 0 and "before, after, before, after" in shown.stdout
    for argv in ([], [str(tmp_path / "nope"), str(tmp_path / "out.csv")]):
        bad = subprocess.run(["bash", script, *argv], capture_output=True, text=True)
        assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    assert not (tmp_path / "out.csv").exists()
