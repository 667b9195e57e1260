"""Shared by the sweep tests: one JAX compilation cache for every unit process (the first unit
compiles, later ones load), tiny sweep files, and checks on finished runs."""

import csv
import os
from pathlib import Path

import pytest
import yaml


@pytest.fixture(scope="session")
def jax_cache():
    """The test suite's compilation cache (tests/conftest.py), so the units reuse what the
    trainer tests compiled for the same smoke settings (JAX keys entries by program, flags and
    version: a stale entry is never used)."""
    return os.environ["JAX_COMPILATION_CACHE_DIR"]


@pytest.fixture(autouse=True)
def _shared_jax_cache(jax_cache, monkeypatch):
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(jax_cache))
    monkeypatch.setenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")


@pytest.fixture
def write_spec():
    return _write_spec


@pytest.fixture
def assert_complete():
    return _assert_complete


def _write_spec(path: Path, **changes) -> Path:
    """A one-unit sweep file: SAC on Hopper, seeds 0-1, the `smoke` preset's settings (so the
    compiled functions are the smoke sweep's), `changes` on top."""
    doc = {
        "name": "tiny",
        "tasks": ["hopper"],
        "algos": ["sac"],
        "seeds": "0-1",
        "budget": 1000,
        "dynamics": "paper",
        "preset": "smoke",
        "evaluation": {"eval_every": 500, "eval_episodes": 1},
        "overrides": {"checkpoint_every": 500, "log_every": 250},
    }
    doc.update(changes)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _assert_complete(run_dir: Path, total_steps: int, seeds=(0, 1)) -> None:
    """DONE at the budget, and every log row written once (no duplicates from a resume)."""
    assert (run_dir / "DONE").read_text().strip() == str(total_steps)
    episodes = _read_rows(run_dir / "episodes.csv")
    for seed in seeds:
        numbers = [int(r["episode"]) for r in episodes if int(r["seed"]) == seed]
        assert numbers == list(range(len(numbers))) and numbers, (seed, numbers)
    train = [(r["step"], r["seed"]) for r in _read_rows(run_dir / "train.csv")]
    assert len(train) == len(set(train))
    assert max(int(s) for s, _ in train) == total_steps
