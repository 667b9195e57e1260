"""The SAC-family training loop: learning, several seeds in one process, exact resume, kills."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
import pytest

from adarl.algos import SAC_FAMILY, sac
from adarl.errors import UsageError
from adarl.nets import rank
from adarl.train import io, sac_loop


def smoke_config(algo="adarl", **overrides):
    values = {**SAC_FAMILY[algo], **sac.PRESETS["smoke"], "algo": algo, "task": "hopper"}
    values.update(overrides)
    return sac.SACConfig(**values)


def csv_rows(run_dir, name, drop=("steps_per_s",)):
    return [
        {k: v for k, v in row.items() if k not in drop} for row in io.read_csv(Path(run_dir) / name)
    ]


def final_arrays(run_dir):
    arrays, _ = io.load_checkpoint(io.latest_checkpoint(run_dir))
    return arrays


def test_pendulum_learns_for_every_seed(tmp_path):
    """Learning check on a small task: every seed of a vmapped run beats −400 within 10k steps."""
    config = sac.SACConfig(
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
    sac_loop.train(config, tmp_path / "run", progress=False)
    rows = io.read_csv(tmp_path / "run" / "eval.csv")
    for seed in (0, 1):
        returns = [float(r["return"]) for r in rows if int(r["seed"]) == seed]
        assert len(returns) == 5
        assert np.mean(returns) > -400, (seed, returns)


class Crash(Exception):
    pass


@pytest.mark.parametrize(
    "rank_settings",
    [{"rank_rule": "cumulative"}, {"rank_rule": "energy", "retain_tolerance": 1e-3}],
    ids=["cumulative", "energy-retain"],
)
def test_resume_after_a_crash_gives_the_same_results(tmp_path, monkeypatch, rank_settings):
    # lanes of 2 seeds (vmapped) and 1 seed (on the second CPU device when there is one)
    config = smoke_config(
        seeds=(0, 1, 2), lanes=2, total_steps=2_000, checkpoint_every=1_000, **rank_settings
    )
    sac_loop.train(config, tmp_path / "full", progress=False)
    cuts = io.read_csv(tmp_path / "full" / "truncations.csv")
    assert len(cuts) == sac.n_truncations(config) * 3 * 3  # truncations × layers × seeds
    decisions = {row["decision"] for row in cuts}
    assert decisions <= {"accepted", "retained", "unchanged"}
    if "retain_tolerance" in rank_settings:  # the retain clause refuses some of the cuts
        assert "retained" in decisions and "accepted" in decisions

    original = sac_loop.Run.env_step

    def crashing(self, lane, t, actions):
        original(self, lane, t, actions)
        if t == 1_600:  # after the checkpoint at 1000 and a truncation
            raise Crash

    monkeypatch.setattr(sac_loop.Run, "env_step", crashing)
    with pytest.raises(Crash):
        sac_loop.train(config, tmp_path / "crashed", progress=False)
    monkeypatch.setattr(sac_loop.Run, "env_step", original)
    assert not (tmp_path / "crashed" / "DONE").exists()
    sac_loop.train(config, tmp_path / "crashed", resume=True, progress=False)

    for name in ("episodes.csv", "train.csv", "eval.csv", "truncations.csv"):
        assert csv_rows(tmp_path / "full", name) == csv_rows(tmp_path / "crashed", name), name
    full, resumed = final_arrays(tmp_path / "full"), final_arrays(tmp_path / "crashed")
    assert full.keys() == resumed.keys()
    for key in full:
        np.testing.assert_array_equal(full[key], resumed[key], err_msg=key)
    spectra = sorted(p.name for p in (tmp_path / "crashed" / "spectra").iterdir())
    assert spectra == sorted(p.name for p in (tmp_path / "full" / "spectra").iterdir())


def test_split_lanes():
    assert sac_loop.split_lanes(5, 4) == [range(0, 2), range(2, 3), range(3, 4), range(4, 5)]
    assert sac_loop.split_lanes(5, 2) == [range(0, 3), range(3, 5)]
    assert sac_loop.split_lanes(2, 4) == [range(0, 1), range(1, 2)]
    assert sac_loop.split_lanes(1, 4) == [range(0, 1)]
    assert sac_loop.split_lanes(8, 3) == [range(0, 3), range(3, 6), range(6, 8)]


def test_lanes_hold_their_seeds_on_separate_devices(tmp_path):
    run = sac_loop.Run(smoke_config(seeds=(4, 7, 9), lanes=2), tmp_path / "run", progress=False)
    run.fresh()
    assert [lane.seeds for lane in run.lanes] == [range(0, 2), range(2, 3)]
    assert [lane.state["buffer"]["obs"].shape[0] for lane in run.lanes] == [2, 1]
    devices = jax.local_devices()
    assert [lane.device for lane in run.lanes] == [devices[0], devices[1 % len(devices)]]
    for lane in run.lanes:
        assert lane.state["actor"]["mu"]["w"].devices() == {lane.device}
    # the checkpoint stacks the lanes back in seed order, exactly as they were initialised
    arrays = run.checkpoint_arrays()
    expected = [
        sac.init_state(run.spec, s, with_buffer=False)["actor"]["mu"]["w"] for s in (4, 7, 9)
    ]
    np.testing.assert_array_equal(arrays["state['actor']['mu']['w']"], np.stack(expected))


def test_several_seeds_match_training_each_alone(tmp_path):
    """Seeds vmapped together in a lane (0 and 3), and a seed in a lane of its own (5, on the
    second CPU device when there is one), follow the same trajectory as each seed alone."""
    config = smoke_config(seeds=(0, 3, 5), lanes=2, total_steps=1_000, checkpoint_every=1_000)
    sac_loop.train(config, tmp_path / "all", progress=False)
    for seed in (3, 5):
        sac_loop.train(
            smoke_config(seeds=(seed,), total_steps=1_000, checkpoint_every=1_000),
            tmp_path / f"alone{seed}",
            progress=False,
        )
        together = [r for r in csv_rows(tmp_path / "all", "episodes.csv") if r["seed"] == str(seed)]
        alone = csv_rows(tmp_path / f"alone{seed}", "episodes.csv")
        # same environment stream: random warm-up actions are identical, so are early episodes
        assert together[:5] == alone[:5]
        train_together = [
            r for r in csv_rows(tmp_path / "all", "train.csv") if r["seed"] == str(seed)
        ]
        train_alone = csv_rows(tmp_path / f"alone{seed}", "train.csv")
        assert len(train_together) == len(train_alone)
        for a, b in zip(train_together, train_alone):
            for key in ("loss_q", "loss_pi", "q_mean", "entropy"):
                assert float(a[key]) == pytest.approx(float(b[key]), rel=1e-3, abs=1e-4), key
        # the truncation after 500 updates: the same spectra up to float drift (vmapped and
        # alone, XLA may sum in another order), and the rank the rule picks from the seed's own
        # spectrum, unless that spectrum sits on the rule's threshold (β ± 0.1% choose otherwise)
        (name,) = [p.name for p in (tmp_path / "all" / "spectra").iterdir()]
        with (
            np.load(tmp_path / "all" / "spectra" / name) as all_,
            np.load(tmp_path / f"alone{seed}" / "spectra" / name) as alone_,
        ):
            row = list(all_["seeds"]).index(seed)
            for layer in ("actor_1", "q1_1", "q2_1"):
                spectrum = alone_[layer][0]
                np.testing.assert_allclose(all_[layer][row], spectrum, rtol=1e-3, atol=1e-5)
                rank_together = int(train_together[-1][f"rank_{layer}"])
                near = {
                    int(rank.select_rank(spectrum, beta, config.rank_rule))
                    for beta in (config.beta * (1 - 1e-3), config.beta, config.beta * (1 + 1e-3))
                }
                assert int(train_alone[-1][f"rank_{layer}"]) in near, layer
                assert rank_together in near, layer


def test_new_run_refuses_a_non_empty_folder(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "notes.txt").write_text("keep me")
    with pytest.raises(UsageError, match="already exists"):
        sac_loop.train(smoke_config(), tmp_path / "run", progress=False)
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
    while time.time() < deadline and len(io.checkpoint_dirs(run_dir)) < 2:
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
    episodes = io.read_csv(run_dir / "episodes.csv")
    keys = [(r["seed"], r["episode"]) for r in episodes]
    assert len(keys) == len(set(keys))
    steps = [int(r["step"]) for r in io.read_csv(run_dir / "train.csv")]
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
    sac_loop.train(config, tmp_path / "run", progress=False)
    arrays = final_arrays(tmp_path / "run")
    # the rows written (1000 steps, plus one row per episode end) and the provisional next row
    used = int(arrays["buffer/size"].max()) + 1
    assert 1_000 < used < 2_000
    for key in sac_loop.BUFFER_ROW_KEYS:
        assert arrays[f"buffer/{key}"].shape[1] == used, key
