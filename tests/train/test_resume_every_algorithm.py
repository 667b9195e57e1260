"""Every registered algorithm keeps the exact-resume promise (the pattern of Stable-Baselines3's
test_deterministic.py): a tiny run killed between two checkpoints and resumed (reading every
array of its checkpoint memory-mapped), or stopped there by SIGTERM (a checkpoint where it stops)
and resumed, writes the same CSV rows, spectra, final checkpoint arrays and policy files as the
same run uninterrupted. And a seed's numbers are its own (the lane promise,
docs/algorithms.md): seed 1 trained alone writes what it writes beside seed 0."""

import json
import os
import signal

import numpy as np
import pytest
from seed_slices import assert_seed_slice_equal

from adarl.algos import registry
from adarl.errors import Stopped
from adarl.runs import checkpoints, folder, npz
from adarl.runs.layout import CHECKPOINT_DIR
from adarl.runs.logs import read_csv
from adarl.train import loop
from adarl.train.trainers import trainer

# Each algorithm's `smoke` preset with the budgets of its own tests (tests/algos/test_sac_family.py,
# tests/algos/test_rnac.py); the crash comes before the second checkpoint, with CSV rows written
# after the first. A new algorithm needs an entry here (the test below says so).
SAC_FAMILY_BUDGET = {
    "seeds": (0, 1),
    "total_steps": 400,
    "start_steps": 100,
    "update_after": 100,
    "checkpoint_every": 200,
    "eval_every": 200,
    "log_every": 100,
}
BUDGETS = {
    "sac": SAC_FAMILY_BUDGET,
    "sac-parseval": SAC_FAMILY_BUDGET,
    # truncations at gradient steps 150 and 300, one on each side of the crash
    "adarl": {**SAC_FAMILY_BUDGET, "truncate_every": 150, "warmup_steps": 50},
    "adarl-control": {**SAC_FAMILY_BUDGET, "truncate_every": 150, "warmup_steps": 50},
    "sac-fixed-rank": {**SAC_FAMILY_BUDGET, "rank": 7},
    "sac-sparse": {**SAC_FAMILY_BUDGET, "sparse_width": 256},  # narrower than 1024: faster
    # the first checkpoint (640) falls inside a rollout (256 steps)
    "rnac": {
        "seeds": (0, 1),
        "total_steps": 1024,
        "checkpoint_every": 640,
        "eval_every": 512,
        "log_every": 256,
    },
}


class Crash(Exception):
    pass


def test_every_registered_algorithm_has_a_budget():
    assert set(BUDGETS) == set(registry.ALGOS), "add the new algorithm's tiny budget to BUDGETS"


def _csv(run, name):
    rows = read_csv(run / name)
    for row in rows:
        row.pop("steps_per_s", None)  # wall-clock
    return rows


def _final(run):
    return sorted((run / CHECKPOINT_DIR).iterdir())[-1]


def _config(algo):
    return registry.resolve_config(algo, "smoke", {"task": "hopper", **BUDGETS[algo]})


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    """The uninterrupted run of an algorithm, trained once per module (and xdist worker)."""
    runs = {}

    def get(algo):
        if algo not in runs:
            runs[algo] = trainer(algo)(
                _config(algo), tmp_path_factory.mktemp(f"full-{algo}"), progress=False
            )
        return runs[algo]

    return get


@pytest.mark.parametrize("algo", registry.ALGOS)
def test_killed_and_resumed_run_equals_an_uninterrupted_one(algo, full_run, tmp_path, monkeypatch):
    config = _config(algo)
    train = trainer(algo)

    saved = []
    original = checkpoints.save_checkpoint

    def save_then_crash(*args, **kwargs):
        if kwargs.get("folder", CHECKPOINT_DIR) != CHECKPOINT_DIR:
            return original(*args, **kwargs)  # a pre-truncation checkpoint (never resumed from)
        if saved:  # the second checkpoint: die before writing it
            raise Crash
        saved.append(original(*args, **kwargs))
        return saved[-1]

    monkeypatch.setattr(checkpoints, "save_checkpoint", save_then_crash)
    with pytest.raises(Crash):
        train(config, tmp_path / "killed", progress=False)
    monkeypatch.setattr(checkpoints, "save_checkpoint", original)
    killed = tmp_path / "killed"
    assert not (killed / "DONE").exists() and len(saved) == 1
    steps_after = [int(r["step"]) for r in read_csv(killed / "train.csv")]
    first = json.loads((saved[0] / "meta.json").read_text())["step"]
    assert max(steps_after) > first  # rows past the checkpoint, which the resume must cut
    algo_back, config_back = folder.config_from_run(killed)
    assert (algo_back, config_back) == (algo, config)
    monkeypatch.setattr(npz, "MMAP_FROM", 1)  # every array of the checkpoint memory-mapped
    train(config_back, killed, resume=True, progress=False)

    assert_same_run(full_run(algo), killed, algo)


# The SIGTERM comes at the end of the first step at or past this one: between two checkpoints,
# at a step no trigger checkpoints (RNAC's inside its second rollout).
STOP_AFTER = {"rnac": 700}


