"""Device Hopper throughput: env-steps/s of `adarl.device.hopper` (MJX) for a vmapped batch.

    python bench/accelerator.py --platform gpu --batch 1 64 1024 8192 --steps 1000
    python bench/accelerator.py --mujoco-c --steps 20000       # MuJoCo C, one thread

Prints one CSV line per measurement (``kind,platform,batch,steps,compile_s,run_s,env_steps_per_s``)
and appends it to ``--csv``. Random actions in [-1, 1], one jitted `lax.scan` of ``--steps`` env
steps (4 physics steps each), float32, no resets (the physics runs on after a fall, which costs
the same); timed after compilation with `block_until_ready`. The model is Gymnasium's
hopper.xml, or ``--xml``.
"""

from __future__ import annotations

import argparse
import os
import time

HEADER = "kind,platform,batch,steps,compile_s,run_s,env_steps_per_s"


def hopper_module():
    from adarl.device import hopper

    return hopper


def load_model(xml: str | None):
    import mujoco

    if xml:
        return mujoco.MjModel.from_xml_path(xml)
    return hopper_module().gymnasium_model()


def emit(line: str, csv: str | None) -> None:
    print(line, flush=True)
    if csv:
        new = not os.path.exists(csv)
        with open(csv, "a") as f:
            if new:
                f.write(HEADER + "\n")
            f.write(line + "\n")


def device_rate(model, platform: str, batch: int, steps: int) -> tuple[float, float]:
    import jax
    import jax.numpy as jnp

    HopperTask = hopper_module().HopperTask

    device = jax.devices(platform)[0]
    with jax.default_device(device):
        task = HopperTask(model, dtype=jnp.float32)

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
        compiled(jax.random.key(1)).block_until_ready()  # warm-up
        start = time.perf_counter()
        compiled(jax.random.key(2)).block_until_ready()
        return compile_s, time.perf_counter() - start


def mujoco_c_rate(model, steps: int) -> float:
    import mujoco
    import numpy as np

    data = mujoco.MjData(model)
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, model.nu))
    start = time.perf_counter()
    for a in actions:
        data.ctrl[:] = a
        mujoco.mj_step(model, data, nstep=4)
    return time.perf_counter() - start


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--platform", default="gpu")
    parser.add_argument("--batch", type=int, nargs="+", default=[1])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--mujoco-c", action="store_true", help="time MuJoCo C instead")
    parser.add_argument("--xml", default=None)
    parser.add_argument("--csv", default=None)
    args = parser.parse_args(argv)
    model = load_model(args.xml)
    if args.mujoco_c:
        run_s = mujoco_c_rate(model, args.steps)
        emit(f"mujoco_c,cpu,1,{args.steps},0,{run_s:.3f},{args.steps / run_s:.1f}", args.csv)
        return
    for batch in args.batch:
        compile_s, run_s = device_rate(model, args.platform, batch, args.steps)
        rate = batch * args.steps / run_s
        line = f"mjx,{args.platform},{batch},{args.steps},{compile_s:.1f},{run_s:.3f},{rate:.1f}"
        emit(line, args.csv)


if __name__ == "__main__":
    main()
