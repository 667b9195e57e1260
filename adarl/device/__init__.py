"""Device tasks: Gymnasium v5 MuJoCo tasks as pure JAX reset/step functions on MJX.

    from adarl.device.physics import physics_table
    from adarl.device.tasks import make
    table = physics_table("walker2d", "paper", seed=0)     # per-episode model fields, host-built
    task = make("walker2d", table.mj_model)                # hopper, walker2d, ant, humanoid; float32
    state = task.reset(key, table.row(i))                  # episode i's model fields
    states = jax.vmap(task.reset)(keys, table.rows(range(i, i + n)))  # one episode per lane
    state, obs, reward, terminated, truncated = task.step(state, action)

`common.py` runs every task (`DeviceTask`); each task module holds its Gymnasium rules (`Rules`);
`hopper.HopperTask()` is `make("hopper")`. Where a task's physics differs from MuJoCo C's (Ant's
friction directions, Humanoid's solver): `tasks.DIFFERENCES` and docs/envs.md.

Physics is MJX's pure-JAX implementation (`mujoco.mjx`, ``impl="jax"``), chosen over MuJoCo Warp
because the Warp stack cannot reach the accelerator machine (warp-lang's wheel is 149 MB, the
carried tree 64 MiB) and MJX matches MuJoCo C to 1e-13 in float64 (docs/benchmarks.md,
"Accelerator groundwork"). The backend is imported lazily: ``import adarl.device`` works without
it, and :func:`available` says whether it is installed.

Every matmul of the device backend runs at `MATMUL_PRECISION` (float32), set explicitly where
the physics and the device learner's functions are traced (`matmul_precision`): unset, JAX on an
NVIDIA GPU from Ampere on computes float32 matmuls as TF32 (a 10-bit mantissa), so MJX's physics,
compared with MuJoCo C only on CPUs, and the SVD input of every truncation
(`lowrank.bottleneck_product`) would lose precision there and ranks could differ from a CPU's.
A device run records the setting (`numerics`) in its checkpoints' meta.json.
"""

from __future__ import annotations

import importlib.util

__all__ = [
    "MATMUL_PRECISION",
    "NOT_ON_DEVICE",
    "available",
    "matmul_precision",
    "missing_reason",
    "numerics",
]

#: Algorithms `--backend device` cannot train, and why (`adarl train` says it in one line)
NOT_ON_DEVICE = {
    "rnac": (
        "rnac trains on the host backend only: the device learner is the SAC family's "
        "off-policy chunk, and RNAC's on-policy rollout (its normalisers, GAE and PPO epochs, "
        "double sampling's candidate next states from a copy of each visited state) has no "
        "device version; --backend applies to the SAC family"
    ),
}

#: ``jax.default_matmul_precision`` of every device computation: "highest", float32 matmuls on
#: every platform (a GPU's default is TF32, a TPU's bfloat16 passes)
MATMUL_PRECISION = "highest"


def available() -> bool:
    """Whether the device backend (``mujoco.mjx``) can be imported."""
    return missing_reason() is None


def missing_reason() -> str | None:
    """Why the device backend cannot be imported, or None when it can."""
    try:
        if importlib.util.find_spec("mujoco") is None:
            return "mujoco is not installed"
        if importlib.util.find_spec("mujoco.mjx") is None:
            return "mujoco.mjx is not installed (pip install mujoco-mjx; mujoco 4.0.0 ships none)"
    except (ImportError, ValueError) as err:  # a broken parent package
        return f"mujoco.mjx cannot be found: {err}"
    return None


def matmul_precision():
    """The context that sets `MATMUL_PRECISION` for the matmuls traced inside it (JAX reads the
    setting when a matmul is traced: entered inside a jitted function, it holds whatever the
    process's default is)."""
    import jax

    return jax.default_matmul_precision(MATMUL_PRECISION)


def numerics() -> dict:
    """The settings that change the device backend's numbers, as a run records them."""
    return {"matmul_precision": MATMUL_PRECISION}
