"""The examples of docs/lowrank.md run, cut and report ranks: the pure-JAX one always, the
Stable-Baselines-JAX one when the `sbx` extra is installed (skipped with the reason if not)."""

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def run(script: str, *args: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, str(ROOT / "examples" / script), *args],
        capture_output=True, text=True, env=env, timeout=600, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_pure_jax_example_cuts():
    out = run("lowrank_pure_jax.py", "1000")
    ranks = [(int(a), int(b)) for a, b in re.findall(r"rank (\d+) -> (\d+)", out)]
    assert len(ranks) == 2 and ranks[0][0] == 64
    assert all(new <= old for old, new in ranks) and ranks[-1][1] < 64


MISSING = [m for m in ("sbx", "flax", "stable_baselines3") if importlib.util.find_spec(m) is None]


@pytest.mark.skipif(bool(MISSING), reason=f"the sbx extra is not installed (no {MISSING}): "
                    'pip install -e ".[sbx]" -c constraints.txt')  # fmt: skip
def test_sbx_example_trains_truncates_and_logs_ranks():
    out = run("sbx_adarl_hopper.py", "400", "200")
    lines = re.findall(r"step (\d+) (\w+)\[.*?\]: rank (.+)", out)
    assert {(step, name) for step, name, _ in lines} == {
        (s, n) for s in ("200", "400") for n in ("actor_state", "qf_state")
    }
    actor = [int(r) for step, name, r in lines if name == "actor_state"]
    critics = [json.loads(r) for step, name, r in lines if name == "qf_state"]  # [q1, q2]
    assert 256 > actor[0] >= actor[1] >= 1
    assert all(len(c) == 2 and max(c) < 256 for c in critics)
