"""Training throughput on Hopper with the paper's networks, against references measured in the
same run.

    python bench/throughput.py                 # adarl: 1 seed, 5 seeds; SB3 SAC if installed
    python bench/throughput.py --steps 3000 --algos sac adarl --no-sb3

Prints environment steps per second of training (environment steps, action selection, buffer
writes and one gradient update per step; periodic evaluation and checkpoints excluded), for one
seed and for five seeds in one process (summed over seeds; one lane per seed), the ratio to
Stable-Baselines3 SAC with the same networks and settings (when
`pip install -e .[bench]` has installed it), the cost of a rank truncation relative to training,
the masked-vs-compact bottleneck update cost, and RNAC (`ds` and `ipm`) when its benchmark module
is present. Compilation is excluded (a warm-up runs first).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

from adarl.runtime import configure_xla  # noqa: E402

configure_xla()

import jax  # noqa: E402
import numpy as np  # noqa: E402

from adarl.algos import sac, sac_config  # noqa: E402
from adarl.algos.sac_config import SAC_FAMILY  # noqa: E402
from adarl.train import loop, sac_learner  # noqa: E402


def paper_config(algo: str, seeds: int, **overrides) -> sac_config.SACConfig:
    values = {
        **SAC_FAMILY[algo],
        "algo": algo,
        "task": "hopper",
        "dynamics": "paper",
        "seeds": tuple(range(seeds)),
        "start_steps": 0,
        "update_after": 50,
        "buffer_size": 100_000,
        "total_steps": 10**9,
    }
    values.update(overrides)
    return sac_config.SACConfig(**values).validate()


def training_rate(
    config: sac_config.SACConfig, steps: int, warmup: int
) -> tuple[float, sac_learner.SACLearner]:
    """Environment steps per second (per process) of the training loop, after `warmup` steps."""
    learner = sac_learner.SACLearner(config)
    run_dir = Path(tempfile.mkdtemp(prefix="adarl-bench-"))  # its logs only; removed below
    training = loop.Loop(learner, run_dir, progress=False)
    learner.fresh()
    training.open_logs(None)

    def advance(k):
        target = training.step + k
        while training.step < target:
            training.step = learner.advance(training.step).step
            for lane in learner.lanes:
                lane.infos.clear()

    def block_until_ready():
        for lane in learner.lanes:
            jax.block_until_ready(lane.state)

    advance(warmup)
    block_until_ready()
    start, first = time.perf_counter(), training.step
    advance(steps)
    block_until_ready()
    rate = (training.step - first) / (time.perf_counter() - start)
    training.close()
    shutil.rmtree(run_dir, ignore_errors=True)
    return rate, learner


def truncation_cost(learner: sac_learner.SACLearner, rate: float, **config) -> tuple[float, float]:
    """Seconds per truncation (one lane), and its share of the training time between two;
    `config` changes fields of the run's config for this measurement (e.g. the retain test)."""
    spec = dataclasses.replace(learner.spec, config=dataclasses.replace(learner.config, **config))
    truncate = sac_learner.compile_functions(spec).truncate
    times = []
    for _ in range(6):  # the first call compiles; the best of the other five counts
        state = jax.tree_util.tree_map(lambda a: a.copy(), learner.lanes[0].state)
        jax.block_until_ready(state)
        start = time.perf_counter()
        jax.block_until_ready(truncate(state))
        times.append(time.perf_counter() - start)
    seconds = min(times[1:])
    interval = learner.config.truncate_every / rate  # seconds of training between truncations
    return seconds, seconds / interval


def sb3_rate(steps: int, warmup: int) -> float | None:
    try:
        import torch
        from stable_baselines3 import SAC
    except ImportError:
        return None
    import gymnasium

    torch.set_num_threads(1)
    env = gymnasium.make("Hopper-v5")
    model = SAC(
        "MlpPolicy",
        env,
        learning_rate=3e-3,
        buffer_size=100_000,
        batch_size=256,
        tau=0.005,
        gamma=0.99,
        train_freq=1,
        gradient_steps=1,
        learning_starts=50,
        ent_coef=0.2,
        policy_kwargs={"net_arch": [64, 64]},
        device="cpu",
        verbose=0,
        seed=0,
    )
    model.learn(total_timesteps=warmup)
    start = time.perf_counter()
    model.learn(total_timesteps=steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - start)


