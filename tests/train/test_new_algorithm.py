"""Adding an algorithm (docs/algorithms.md, "Adding an algorithm"), shown with the smallest
on-policy one: its config, its maths, its learner and its registry entry (with its line in the
trainer table) are all in this file, registered for these tests only. It trains through the one
loop from `adarl train`, its rollouts' rewards add up to the episodes the loop logged, and it
resumes exactly after a crash.

The algorithm, `tiny`, is PPO without the learning: it acts with the Gaussian actor it was
initialised with, collects rollouts into the shared on-policy `Host` (normalised observations),
and its "update" computes GAE with a zero critic and reports the rollout's reward sum and mean
advantage."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import onpolicy, registry
from adarl.algos.config import RunConfig
from adarl.cli.main import main
from adarl.errors import UsageError, check_choice
from adarl.runs import checkpoints, codec
from adarl.runs.logs import read_csv
from adarl.train import trainers
from adarl.train.guards import nonfinite_seeds
from adarl.train.learner import Advance, Episode, Truncation, due


# ============================================================================ 1. the config
@dataclass(frozen=True)
class TinyConfig(RunConfig):
    """A tiny run: `RunConfig`'s fields plus its rollout and normaliser settings."""

    algo: str = "tiny"  # the algorithm (adarl train --algo)
    rollout_steps: int = 50  # environment steps per seed per update
    hidden: tuple[int, ...] = (8,)  # hidden layer widths (tanh) of the actor
    gamma: float = 0.99  # discount factor
    gae_lambda: float = 0.95  # GAE's λ
    obs_norm: bool = True  # normalise observations by a running mean and variance
    obs_clip: float = 10.0  # normalised observations are clipped to ±obs_clip
    reward_scaling: bool = False  # divide rewards by the running std of the discounted return

    def validate(self) -> TinyConfig:
        super().validate()
        check_choice("algo", self.algo, ("tiny",))
        if self.rollout_steps < 1:
            raise UsageError(f"rollout-steps must be ≥ 1, got {self.rollout_steps}")
        return self


PRESETS = {
    "smoke": {
        "total_steps": 300,
        "max_episode_steps": 40,
        "log_every": 50,
        "eval_every": 150,
        "eval_episodes": 1,
        "checkpoint_every": 100,
    }
}


# ============================================================================ 2. the maths
def rollout_summary(rewards, terminated, done, gamma: float, lam: float):
    """One seed's [Σ r_t, mean A_t] over a rollout, A from GAE with V = 0."""
    zeros = jnp.zeros_like(rewards)
    adv, _ = onpolicy.gae(rewards, zeros, zeros, terminated, done, gamma, lam)
    return jnp.stack([rewards.sum(), adv.mean()])


UPDATE = jax.jit(jax.vmap(rollout_summary, in_axes=(0, 0, 0, None, None)))
METRICS = ["rollout_reward", "mean_advantage"]


# ============================================================================ 3. the learner
class TinyLearner:
    algo = "tiny"
    train_columns = ["step", "seed", "steps_per_s", *METRICS]
    extra_logs: dict = {}

    def __init__(self, config: TinyConfig):
        from adarl.envs import make

        self.config, self.seeds = config, [int(s) for s in config.seeds]
        self.env_options = config.env_options()
        self.envs = [make(config.task, config.dynamics, s, **self.env_options) for s in self.seeds]
        space = self.envs[0].action_space
        self.low, self.high = space.low.astype(np.float32), space.high.astype(np.float32)
        obs_dim, act_dim = self.envs[0].observation_space.shape[0], self.low.size
        self.rngs = [np.random.default_rng([s, 7]) for s in self.seeds]
        self.actors = [
            onpolicy.init_actor(np.random.default_rng(s), obs_dim, act_dim, config.hidden, -0.5)
            for s in self.seeds
        ]
        n = len(self.seeds)
        self.host = onpolicy.Host.zeros(n, obs_dim, act_dim, config.rollout_steps, len(METRICS))

    def fresh(self) -> None:
        for i, (env, s) in enumerate(zip(self.envs, self.seeds)):
            obs, _ = env.reset(seed=s)
            self.host.obs_norm[i] = self.host.observe(i, obs, self.config)

    def restore(self, arrays: dict, meta: dict) -> None:
        self.host.load(arrays)
        self.rngs = checkpoints.restore_rngs(meta, self.seeds)
        for env, s, enc in zip(self.envs, self.seeds, meta["env_states"]):
            env.reset(seed=s)
            env.set_state(codec.decode_env_state(enc, arrays))

    def checkpoint_state(self) -> tuple[dict, dict]:
        arrays = self.host.arrays()
        return arrays, checkpoints.host_meta(self.rngs, self.envs, arrays)

    def param_names(self) -> list[str]:
        return list(self.envs[0].dynamics_params or {})

    def close(self) -> None:
        for env in self.envs:
            env.close()

    def advance(self, step: int) -> Advance:
        config, host = self.config, self.host
        k, step, episodes = step % config.rollout_steps, step + 1, []
        for i, (env, rng, actor) in enumerate(zip(self.envs, self.rngs, self.actors)):
            action, logp = onpolicy.sample_action(actor, host.obs_norm[i], rng, self.low, self.high)
            obs, reward, terminated, truncated, info = env.step(action)
            host.record(i, k, action, logp, obs, reward, terminated, truncated, config)
            if terminated or truncated:
                ret, length = float(host.ep_return[i]), int(host.ep_length[i])
                episodes.append(Episode(i, step, info, ret, length))
                host.end_episode(i)
                obs, _ = env.reset()
                host.obs_norm[i] = host.observe(i, obs, config)
        if step % config.rollout_steps == 0:
            batch = host.batch()
            host.metrics = np.asarray(
                UPDATE(
                    batch["rewards"],
                    batch["terminated"],
                    batch["done"],
                    config.gamma,
                    config.gae_lambda,
                )
            )
        return Advance(step, episodes, due(config, step))

    def parameters_finite(self) -> bool:
        return True

    def truncate(self, step: int) -> Truncation:
        raise NotImplementedError("tiny never truncates")

    def train_rows(self, step: int, steps_per_s: float) -> list[dict]:
        return [
            {"step": step, "seed": s, "steps_per_s": steps_per_s}
            | dict(zip(METRICS, self.host.metrics[i].tolist()))
            for i, s in enumerate(self.seeds)
        ]

    def policies(self) -> list[dict]:
        return [
            self.host.policy(i, actor, self.config, self.low, self.high)
            for i, actor in enumerate(self.actors)
        ]

    def nonfinite(self, step: int) -> dict[str, list[int]]:
        found = {"episode return": nonfinite_seeds(self.seeds, self.host.ep_return)}
        return {quantity: seeds for quantity, seeds in found.items() if seeds}


