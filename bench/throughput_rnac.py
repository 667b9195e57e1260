"""RNAC throughput on Hopper (paper dynamics): training steps/s for the `ds` and `ipm` uncertainty
sets, and what double sampling costs.

    python bench/throughput_rnac.py                 # 1 seed, 20480 steps per setting
    python bench/throughput_rnac.py --steps 40960 --seeds 5

Each setting runs `adarl.algos.rnac.train` in a temporary folder with the default (paper/original)
hyperparameters, no evaluation and one checkpoint at the end; steps/s are taken from train.csv
after the first rollout (which includes compilation). Also measured in the same run: the simulator
alone (random actions through `adarl.envs.make`). Reported:

* steps/s per seed and in total, and the time of one update per seed;
* ds (δ = 1/3, as the original) and ds with δ = 1, which simulates the candidates at every step,
  as the original code does whatever δ is (ours simulates them only on the steps that take the
  worst case: the other steps just draw a random candidate's noise);
* the double-sampling cost factor: ipm steps/s ÷ ds steps/s, and simulator steps per env step.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from adarl.algos import rnac
from adarl.train.io import read_csv


class CountingShadow(rnac.ShadowSimulator):
    """The double-sampling simulator, counting the candidate transitions it simulates."""

    simulated = 0

    def candidates(self, actions):
        CountingShadow.simulated += len(actions)
        return super().candidates(actions)


def simulator_alone(task: str, steps: int) -> float:
    """Env steps/s with uniform random actions."""
    from adarl.envs import make

    env = make(task, dynamics="paper", seed=0)
    rng = np.random.default_rng(0)
    low, high = env.action_space.low, env.action_space.high
    env.reset()
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(rng.uniform(low, high).astype(np.float32))
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def train_throughput(task: str, steps: int, seeds: int, **overrides) -> dict:
    """Run the trainer; steps/s per seed after the first rollout, candidates per step."""
    config = rnac.RNACConfig(
        task=task,
        seeds=tuple(range(seeds)),
        total_steps=steps,
        eval_episodes=0,
        checkpoint_every=10**12,
        **overrides,
    )
    config.log_every = config.rollout_steps
    CountingShadow.simulated = 0
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        rnac.train(config, Path(tmp) / "run")
        wall = time.perf_counter() - start
        rows = [r for r in read_csv(Path(tmp) / "run" / "train.csv") if r["seed"] == "0"]
    sps = [float(r["steps_per_s"]) for r in rows[1:]]
    per_seed = len(sps) / sum(1.0 / s for s in sps)  # equal intervals: harmonic mean
    return {
        "per_seed": per_seed,
        "total": per_seed * seeds,
        "wall": wall,
        "candidates_per_step": CountingShadow.simulated / (steps * seeds),
    }


def update_seconds(seeds: int) -> float:
    """Wall time of one update (2048 × 10 epochs / 64) for `seeds` vmapped seeds."""
    config = rnac.RNACConfig(seeds=tuple(range(seeds)))
    state, keys = rnac.init_states(list(config.seeds), config, 11, 3)
    rng = np.random.default_rng(0)
    s, t = seeds, config.rollout_steps
    batch = {
        "obs": rng.standard_normal((s, t, 11)),
        "actions": rng.uniform(-1, 1, (s, t, 3)),
        "logp": rng.standard_normal((s, t)) - 3,
        "rewards": rng.standard_normal((s, t)),
        "next_obs": rng.standard_normal((s, t, 11)),
        "terminated": np.zeros((s, t)),
        "done": np.zeros((s, t)),
    }
    batch = {k: v.astype(np.float32) for k, v in batch.items()}
    update = rnac.make_update(config, -np.ones(3), np.ones(3))
    args = (np.float32(3e-4), np.float32(0.0))
    np.asarray(update(state, batch, keys, *args)[1])  # compile
    start = time.perf_counter()
    for _ in range(3):
        state, metrics, keys = update(state, batch, keys, *args)
        np.asarray(metrics)
    return (time.perf_counter() - start) / 3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="hopper")
    parser.add_argument("--steps", type=int, default=20480, help="env steps per seed per setting")
    parser.add_argument("--seeds", type=int, default=1)
    args = parser.parse_args()
    rnac.ShadowSimulator = CountingShadow

    sim = simulator_alone(args.task, 5000)
    print(f"simulator alone ({args.task}, random actions): {sim:.0f} steps/s")
    upd = update_seconds(args.seeds)
    print(
        f"one update ({args.seeds} seed(s) vmapped): {upd * 1e3:.0f} ms "
        f"= {upd / 2048 * 1e6:.0f} µs per env step"
    )
    results = {}
    for name, overrides in [
        ("ipm", {"uncertainty_set": "ipm"}),
        ("ds", {"uncertainty_set": "ds"}),
        ("ds δ=1", {"uncertainty_set": "ds", "delta": 1.0}),
    ]:
        r = results[name] = train_throughput(args.task, args.steps, args.seeds, **overrides)
        print(
            f"{name:7s} {r['per_seed']:6.0f} steps/s per seed, {r['total']:6.0f} in total "
            f"({args.seeds} seed(s)); {1 + r['candidates_per_step']:.2f} simulator steps per "
            f"env step; run {r['wall']:.0f} s"
        )
    for name in ("ds", "ds δ=1"):
        print(
            f"double-sampling cost factor ({name}): ipm/{name} = "
            f"{results['ipm']['per_seed'] / results[name]['per_seed']:.2f}× wall time"
        )


if __name__ == "__main__":
    main()
