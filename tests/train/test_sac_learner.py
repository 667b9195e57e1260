"""The SAC-family training loop: learning, several seeds in one process, exact resume, kills."""

import dataclasses
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
import pytest
from seed_slices import assert_seed_slice_equal

from adarl.algos import sac, sac_config, schedule
from adarl.algos.sac_config import SAC_FAMILY
from adarl.errors import UsageError
from adarl.runs import checkpoints
from adarl.runs.logs import read_csv
from adarl.train import sac_learner, trainers


def smoke_config(algo="adarl", **overrides):
    values = {**SAC_FAMILY[algo], **sac_config.PRESETS["smoke"], "algo": algo, "task": "hopper"}
    values.update(overrides)
    return sac_config.SACConfig(**values)


def csv_rows(run_dir, name, drop=("steps_per_s",)):
    return [
        {k: v for k, v in row.items() if k not in drop} for row in read_csv(Path(run_dir) / name)
    ]


def final_arrays(run_dir):
    arrays, _ = checkpoints.load_checkpoint(checkpoints.latest_checkpoint(run_dir))
    return arrays


def test_pendulum_learns_for_every_seed(tmp_path):
    """Learning check on a small task: every seed of a vmapped run beats −400 within 10k steps."""
    config = sac_config.SACConfig(
        algo="sac",
        task="gym:Pendulum-v1",
        dynamics="default",
        seeds=(0, 1),
        total_steps=10_000,
        start_steps=1_000,
        update_after=1_000,
        max_episode_steps=200,
        buffer_size=10_000,
        eval_every=10_000,
        eval_episodes=5,
        log_every=2_000,
        checkpoint_every=10_000,
    )
    trainers.train(config, tmp_path / "run", progress=False)
    rows = read_csv(tmp_path / "run" / "eval.csv")
    for seed in (0, 1):
        returns = [float(r["return"]) for r in rows if int(r["seed"]) == seed]
        assert len(returns) == 5
        assert np.mean(returns) > -400, (seed, returns)


class Crash(Exception):
    pass


@pytest.mark.parametrize(
    "rank_settings",
    [
        {"rank_rule": "cumulative"},  # one lane per seed, each narrowed to its own widths
        {"rank_rule": "energy", "retain_tolerance": 1e-3},
    ],
    ids=["cumulative", "energy-retain"],
)
def test_resume_after_a_crash_gives_the_same_results(tmp_path, monkeypatch, rank_settings):
    config = smoke_config(seeds=(0, 1), total_steps=2_000, checkpoint_every=1_000, **rank_settings)
    trainers.train(config, tmp_path / "full", progress=False)
    cuts = read_csv(tmp_path / "full" / "truncations.csv")
    assert len(cuts) == schedule.n_truncations(config) * 3 * 2  # truncations × layers × seeds
    decisions = {row["decision"] for row in cuts}
    assert decisions <= {"accepted", "retained", "unchanged"}
    if "retain_tolerance" in rank_settings:  # the retain clause refuses some of the cuts
        assert "retained" in decisions and "accepted" in decisions

    original = sac_learner.SACLearner.env_step

    def crashing(self, lane, t, action, episodes):
        original(self, lane, t, action, episodes)
        if t == 1_600:  # after the checkpoint at 1000 and a truncation
            raise Crash

    monkeypatch.setattr(sac_learner.SACLearner, "env_step", crashing)
    with pytest.raises(Crash):
        trainers.train(config, tmp_path / "crashed", progress=False)
    monkeypatch.setattr(sac_learner.SACLearner, "env_step", original)
    assert not (tmp_path / "crashed" / "DONE").exists()
    trainers.train(config, tmp_path / "crashed", resume=True, progress=False)

    for name in ("episodes.csv", "train.csv", "eval.csv", "truncations.csv"):
        assert csv_rows(tmp_path / "full", name) == csv_rows(tmp_path / "crashed", name), name
    full, resumed = final_arrays(tmp_path / "full"), final_arrays(tmp_path / "crashed")
    assert full.keys() == resumed.keys()
    for key in full:
        np.testing.assert_array_equal(full[key], resumed[key], err_msg=key)
    spectra = sorted(p.name for p in (tmp_path / "crashed" / "spectra").iterdir())
    assert spectra == sorted(p.name for p in (tmp_path / "full" / "spectra").iterdir())


def test_lanes_hold_their_seeds_on_separate_devices(tmp_path):
    learner = sac_learner.SACLearner(smoke_config(seeds=(4, 7, 9)))
    learner.fresh()
    assert [lane.index for lane in learner.lanes] == [0, 1, 2]  # one lane per seed
    assert [lane.state["buffer"]["obs"].shape[0] for lane in learner.lanes] == [1, 1, 1]
    devices = jax.local_devices()
    assert [lane.device for lane in learner.lanes] == [devices[k % len(devices)] for k in range(3)]
    for lane in learner.lanes:
        assert lane.state["actor"]["mu"]["w"].devices() == {lane.device}
    # the checkpoint stacks the lanes back in seed order, exactly as they were initialised
    arrays, _ = learner.checkpoint_state()
    expected = [
        sac.init_state(learner.spec, s, with_buffer=False)["actor"]["mu"]["w"] for s in (4, 7, 9)
    ]
    np.testing.assert_array_equal(arrays["state['actor']['mu']['w']"], np.stack(expected))