@pytest.mark.parametrize("algo", registry.ALGOS)
def test_a_run_stopped_by_sigterm_resumes_exactly_from_where_it_stopped(
    algo, full_run, tmp_path, monkeypatch
):
    config = _config(algo)
    sent = []
    end_of_step = loop.Loop.end_of_step

    def end_of_step_then_sigterm(self, *args, **kwargs):
        end_of_step(self, *args, **kwargs)
        if self.step >= STOP_AFTER.get(algo, 250) and not sent:
            # the run's handler, not the default that would end this test's process
            assert isinstance(
                getattr(signal.getsignal(signal.SIGTERM), "__self__", None), loop.StopSignals
            )
            sent.append(self.step)
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(loop.Loop, "end_of_step", end_of_step_then_sigterm)
    before = signal.getsignal(signal.SIGTERM)
    stopped = tmp_path / "stopped"
    with pytest.raises(Stopped) as info:
        trainer(algo)(config, stopped, progress=False)
    monkeypatch.undo()
    assert signal.getsignal(signal.SIGTERM) is before  # the handlers are put back
    assert (info.value.step, info.value.exit_code) == (sent[0], 128 + signal.SIGTERM)
    assert not (stopped / "DONE").exists()
    steps = [int(p.name.split("_")[1]) for p in (stopped / CHECKPOINT_DIR).glob("step_*")]
    assert max(steps) == sent[0] and sent[0] % config.checkpoint_every != 0
    trainer(algo)(config, stopped, resume=True, progress=False)

    assert_same_run(full_run(algo), stopped, algo)


def assert_same_run(full, other, algo):
    """`other` (interrupted and resumed) wrote what `full` (uninterrupted) did: DONE, every CSV
    row (wall-clock columns aside), every spectrum, and the final checkpoint's arrays, policy
    files and meta."""
    assert (other / "DONE").read_text() == (full / "DONE").read_text()
    names = sorted(p.name for p in full.glob("*.csv"))
    assert names == sorted(p.name for p in other.glob("*.csv"))
    for name in names:
        assert _csv(other, name) == _csv(full, name), name
    spectra = sorted(p.name for p in full.glob("spectra/*.npz"))
    assert spectra == sorted(p.name for p in other.glob("spectra/*.npz"))
    if algo == "adarl":
        assert spectra, "the adarl budget should truncate"
    for name in spectra:
        with np.load(full / "spectra" / name) as a, np.load(other / "spectra" / name) as b:
            assert a.files == b.files
            for key in a.files:
                np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name} {key}")
    a_dir, b_dir = _final(full), _final(other)
    assert a_dir.name == b_dir.name
    with np.load(a_dir / "arrays.npz") as a, np.load(b_dir / "arrays.npz") as b:
        assert a.files == b.files
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    files = sorted(p.name for p in a_dir.iterdir() if p.name not in ("arrays.npz", "meta.json"))
    assert files == sorted(
        p.name for p in b_dir.iterdir() if p.name not in ("arrays.npz", "meta.json")
    )
    for name in files:
        assert (a_dir / name).read_bytes() == (b_dir / name).read_bytes(), name
    meta_a, meta_b = (json.loads((d / "meta.json").read_text()) for d in (a_dir, b_dir))
    # (the CSV offsets differ by the width of the steps_per_s column: wall-clock)
    for key in ("rng_states", "env_states", "config", "seeds", "step"):
        assert meta_a[key] == meta_b[key], key


@pytest.mark.parametrize("algo", registry.ALGOS)
def test_a_seed_trained_alone_writes_what_it_writes_beside_another(algo, full_run, tmp_path):
    """Seed 1 alone and seed 1 of the two-seed run: the same CSV rows, spectra, policy files and
    final checkpoint arrays (its slice of each array stacked over seeds)."""
    import dataclasses

    config = _config(algo)
    assert config.seeds == (0, 1)
    beside, alone = full_run(algo), tmp_path / "alone"
    trainer(algo)(dataclasses.replace(config, seeds=(1,)), alone, progress=False)
    for name in sorted(p.name for p in beside.glob("*.csv")):
        mine = [r for r in _csv(beside, name) if r.get("seed") == "1"]
        assert _csv(alone, name) == mine, name
    spectra = sorted(alone.glob("spectra/*.npz"))
    assert bool(spectra) == algo.startswith("adarl")  # their budgets truncate
    for path in spectra:
        with np.load(path) as a, np.load(beside / "spectra" / path.name) as b:
            for key in a.files:
                np.testing.assert_array_equal(a[key][0], b[key][1], err_msg=f"{path.name} {key}")
    a_dir, b_dir = _final(alone), _final(beside)
    assert a_dir.name == b_dir.name
    policies = sorted(a_dir.glob("*policy_seed_1.npz"))
    assert policies and not list(a_dir.glob("*policy_seed_0.npz"))
    for path in policies:
        assert path.read_bytes() == (b_dir / path.name).read_bytes(), path.name
    with np.load(a_dir / "arrays.npz") as a, np.load(b_dir / "arrays.npz") as b:
        assert_seed_slice_equal(dict(a), dict(b), index=1)
