"""Steps/s of `adarl.envs.make(task, "paper")` next to plain `gymnasium.make(<id>)`, same run.

Random actions (seeded), resets included: a reset after every termination or truncation, and
under `paper` every reset compiles a new model. Besides paper/plain it shows
  wrapper    default/plain   our env on Gymnasium's own model: the wrapper's cost alone
  physics    nominal/plain   the paper's centroid dynamics, compiled once: MuJoCo's own cost of
                             the changed physics (air drag on Ant and Humanoid, longer bodies)
  compiling  share of the `paper` runs' CPU time spent compiling and swapping in models
  ep.len     mean episode length under `paper`; compile ms: CPU time per compile + swap

Rates are steps per CPU-second of this process (`time.process_time`), so that other jobs on a
shared machine do not count; the envs alternate in rounds and each keeps its best round.
`--no-termination` builds every env with terminate_when_unhealthy=False, so episodes run to the
1000-step limit (the regime of a trained policy) and one compile serves 1000 steps.

    python bench/envs.py [--steps 3000] [--rounds 5] [--tasks hopper ...] [--no-termination]
"""

from __future__ import annotations

import argparse
import copy
import time

import gymnasium
import numpy as np
from gymnasium.envs.registration import load_env_creator

from adarl.envs import DynamicsEnv, get_task, list_tasks, make, parse_dynamics

#: plain: gymnasium.make(id); default: our wrapper on Gymnasium's model (its cost alone);
#: nominal: the paper's centroid compiled once (the physics of the paper's dynamics);
#: paper: a new model every episode (compile+swap time is in env.compile_seconds).
KINDS = {"plain": None, "default": "default", "nominal": "nominal", "paper": "paper"}


def run(env, steps: int, seed: int) -> tuple[float, int, float]:
    """(steps per CPU-second, episodes ended, CPU seconds compiling) for `steps` random-action
    steps with resets."""
    rng = np.random.default_rng(seed)
    space = env.action_space
    actions = rng.uniform(space.low, space.high, size=(steps, *space.shape)).astype(space.dtype)
    env.reset(seed=seed)
    ended = 0
    compiling = getattr(env, "compile_seconds", 0.0)
    start = time.process_time()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
            ended += 1
    elapsed = time.process_time() - start
    return steps / elapsed, ended, getattr(env, "compile_seconds", 0.0) - compiling


def build(task: str, dynamics: str | None, terminate: bool):
    """Plain Gymnasium env (dynamics=None) or ours, optionally without early termination."""
    spec = get_task(task)
    if terminate:
        return gymnasium.make(spec.gym_id) if dynamics is None else make(task, dynamics, seed=0)
    if dynamics is None:
        return gymnasium.make(spec.gym_id, terminate_when_unhealthy=False)
    gym_spec = gymnasium.spec(spec.gym_id)
    raw = load_env_creator(gym_spec.entry_point)(terminate_when_unhealthy=False)
    raw.spec = copy.copy(gym_spec)
    return DynamicsEnv(raw, spec, parse_dynamics(dynamics, task), seed=0)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000, help="steps per round")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--tasks", nargs="+", default=list_tasks(), choices=list_tasks())
    parser.add_argument("--no-termination", action="store_true")
    args = parser.parse_args(argv)
    terminate = not args.no_termination
    print(
        f"{'task':<9} {'plain/s':>8} {'paper/s':>8} {'paper/plain':>11} | {'wrapper':>7}"
        f" {'physics':>7} {'compiling':>9} | {'ep.len':>6} {'compile ms':>10}"
    )
    for task in args.tasks:
        envs = {name: build(task, dyn, terminate) for name, dyn in KINDS.items()}
        best = dict.fromkeys(envs, 0.0)
        ended, compiling, cpu = 0, 0.0, 0.0
        for r in range(args.rounds):
            for name, env in envs.items():
                rate, n, compile_cpu = run(env, args.steps, seed=r)
                best[name] = max(best[name], rate)
                if name == "paper":
                    ended += n
                    compiling += compile_cpu
                    cpu += args.steps / rate
        ours = envs["paper"]
        print(
            f"{task:<9} {best['plain']:>8.0f} {best['paper']:>8.0f} {best['paper'] / best['plain']:>11.3f} |"
            f" {best['default'] / best['plain']:>7.3f} {best['nominal'] / best['plain']:>7.3f}"
            f" {compiling / cpu:>8.1%} |"
            f" {args.rounds * args.steps / max(ended, 1):>6.1f}"
            f" {1e3 * ours.compile_seconds / max(ours.compiles, 1):>10.2f}"
        )
        for env in envs.values():
            env.close()


if __name__ == "__main__":
    main()