def seed_rows(run_dir, name, seed):
    return [r for r in csv_rows(run_dir, name) if r["seed"] == str(seed)]


def test_a_seed_gives_the_same_bits_alone_and_among_other_seeds(tmp_path):
    """A seed's CSVs, spectra, policy and checkpoint arrays are a function of (code, config,
    seed): seed 3 trained alone and trained beside 0, 5 and 6 (whose ranks, and so bottleneck
    widths, differ from its own after the truncations) are bit-identical."""
    config = smoke_config(total_steps=1_500, checkpoint_every=500, rank_rule="cumulative")
    trainers.train(
        dataclasses.replace(config, seeds=(0, 3, 5, 6)), tmp_path / "all", progress=False
    )
    trainers.train(dataclasses.replace(config, seeds=(3,)), tmp_path / "alone", progress=False)
    together, alone = tmp_path / "all", tmp_path / "alone"
    for name in ("episodes.csv", "train.csv", "eval.csv", "truncations.csv"):
        assert seed_rows(together, name, 3) == seed_rows(alone, name, 3), name
    cuts = read_csv(together / "truncations.csv")
    assert len({(r["layer"], r["new_rank"]) for r in cuts if r["step"] == cuts[-1]["step"]}) > 3
    for name in sorted(p.name for p in (alone / "spectra").iterdir()):
        with np.load(together / "spectra" / name) as a, np.load(alone / "spectra" / name) as b:
            for layer in ("actor_1", "q1_1", "q2_1"):
                np.testing.assert_array_equal(a[layer][1], b[layer][0], err_msg=layer)
    policy = "checkpoints/step_000000001500/policy_seed_3.npz"
    with np.load(together / policy) as a, np.load(alone / policy) as b:
        assert sorted(a.files) == sorted(b.files)
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert_seed_slice_equal(final_arrays(alone), final_arrays(together), index=1)


def test_new_run_refuses_a_non_empty_folder(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "notes.txt").write_text("keep me")
    with pytest.raises(UsageError, match="already exists"):
        trainers.train(smoke_config(), tmp_path / "run", progress=False)
    assert (tmp_path / "run" / "notes.txt").read_text() == "keep me"


def test_sigkill_then_resume_completes_without_duplicates(tmp_path):
    run_dir = tmp_path / "run"
    cmd = [
        sys.executable,
        "-m",
        "adarl.cli.main",
        "train",
        "--preset",
        "smoke",
        "--algo",
        "sac",
        "--total-steps",
        "3000",
        "--checkpoint-every",
        "500",
        "--out",
        str(run_dir),
        "--no-progress",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 240
    while time.time() < deadline and len(checkpoints.checkpoint_dirs(run_dir)) < 2:
        time.sleep(0.2)
        assert proc.poll() is None, "training ended before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (run_dir / "DONE").exists()
    resume = subprocess.run(
        [
            sys.executable,
            "-m",
            "adarl.cli.main",
            "train",
            "--resume",
            str(run_dir),
            "--no-progress",
        ],
        capture_output=True,
        text=True,
    )
    assert resume.returncode == 0, resume.stderr
    assert (run_dir / "DONE").read_text().strip() == "3000"
    episodes = read_csv(run_dir / "episodes.csv")
    keys = [(r["seed"], r["episode"]) for r in episodes]
    assert len(keys) == len(set(keys))
    steps = [int(r["step"]) for r in read_csv(run_dir / "train.csv")]
    assert steps == sorted(set(steps))


def test_resume_rejects_bad_folders(tmp_path):
    from adarl.cli.main import main

    assert main(["train", "--resume", str(tmp_path / "missing")]) == 2
    (tmp_path / "half").mkdir()
    assert main(["train", "--resume", str(tmp_path / "half")]) == 2
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "config.yaml").write_text("algo: adarl\nformat_version: 0\n")
    assert main(["train", "--resume", str(tmp_path / "old")]) == 2


def test_checkpoint_holds_only_the_used_part_of_the_buffer(tmp_path):
    config = smoke_config(
        algo="sac", total_steps=1_000, checkpoint_every=1_000, buffer_size=100_000
    )
    trainers.train(config, tmp_path / "run", progress=False)
    arrays = final_arrays(tmp_path / "run")
    # the rows written (1000 steps, plus one row per episode end) and the provisional next row
    used = int(arrays["buffer/size"].max()) + 1
    assert 1_000 < used < 2_000
    for key in sac_learner.BUFFER_ROW_KEYS:
        assert arrays[f"buffer/{key}"].shape[1] == used, key
