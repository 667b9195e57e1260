"""The device tasks by name, and where their physics differs from the host task's (JAX-free:
`adarl tasks` prints `DIFFERENCES`).

    from adarl.device.tasks import make
    task = make("walker2d", dtype=jnp.float64)       # Gymnasium's XML; or mj_model=...
    state = task.reset(key, fields)                  # fields: adarl.device.physics per episode
    state, obs, reward, terminated, truncated = task.step(state, action)
"""

from __future__ import annotations

from adarl.device import ant, hopper, humanoid, walker2d
from adarl.device.common import DeviceTask, Rules
from adarl.errors import check_choice

RULES: dict[str, Rules] = {
    r.name: r for r in (hopper.RULES, walker2d.RULES, ant.RULES, humanoid.RULES)
}

#: Where the device task differs from the host task on MuJoCo C, as measured in float64 by
#: tests/device (docs/envs.md, "Device physics"); never mix the two backends in one comparison.
DIFFERENCES: dict[str, str] = {
    "hopper": (
        "same physics as MuJoCo C (float64, 200 steps: 1e-8 apart, same terminations) but a "
        "torso-foot contact after a fall (9.6e-8)"
    ),
    "walker2d": "same physics as MuJoCo C (float64: 1.9e-12 apart over 200 steps, same terminations)",
    "ant": (
        "differs from MuJoCo C from the first contact: C and MJX align friction directions "
        "differently under the pyramidal cone (float64, one env step from the same state: "
        "observation 2.07 apart, reward 0.24)"
    ),
    "humanoid": (
        "solves with Newton, the XML with PGS (MJX has no PGS): free-running 200 steps, reward "
        "0.09 apart, same terminations (float64)"
    ),
}


def make(name: str, mj_model=None, dtype=None) -> DeviceTask:
    """The device task `name` on `mj_model` (Gymnasium's XML when omitted) in `dtype` (float32
    unless given; float64 needs ``jax_enable_x64``)."""
    check_choice("device task", name, RULES)
    return DeviceTask(RULES[name], mj_model, dtype)