def update_cost(width: int, rank: int, n: int = 200) -> float:
    """Milliseconds per jitted gradient step (one seed) with a bottleneck of `width` columns,
    `rank` of them active: masked-static (width 64) vs compact (width = rank) layouts."""
    config = paper_config("sac-fixed-rank", 1, rank=rank, update_every=n)
    spec = sac.make_spec(config, 11, 3, [-1.0] * 3, [1.0] * 3)
    if width != 64:
        from adarl.nets import mlp

        spec = sac.Spec(
            actor=mlp.make_layout([11, 64, 64], (1,), width),
            critic=mlp.make_layout([14, 64, 64, 1], (1,), width),
            obs_dim=11,
            act_dim=3,
            act_low=spec.act_low,
            act_high=spec.act_high,
            config=config,
        )
    state = jax.device_put(sac.init_state(spec, 0))
    from adarl.algos import replay

    rows = {
        "obs": np.random.default_rng(0).normal(size=(n + 1, 11)).astype(np.float32),
        "act": np.zeros((n + 1, 3), np.float32),
        "rew": np.zeros(n + 1, np.float32),
        "term": np.zeros(n + 1, np.uint8),
        "valid": np.ones(n + 1, np.uint8),
    }
    state = dict(state, buffer=replay.append_rows(state["buffer"], rows, n + 1))
    step = jax.jit(lambda s: jax.lax.scan(lambda c, _: sac.update_step(spec, c), s, None, length=n))
    jax.block_until_ready(step(state))
    start = time.perf_counter()
    jax.block_until_ready(step(state))
    return (time.perf_counter() - start) / n * 1000


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000, help="timed steps per measurement")
    parser.add_argument("--warmup", type=int, default=300, help="untimed steps (compilation)")
    parser.add_argument("--algos", nargs="+", default=["adarl", "sac"])
    parser.add_argument("--no-sb3", action="store_true")
    parser.add_argument("--no-rnac", action="store_true")
    args = parser.parse_args()
    print(
        f"Hopper-v5, paper dynamics, (64, 64) ReLU, batch 256, 1 update/step; {os.cpu_count()} "
        f"cores; jax {jax.__version__}; {args.steps} timed steps\n"
    )
    reference = None if args.no_sb3 else sb3_rate(args.steps, args.warmup)
    if reference is None:
        print("Stable-Baselines3 SAC: not installed (pip install -e .[bench]); no ratio")
    else:
        print(f"Stable-Baselines3 SAC, 1 seed: {reference:8.1f} steps/s")
    for algo in args.algos:
        one, learner = training_rate(paper_config(algo, 1), args.steps, args.warmup)
        five, _ = training_rate(paper_config(algo, 5), args.steps // 3, args.warmup)
        line = (
            f"{algo:6s} 1 seed: {one:8.1f} steps/s   5 seeds: {five:7.1f} steps/s x 5 = "
            f"{5 * five:8.1f} seed-steps/s ({5 * five / one:.2f}x one seed)"
        )
        if reference:
            line += f"   1 seed vs SB3: {one / reference:.2f}x"
        print(line)
        if algo == "adarl":
            for label, config in [
                ("truncation, retain test off", {"retain_tolerance": None}),
                ("truncation, retain test on ", {"retain_tolerance": 0.01}),
                ("truncation, 1 test sample  ", {"retain_tolerance": 0.01, "retain_samples": 1}),
            ]:
                seconds, share = truncation_cost(learner, one, **config)
                print(
                    f"       {label}: {seconds * 1000:.1f} ms = {100 * share:.4f}% of the "
                    f"training time between truncations (d_t = {learner.config.truncate_every})"
                )
    masked, compact = update_cost(64, 7), update_cost(7, 7)
    print(
        f"\nupdate at rank 7: masked 64-wide {masked:.3f} ms, compact 7-wide {compact:.3f} ms "
        f"per step (one seed); a rank change would also cost a recompile of several seconds"
    )
    if not args.no_rnac:
        try:
            sys.path.insert(0, os.path.dirname(__file__))
            import throughput_rnac
        except ImportError:
            print("RNAC: bench/throughput_rnac.py not found")
        else:
            throughput_rnac.report(steps=max(args.steps, 4096))
    return 0


if __name__ == "__main__":
    sys.exit(main())