# ============================================================================ 4. its entries
@pytest.fixture
def tiny(monkeypatch):
    """The registry entry and the trainer table's line, for this test only."""
    entry = registry.Algorithm(
        name="tiny",
        config_class=TinyConfig,
        defaults={},
        task_defaults={},
        presets=PRESETS,
        default_preset="smoke",
    )
    monkeypatch.setitem(registry.ALGORITHMS, "tiny", entry)
    monkeypatch.setattr(registry, "ALGOS", (*registry.ALGOS, "tiny"))
    monkeypatch.setitem(trainers.LEARNERS, TinyConfig, TinyLearner)


class Crash(Exception):
    pass


def csv_rows(run_dir: Path, name: str) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "steps_per_s"} for r in read_csv(run_dir / name)]


def test_a_new_algorithm_trains_through_the_one_loop(tiny, tmp_path, capsys):
    run = tmp_path / "run"
    argv = ["train", "--algo", "tiny", "--seeds", "0,1", "--out", str(run), "--no-progress"]
    assert main([*argv, "--no-report"]) == 0, capsys.readouterr().err
    assert "--rollout-steps INT environment steps per seed per update; default: 50" in " ".join(
        _help(capsys).split()
    )

    rows = read_csv(run / "train.csv")
    assert [(int(r["step"]), int(r["seed"])) for r in rows] == [
        (step, seed) for step in range(50, 301, 50) for seed in (0, 1)
    ]
    episodes = read_csv(run / "episodes.csv")
    final = checkpoints.load_checkpoint(checkpoints.latest_checkpoint(run))[0]
    for i, seed in enumerate((0, 1)):
        # every reward of every rollout is in a logged episode or in the one still running
        collected = sum(float(r["rollout_reward"]) for r in rows if int(r["seed"]) == seed)
        logged = sum(float(e["return"]) for e in episodes if int(e["seed"]) == seed)
        assert len([e for e in episodes if int(e["seed"]) == seed]) >= 300 // 40
        assert collected == pytest.approx(logged + final["host/ep_return"][i], rel=1e-5)
    evaluations = read_csv(run / "eval.csv")
    assert sorted({(int(r["step"]), int(r["seed"])) for r in evaluations}) == [
        (150, 0), (150, 1), (300, 0), (300, 1)
    ]  # fmt: skip
    assert (run / "DONE").exists()
    assert main(["export", str(run), "--seed", "1", "--out", str(tmp_path / "p.npz")]) == 0


def _help(capsys) -> str:
    with pytest.raises(SystemExit):
        main(["train", "--algo", "tiny", "--help"])
    return capsys.readouterr().out


def test_a_new_algorithm_resumes_exactly(tiny, tmp_path, monkeypatch):
    config = registry.resolve_config("tiny", "smoke", {"seeds": "2,5"})
    trainers.train(config, tmp_path / "full", progress=False)
    original = TinyLearner.advance

    def crashing(self, step):
        if step == 170:  # after the checkpoint at 100, inside a rollout
            raise Crash
        return original(self, step)

    monkeypatch.setattr(TinyLearner, "advance", crashing)
    with pytest.raises(Crash):
        trainers.train(config, tmp_path / "crashed", progress=False)
    monkeypatch.setattr(TinyLearner, "advance", original)
    trainers.train(config, tmp_path / "crashed", resume=True, progress=False)
    for name in ("episodes.csv", "train.csv", "eval.csv"):
        assert csv_rows(tmp_path / "full", name) == csv_rows(tmp_path / "crashed", name), name
    full, resumed = (
        checkpoints.load_checkpoint(checkpoints.latest_checkpoint(tmp_path / d))[0]
        for d in ("full", "crashed")
    )
    assert full.keys() == resumed.keys()
    for key in full:
        np.testing.assert_array_equal(full[key], resumed[key], err_msg=key)
