"""Gymnasium v5 Humanoid on MJX: `gymnasium/envs/mujoco/humanoid_v5.py` with its default arguments
(humanoid.xml, as adarl's host task), with the Newton solver in place of the XML's PGS.

- observation: ``qpos[2:]``, ``qvel``, ``cinert[1:]``, ``cvel[1:]``, ``qfrc_actuator[6:]``,
  ``cfrc_ext[1:]`` flattened (22 + 23 + 130 + 78 + 17 + 78 = 348 numbers);
- reward: ``1.25 * x_velocity + 5 * healthy - 0.1 * sum(ctrl**2) - min(5e-7 * sum(cfrc_ext**2), 10)``,
  the velocity that of the centre of mass (``sum(body_mass * xipos) / sum(body_mass)``) over
  ``dt = 0.015`` s;
- termination: not healthy, where healthy is ``1 < z < 2``;
- reset: ``init_qpos + U(-1e-2, 1e-2)`` and ``init_qvel + U(-1e-2, 1e-2)``; frame skip 5.

MJX has no PGS solver (Newton and CG only), so the device model solves with Newton (same
iterations and tolerance): the physics differs from MuJoCo C's (docs/envs.md, "Device physics").
"""

from __future__ import annotations

from adarl.device.common import Rules, cfrc_ext, cinert, inside, uniform_noise

FRAME_SKIP = 5
FORWARD_REWARD_WEIGHT = 1.25
CTRL_COST_WEIGHT = 0.1
CONTACT_COST_WEIGHT = 5e-7
CONTACT_COST_MAX = 10.0
HEALTHY_REWARD = 5.0
HEALTHY_Z_RANGE = (1.0, 2.0)
RESET_NOISE_SCALE = 1e-2
SOLVER_CHANGE = "the device solves with Newton, the XML with PGS (MJX has no PGS)"


def observation(data):
    """Humanoid-v5 ``_get_obs`` (positions without x, y; then the com-based quantities)."""
    import jax.numpy as jnp

    return jnp.concatenate(
        [
            data.qpos[2:],
            data.qvel,
            cinert(data)[1:].ravel(),
            data.cvel[1:].ravel(),
            data.qfrc_actuator[6:],
            cfrc_ext(data)[1:].ravel(),
        ]
    )


def mass_center(model, data):
    """x and y of the centre of mass (Gymnasium's ``mass_center``)."""
    import jax.numpy as jnp

    mass = model.body_mass[:, None]
    return (jnp.sum(mass * data.xipos, axis=0) / jnp.sum(mass))[:2]


def reward(data, action, xy_velocity):
    """Humanoid-v5 ``_get_rew`` and ``is_healthy``: (reward, healthy); the control cost is of
    ``data.ctrl`` (the action as written, before MuJoCo clamps it)."""
    import jax.numpy as jnp

    z = data.qpos[2]
    healthy = inside(z, HEALTHY_Z_RANGE)
    ctrl_cost = CTRL_COST_WEIGHT * jnp.sum(jnp.square(data.ctrl))
    contact = CONTACT_COST_WEIGHT * jnp.sum(jnp.square(cfrc_ext(data)))
    contact_cost = jnp.minimum(contact, CONTACT_COST_MAX)
    forward = FORWARD_REWARD_WEIGHT * xy_velocity[0]
    return forward + HEALTHY_REWARD * healthy - ctrl_cost - contact_cost, healthy


def use_newton(mj_model) -> None:
    """Switch `mj_model`'s solver to Newton (in place)."""
    import mujoco

    mj_model.opt.solver = mujoco.mjtSolver.mjSOL_NEWTON


RULES = Rules(
    name="humanoid",
    xml="humanoid.xml",
    frame_skip=FRAME_SKIP,
    observation_size=348,
    action_size=17,
    observation=observation,
    position=mass_center,
    reward=reward,
    reset_noise=uniform_noise(RESET_NOISE_SCALE),
    contact_forces=True,
    device_change=(use_newton, SOLVER_CHANGE),
)
