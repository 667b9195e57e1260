"""Device physics throughput: env-steps/s of a device task (`adarl.device.tasks`, MJX) for a
vmapped batch, against MuJoCo C on one thread.

    python bench/accelerator.py --task hopper --platform gpu --batch 1 1024 8192 --steps 1000
    python bench/accelerator.py --task hopper --mujoco-c --steps 20000
    python bench/accelerator.py --task hopper --device-solver 100,4 --batch 1024

``--device-solver ITERATIONS,LS`` caps the constraint solver as `adarl train --device-solver`
does (the XMLs' are 100,50, Humanoid's 50,50): `100,4` matched MuJoCo C as the XML's does, `1,4`
(MuJoCo Playground's MJX models) is a different physics (docs/envs.md, "Device physics"); the
kind column says which (`mjx`, `mjx-100/4`).

Prints one CSV line per measurement (``task,kind,platform,batch,steps,compile_s,run_s,env_steps_per_s``)
and appends it to ``--csv``. Random actions in [-1, 1], one jitted `lax.scan` of ``--steps`` env
steps (the task's frame skip of physics steps each), float32, no resets (the physics runs on
after a fall, which costs about the same); timed after compilation with `block_until_ready`. The
model is Gymnasium's XML of the task (MuJoCo C runs it as it is: Humanoid with PGS, the device
task with Newton, docs/envs.md "Device physics").
"""

from __future__ import annotations

import argparse
import os
import sys
import time

HEADER = "task,kind,platform,batch,steps,compile_s,run_s,env_steps_per_s"


def rules_of(task: str):
    from adarl.device.tasks import RULES

    return RULES[task]


def load_model(task: str):
    from adarl.device.common import gymnasium_model

    return gymnasium_model(rules_of(task).xml)


def progress(message: str) -> None:
    """A line on stderr as the measurement goes, so that one stopped by its time limit still
    tells how far it got (bench/accelerator.sh keeps them in accelerator.err)."""
    print(f"# {message}", file=sys.stderr, flush=True)


def emit(line: str, csv: str | None) -> None:
    print(line, flush=True)
    if csv:
        new = not os.path.exists(csv)
        with open(csv, "a") as f:
            if new:
                f.write(HEADER + "\n")
            f.write(line + "\n")


def device_rate(
    name: str, platform: str, batch: int, steps: int, solver=None
) -> tuple[float, float]:
    import jax
    import jax.numpy as jnp

    from adarl.device.tasks import make

    device = jax.devices(platform)[0]
    with jax.default_device(device):
        task = make(name, dtype=jnp.float32, solver=solver)

        @jax.jit
        def rollout(key):
            k_reset, k_act = jax.random.split(key)
            state = jax.vmap(task.reset)(jax.random.split(k_reset, batch))

            def body(carry, k):
                state, total = carry
                action = jax.random.uniform(k, (batch, task.action_size), jnp.float32, -1, 1)
                state, _, reward, _, _ = jax.vmap(task.step)(state, action)
                return (state, total + reward.sum()), None

            (state, total), _ = jax.lax.scan(
                body, (state, jnp.zeros((), jnp.float32)), jax.random.split(k_act, steps)
            )
            return total

        start = time.perf_counter()
        compiled = rollout.lower(jax.random.key(0)).compile()
        compile_s = time.perf_counter() - start
        progress(f"{name} B={batch}: compiled in {compile_s:.1f} s")
        start = time.perf_counter()
        compiled(jax.random.key(1)).block_until_ready()  # warm-up
        progress(f"{name} B={batch}: warm-up run in {time.perf_counter() - start:.3f} s")
        start = time.perf_counter()
        compiled(jax.random.key(2)).block_until_ready()
        return compile_s, time.perf_counter() - start


def mujoco_c_rate(name: str, steps: int) -> float:
    import mujoco
    import numpy as np

    model, frame_skip = load_model(name), rules_of(name).frame_skip
    data = mujoco.MjData(model)
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, model.nu))
    start = time.perf_counter()
    for a in actions:
        data.ctrl[:] = a
        mujoco.mj_step(model, data, nstep=frame_skip)
    return time.perf_counter() - start


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--task", default="hopper", choices=["hopper", "walker2d", "ant", "humanoid"]
    )
    parser.add_argument("--platform", default="gpu")
    parser.add_argument("--batch", type=int, nargs="+", default=[1])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--mujoco-c", action="store_true", help="time MuJoCo C instead")
    parser.add_argument("--device-solver", default="xml", help="xml, or ITERATIONS,LS_ITERATIONS")
    parser.add_argument("--csv", default=None)
    args = parser.parse_args(argv)
    from adarl.device.tasks import solver_caps
    from adarl.errors import UsageError

    try:
        solver = solver_caps(args.device_solver)
    except UsageError as exc:
        print(f"accelerator.py: error: {exc}", file=sys.stderr)
        return 2
    if args.mujoco_c:
        run_s = mujoco_c_rate(args.task, args.steps)
        line = f"{args.task},mujoco_c,cpu,1,{args.steps},0,{run_s:.3f},{args.steps / run_s:.1f}"
        emit(line, args.csv)
        return 0
    kind = "mjx" if solver is None else "mjx-" + args.device_solver.replace(",", "/")
    for batch in args.batch:
        compile_s, run_s = device_rate(args.task, args.platform, batch, args.steps, solver)
        rate = batch * args.steps / run_s
        line = f"{args.task},{kind},{args.platform},{batch},{args.steps},{compile_s:.1f},{run_s:.3f},{rate:.1f}"
        emit(line, args.csv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
