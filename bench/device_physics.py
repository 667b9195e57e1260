"""Where the device tasks' physics (MJX) and the host tasks' (MuJoCo C) part, and why (issue 36;
docs/envs.md, "Device physics"). Float64 on the CPU.

    python bench/device_physics.py compare hopper --tolerance 1e-10
    python bench/device_physics.py compare humanoid --integrator euler --solver newton
    python bench/device_physics.py rk4 humanoid

`compare` runs tests/device/host_compare.py's four lanes (the nominal episode and three `paper`
episodes, random actions, 200 env steps) with the options given applied to both sides' models, and
prints how far the observation and reward get apart per lane, free-running and one env step from
the same state. (Ant's and Humanoid's rewards read body positions, which after a step are those
of its last physics step's start on both sides; from a state set on the host, `set_state`'s
`mj_forward` makes its "before" position fresh where the device's is not, so their rewards one step
from the same state are not comparable; free-running they are.) `rk4` takes one physics step of the task's XML model (its integrator set to RK4, Newton
solver, constraints off) from a perturbed state with MuJoCo C's `mj_step`, with MJX's `step`, and
with a textbook RK4 assembled from C's own `mj_forward` and `mj_integratePos`, and prints how far
apart the three land.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "device"))  # the harness


def _options(args):
    import mujoco

    def apply(model):
        if args.integrator:
            model.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{args.integrator.upper()}")
        if args.solver:
            model.opt.solver = getattr(mujoco.mjtSolver, f"mjSOL_{args.solver.upper()}")
        if args.tolerance is not None:
            model.opt.tolerance = args.tolerance
        if args.cone:
            model.opt.cone = getattr(mujoco.mjtCone, f"mjCONE_{args.cone.upper()}")

    return apply


def _worst(values) -> str:
    return "[" + ", ".join(f"{v:.2g}" for v in values) + "]"


def compare(args) -> None:
    import host_compare
    import jax

    with jax.enable_x64(True):
        setup = host_compare.setup(args.task, options=_options(args))
        for resync in (False, True):
            r = host_compare.compare(
                setup.lanes, setup.fields, setup.envs, args.steps, resync_every_step=resync
            )
            how = "one env step from the same state" if resync else "free-running"
            print(
                f"{args.task} {how}: observation {_worst(r.obs)}, reward {_worst(r.reward)}, "
                "first step > 1e-6 apart "
                f"{r.first_apart}, terminations {r.terminations} ({r.termination_mismatches} on "
                "one side only)"
            )


def rk4(args) -> dict[str, tuple[float, float]]:
    """Prints, and returns, each of mj_step's and MJX's distance from the textbook RK4 step
    (qpos, qvel; max-abs)."""
    import jax
    import mujoco
    from mujoco import mjx

    from adarl.device.common import gymnasium_model
    from adarl.device.tasks import RULES

    m = gymnasium_model(RULES[args.task].xml)
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    m.opt.solver = mujoco.mjtSolver.mjSOL_NEWTON
    m.opt.disableflags = int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    d.qpos[:] += rng.uniform(-0.01, 0.01, m.nq)
    d.qvel[:] = rng.uniform(-0.1, 0.1, m.nv)
    d.ctrl[:] = rng.uniform(*m.actuator_ctrlrange.T)
    mujoco.mj_normalizeQuat(m, d.qpos)
    q0, v0 = d.qpos.copy(), d.qvel.copy()
    with jax.enable_x64(True):
        device = jax.jit(mjx.step)(mjx.put_model(m), mjx.put_data(m, d))
        device = jax.tree.map(np.asarray, (device.qpos, device.qvel))

    scratch = mujoco.MjData(m)
    scratch.ctrl[:] = d.ctrl

    def acceleration(q, v):
        scratch.qpos[:], scratch.qvel[:] = q, v
        mujoco.mj_forward(m, scratch)
        return scratch.qacc.copy()

    h = m.opt.timestep
    stages, accelerations = [(q0, v0)], [acceleration(q0, v0)]
    for a in (0.5, 0.5, 1.0):  # the RK4 tableau's diagonal (MuJoCo's RK4_A)
        q = q0.copy()
        mujoco.mj_integratePos(m, q, a * stages[-1][1], h)
        v = v0 + h * a * accelerations[-1]
        stages.append((q, v))
        accelerations.append(acceleration(q, v))
    b = (1 / 6, 1 / 3, 1 / 3, 1 / 6)
    textbook_q = q0.copy()
    mujoco.mj_integratePos(m, textbook_q, sum(w * s[1] for w, s in zip(b, stages)), h)
    textbook_v = v0 + h * sum(w * f for w, f in zip(b, accelerations))
    mujoco.mj_step(m, d)
    out = {}
    for name, (q, v) in {
        "mj_step": (d.qpos, d.qvel),
        "MJX": device,
    }.items():
        out[name] = (float(np.abs(q - textbook_q).max()), float(np.abs(v - textbook_v).max()))
        print(
            f"{args.task} RK4, one step, {name} − textbook: qpos {out[name][0]:.2g}, "
            f"qvel {out[name][1]:.2g}"
        )
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    tasks = ["hopper", "walker2d", "ant", "humanoid"]
    c = sub.add_parser("compare", help="the device task against the host task, four lanes")
    c.add_argument("task", choices=tasks)
    c.add_argument("--steps", type=int, default=200)
    c.add_argument("--integrator", choices=["euler", "rk4", "implicitfast"])
    c.add_argument("--solver", choices=["newton", "cg"])
    c.add_argument("--tolerance", type=float)
    c.add_argument("--cone", choices=["pyramidal", "elliptic"])
    r = sub.add_parser("rk4", help="one RK4 step: mj_step, MJX and a textbook RK4")
    r.add_argument("task", choices=tasks)
    args = parser.parse_args(argv)
    compare(args) if args.command == "compare" else rk4(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
