"""RNAC throughput on Hopper (paper dynamics): training steps/s for the `ds` and `ipm` uncertainty
sets, and what double sampling costs.

    python bench/throughput_rnac.py                 # 1 seed, 20480 steps per setting
    python bench/throughput_rnac.py --steps 40960 --seeds 5

Each setting runs `adarl.train.trainers.train` in a temporary folder with the default (paper/original)
hyperparameters, one one-episode evaluation and one checkpoint at the end, after a one-rollout
run that compiles the update. Also measured in the same process: the simulator alone (random actions through
`adarl.envs.make`). Throughputs are given per wall-clock second and per CPU second of this process
(the latter is the steadier figure when other jobs share the machine). Reported:

* steps/s per seed and in total, and the time of one update;
* ds (δ = 1/3, as the original), which simulates the candidates only on the steps that take the
  worst case, and ds with `eager_candidates`, which simulates and values them at every step as
  the original code does (the same transitions: its run is identical, only slower);
* the double-sampling cost factor: ipm steps/s ÷ ds steps/s, and simulator steps per env step.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from adarl.algos import onpolicy, rnac, rnac_config
from adarl.runs.layout import EPISODES_CSV
from adarl.runs.logs import read_csv
from adarl.train import rnac_learner, trainers


class CountingShadow(rnac_learner.ShadowSimulator):
    """The double-sampling simulator, counting the candidate transitions it simulates."""

    simulated = 0

    def candidates(self, actions):
        CountingShadow.simulated += len(actions)
        return super().candidates(actions)


def simulator_alone(task: str, steps: int) -> tuple[float, float]:
    """Env steps per wall-clock second and per CPU second, uniform random actions."""
    from adarl.envs import make

    env = make(task, dynamics="paper", seed=0)
    rng = np.random.default_rng(0)
    low, high = env.action_space.low, env.action_space.high
    env.reset()
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(rng.uniform(low, high).astype(np.float32))
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - wall), steps / (time.process_time() - cpu)


def candidate_cost(task: str, steps: int, n: int = 2) -> tuple[float, float]:
    """Microseconds of one env step and of one set of `n` candidates (state copy, simulation,
    observation, normalisation and critic values), measured interleaved so both see the same
    machine load."""
    from adarl.envs import make

    env = make(task, dynamics="paper", seed=0)
    shadow = rnac_learner.ShadowSimulator(env)
    config = rnac_config.RNACConfig()
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    state, _ = rnac.init_states([0], config, obs_dim, act_dim)
    critic = onpolicy.host_params(state.actor, state.critic)[0][1]
    rng = np.random.default_rng(0)
    low, high = env.action_space.low, env.action_space.high
    env.reset()
    t_env = t_cand = 0.0
    for _ in range(steps):
        actions = rng.uniform(low, high, (n, low.size)).astype(np.float32)
        start = time.perf_counter()
        cand = shadow.candidates(actions)
        onpolicy.critic_value(critic, onpolicy.normalise_obs(cand, 0.0, 1.0, 10.0), np)
        middle = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(actions[0])
        t_cand += middle - start
        t_env += time.perf_counter() - middle
        if terminated or truncated:
            env.reset()
    return t_env / steps * 1e6, t_cand / steps * 1e6


def train_throughput(task: str, steps: int, seeds: int, **overrides) -> dict:
    """Run the trainer (after a one-rollout warm-up run that compiles the update): env steps per
    seed per wall-clock second and per CPU second of the whole run, candidates per step."""
    config = rnac_config.RNACConfig(
        task=task,
        seeds=tuple(range(seeds)),
        total_steps=steps,
        eval_every=10**12,  # RNAC refuses eval_episodes 0: one 1-episode evaluation, at the end
        eval_episodes=1,
        checkpoint_every=10**12,
        **overrides,
    )
    config = dataclasses.replace(config, log_every=config.rollout_steps)
    with tempfile.TemporaryDirectory() as tmp:
        warm = dataclasses.replace(config, total_steps=config.rollout_steps)
        trainers.train(warm, Path(tmp) / "warm-up", progress=False)
        CountingShadow.simulated = 0
        wall, cpu = time.perf_counter(), time.process_time()
        trainers.train(config, Path(tmp) / "run", progress=False)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        episodes = len(read_csv(Path(tmp) / "run" / EPISODES_CSV))
    return {
        "per_seed": steps / wall,
        "per_seed_cpu": steps / cpu,
        "total": steps * seeds / wall,
        "candidates_per_step": CountingShadow.simulated / (steps * seeds),
        "episode_length": steps * seeds / max(episodes, 1),
    }


def update_seconds(seeds: int) -> float:
    """Wall time of one update (2048 × 10 epochs / 64) for `seeds` vmapped seeds."""
    config = rnac_config.RNACConfig(seeds=tuple(range(seeds)))
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


def report(steps: int = 20480, task: str = "hopper", **overrides) -> None:
    """RNAC lines for bench/throughput.py: steps/s of `ipm` and `ds`, and the DS cost factor
    (`overrides`: config fields, e.g. a smaller rollout for a smoke test)."""
    rnac_learner.ShadowSimulator = CountingShadow
    rates = {}
    for name in ("ipm", "ds"):
        rates[name] = train_throughput(task, steps, 1, uncertainty_set=name, **overrides)[
            "per_seed"
        ]
        print(f"rnac   {name:3s} 1 seed: {rates[name]:8.1f} steps/s")
    print(f"       double sampling costs {rates['ipm'] / rates['ds']:.2f}x the time of ipm")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="hopper")
    parser.add_argument("--steps", type=int, default=20480, help="env steps per seed per setting")
    parser.add_argument("--seeds", type=int, default=1)
    args = parser.parse_args()
    rnac_learner.ShadowSimulator = CountingShadow
    print(f"load average before: {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")

    sim, sim_cpu = simulator_alone(args.task, 5000)
    print(
        f"simulator alone ({args.task}, random actions): {sim:.0f} steps/s "
        f"({sim_cpu:.0f} per CPU second)"
    )
    t_env, t_cand = candidate_cost(args.task, 5000)
    print(
        f"one env step {t_env:.0f} µs; one set of 2 candidates {t_cand:.0f} µs "
        f"(= {t_cand / t_env:.2f} env steps)"
    )
    upd = update_seconds(args.seeds)
    print(
        f"one update ({args.seeds} seed(s) vmapped): {upd * 1e3:.0f} ms "
        f"= {upd / 2048 * 1e6:.0f} µs per env step per seed"
    )
    results = {}
    settings = [
        ("ipm", {"uncertainty_set": "ipm"}),
        ("ds", {"uncertainty_set": "ds"}),
        ("ds eager", {"uncertainty_set": "ds", "eager_candidates": True}),
    ]
    for name, overrides in settings:
        r = results[name] = train_throughput(args.task, args.steps, args.seeds, **overrides)
        print(
            f"{name:8s} {r['per_seed']:5.0f} steps/s per seed ({r['per_seed_cpu']:.0f} per CPU "
            f"second), {r['total']:5.0f} in total ({args.seeds} seed(s)); "
            f"{1 + r['candidates_per_step']:.2f} simulator steps per env step; "
            f"mean episode length {r['episode_length']:.0f}"
        )
    for name in ("ds", "ds eager"):
        wall = results["ipm"]["per_seed"] / results[name]["per_seed"]
        cpu = results["ipm"]["per_seed_cpu"] / results[name]["per_seed_cpu"]
        print(
            f"double-sampling cost factor ({name}): ipm/{name} = {wall:.2f}× wall time, "
            f"{cpu:.2f}× CPU time"
        )
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
