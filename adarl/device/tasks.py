"""The device tasks by name, and where their physics differs from the host task's (JAX-free:
`adarl tasks` prints `DIFFERENCES`).

    from adarl.device.tasks import make
    task = make("walker2d", dtype=jnp.float64)       # Gymnasium's XML; or mj_model=...
    task = make("hopper", solver=solver_caps("1,4"))  # the solver capped (a different physics)
    state = task.reset(key, fields)                  # fields: adarl.device.physics per episode
    state, obs, reward, terminated, truncated = task.step(state, action)
"""

from __future__ import annotations

from adarl.device import ant, hopper, humanoid, walker2d
from adarl.device.common import DeviceTask, Rules, gymnasium_model
from adarl.errors import UsageError, check_choice

#: The device solver as the task's XML sets it (`--device-solver xml`), else "ITERATIONS,LS"
#: capped: MJX's line search is a scan whose trips, vmapped, all run, so `100,4` ran 4.6 times
#: faster on a CPU and matched MuJoCo C as `xml` does; `1,4` (MuJoCo Playground's MJX models) is
#: a different physics (docs/envs.md, "Device physics").
XML_SOLVER = "xml"
#: `--device-solver`'s default per task (`default_solver`): the capped `100,4` where, and only
#: where, the float64 comparison against MuJoCo C passes with it as with the XML's solver
#: (tests/device/test_hopper.py and test_walker2d.py, "capped" tests); Ant and Humanoid differ
#: from C under either solver (`DIFFERENCES`), so nothing shows the cap is their physics: `xml`.
CAPPED_SOLVER = "100,4"
CAPPED_DEFAULT = ("hopper", "walker2d")

RULES: dict[str, Rules] = {
    r.name: r for r in (hopper.RULES, walker2d.RULES, ant.RULES, humanoid.RULES)
}

#: Where the device task differs from the host task on MuJoCo C, as measured in float64 by
#: tests/device (docs/envs.md, "Device physics"); never mix the two backends in one comparison.
DIFFERENCES: dict[str, str] = {
    "hopper": (
        "same physics as MuJoCo C (float64, 200 steps: 1e-14 apart, same terminations, once C's "
        "solver is converged; at the XML's tolerance C stops up to 9.6e-8 short)"
    ),
    "walker2d": "same physics as MuJoCo C (float64: 1.9e-12 apart over 200 steps, same terminations)",
    "ant": (
        "differs from MuJoCo C from the first contact: C and MJX align friction directions "
        "differently under the pyramidal cone (float64, one env step from the same state: "
        "observation 2.07 apart, reward 0.24); C's RK4 with a free joint is not the textbook "
        "RK4 that MJX computes (6.7e-8 per physics step)"
    ),
    "humanoid": (
        "solves with Newton, the XML with PGS (MJX has no PGS); C's RK4 with a free joint is not "
        "the textbook RK4 that MJX computes (3.2e-8 per physics step); contacts as Ant's: "
        "free-running 200 steps, reward 0.09 apart, same terminations (float64)"
    ),
}


def default_solver(task: str) -> str:
    """The `--device-solver` a device run of `task` gets when none is given (`CAPPED_DEFAULT`)."""
    return CAPPED_SOLVER if task in CAPPED_DEFAULT else XML_SOLVER


def solver_caps(value: str) -> tuple[int, int] | None:
    """`--device-solver`: None for "xml" (the task XML's solver), else (iterations,
    line-search iterations) from "I,L", each an integer ≥ 1 (one-line UsageError otherwise)."""
    if value == XML_SOLVER:
        return None
    parts = value.split(",")
    if len(parts) == 2 and all(p.strip().isdigit() and int(p) >= 1 for p in parts):
        return int(parts[0]), int(parts[1])
    raise UsageError(
        f"device-solver must be 'xml' or 'ITERATIONS,LS_ITERATIONS' (integers >= 1, e.g. 1,4), "
        f"got {value!r}"
    )


def make(name: str, mj_model=None, dtype=None, solver: tuple[int, int] | None = None) -> DeviceTask:
    """The device task `name` on `mj_model` (Gymnasium's XML when omitted) in `dtype` (float32
    unless given; float64 needs ``jax_enable_x64``), its solver capped at `solver` (iterations,
    line-search iterations) where given, on a copy of the model."""
    import copy

    check_choice("device task", name, RULES)
    rules = RULES[name]
    if solver is not None:
        mj_model = copy.copy(gymnasium_model(rules.xml) if mj_model is None else mj_model)
        mj_model.opt.iterations, mj_model.opt.ls_iterations = solver
    return DeviceTask(rules, mj_model, dtype)
