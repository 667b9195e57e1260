"""Smoke tests of the scripts under bench/ (issue 38: `python bench/throughput.py`, the README's
speed command, ended in a traceback in its RNAC part): each runs at a tiny size and exits 0."""

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
def test_bench_throughput_runs_at_a_tiny_size():
    out = run_script("bench/throughput.py", "--steps", "30", "--warmup", "60", "--algos", "sac",
                     "--no-sb3", "--no-rnac")  # fmt: skip
    assert "sac    1 seed:" in out and "update at rank 7" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["bench/envs.py", "--steps", "50", "--rounds", "1", "--tasks", "hopper"],
        ["bench/ompo_refresh.py", "--steps", "50"],
    ],
)
def test_bench_scripts_run_at_a_tiny_size(argv):
    assert run_script(*argv)
