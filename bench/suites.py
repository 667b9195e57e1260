"""How long a robustness suite's grid takes per policy (`adarl evaluate --suite`), on this machine.

Two measurements, wall clock, with a policy of the AdaRL actor's size (two 256-wide layers):

  grid      the suite's real pipeline (`suites.plan_suite` + `parallel.run_units`, a spawn pool
            of --workers processes) over the whole grid at --episodes per point. The policy is
            random, so Hopper episodes end after a few steps: this is the cost of the grid's
            fixed part (a process pool, one env built and one model compiled per point).
  stepping  env steps per second of --workers processes stepping the suite's worst-case point
            with early termination off (Gymnasium's terminate_when_unhealthy=False), i.e. the
            regime of a trained policy that keeps going for all 1000 steps.

It then estimates the grid for a policy whose episodes all last 1000 steps, at the suite's own
episodes per point and at one: fixed part + points x episodes x 1000 / stepping rate.

    python bench/suites.py [--suite m2td3-3d] [--task hopper] [--workers 2] [--episodes 1]
"""

from __future__ import annotations

import argparse
import copy
import json
import multiprocessing
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

HIDDEN = 256
# the synthetic run folder is a test fixture (tests/synthetic_runs.py), imported by path
TESTS = Path(__file__).resolve().parent.parent / "tests"


def step_rate(task: str, dynamics: str, policy_path: str, steps: int) -> int:
    """Step one no-termination env `steps` times under `policy_path`; returns `steps`."""
    import gymnasium
    from gymnasium.envs.registration import load_env_creator

    from adarl.envs import DynamicsEnv, get_task, parse_dynamics
    from adarl.policy import load

    spec = get_task(task)
    gym_spec = gymnasium.spec(spec.gym_id)
    raw = load_env_creator(gym_spec.entry_point)(terminate_when_unhealthy=False)
    raw.spec = copy.copy(gym_spec)
    env = DynamicsEnv(raw, spec, parse_dynamics(dynamics, task), seed=0)
    policy = load(policy_path)
    obs, _ = env.reset(seed=0)
    for k in range(steps):
        obs, _, terminated, truncated, _ = env.step(policy(obs))
        if terminated or truncated:
            obs, _ = env.reset(seed=k)
    return steps


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", default="m2td3-3d")
    parser.add_argument("--task", default="hopper")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--episodes", type=int, default=1, help="episodes per point (grid part)")
    parser.add_argument("--steps", type=int, default=20_000, help="steps per worker (stepping)")
    args = parser.parse_args(argv)

    sys.path.insert(0, str(TESTS))
    from synthetic_runs import policy_arrays, write_run

    from adarl.evaluation import suites
    from adarl.evaluation.parallel import run_units
    from adarl.policy import save
    from adarl.results.runs import find_runs
    from adarl.runs.checkpoints import file_sha256, policy_files, select_checkpoint

    suite = suites.get_suite(args.suite, args.task)
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = write_run(tmp, "run", task=args.task, seeds=(0,))
        (run,) = find_runs([run_dir])
        policy = str(policy_files(select_checkpoint(run.path))[0])
        obs_dim, act_dim = _dims(args.task)
        save(policy, policy_arrays(obs_dim, act_dim, seed=0, hidden=HIDDEN))
        meta_path = Path(policy).parent / "meta.json"  # the checkpoint's checksum of the new file
        meta = json.loads(meta_path.read_text())
        meta["files_sha256"][Path(policy).name] = file_sha256(policy)
        meta_path.write_text(json.dumps(meta))

        units = suites.plan_suite([run], args.suite, args.episodes)
        start = time.perf_counter()
        results = run_units(units, args.workers, progress=False)
        grid_s = time.perf_counter() - start
        steps = sum(row["length"] for rows in results for row in rows)

        worst = min((r for rows in results for r in rows), key=lambda r: r["return"])
        dynamics = units[[i for i, rows in enumerate(results) if worst in rows][0]].label
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(args.workers, mp_context=context) as pool:
            pool.submit(int, 0).result()  # workers started before the clock
            start = time.perf_counter()
            jobs = [
                pool.submit(step_rate, args.task, dynamics, policy, args.steps)
                for _ in range(args.workers)
            ]
            total = sum(j.result() for j in jobs)
            rate = total / (time.perf_counter() - start)

    fixed_s = max(grid_s - steps / rate, 0.0)
    print(
        f"{args.suite} on {args.task}: {len(units)} points, {args.workers} workers, "
        f"policy {HIDDEN}x{HIDDEN}"
    )
    print(
        f"  grid at {args.episodes} episode(s)/point (random policy, {steps / len(units) / args.episodes:.0f} "
        f"steps/episode): {grid_s:.1f} s"
    )
    print(f"  stepping ({dynamics}, no termination): {rate:,.0f} steps/s over all workers")
    for episodes in sorted({1, suite.episodes}):
        estimate = fixed_s + len(units) * episodes * 1000 / rate
        print(
            f"  estimate, 1000-step episodes at {episodes} episode(s)/point: "
            f"{estimate:,.0f} s ({estimate / 3600:.2f} h)"
        )


def _dims(task: str) -> tuple[int, int]:
    from adarl.envs import get_task

    spec = get_task(task)
    return spec.obs_dim, spec.act_dim


if __name__ == "__main__":
    main()
