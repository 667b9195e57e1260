"""Gymnasium v5 Ant on MJX: `gymnasium/envs/mujoco/ant_v5.py` with its default arguments (ant.xml,
as adarl's host task).

- observation: ``qpos[2:]``, ``qvel``, then ``clip(cfrc_ext[1:], -1, 1)`` flattened (13 + 14 + 78 =
  105 numbers; v5's default includes the contact forces);
- reward: ``x_velocity + healthy - 0.5 * sum(action**2) - 5e-4 * sum(clip(cfrc_ext, -1, 1)**2)``,
  the velocity that of the torso's ``xpos`` (body 1) over ``dt = 0.05`` s;
- termination: not healthy, where healthy is every entry of (qpos, qvel) finite and
  ``0.2 <= z <= 1`` (closed);
- reset: ``init_qpos + U(-0.1, 0.1)`` and ``init_qvel + 0.1 * N(0, 1)``; frame skip 5.

The physics differs from MuJoCo C from the first contact (docs/envs.md, "Device physics"): under
the XML's pyramidal friction cone, C and MJX pick different friction directions.
"""

from __future__ import annotations

from adarl.device.common import Rules, cfrc_ext

FRAME_SKIP = 5
FORWARD_REWARD_WEIGHT = 1.0
CTRL_COST_WEIGHT = 0.5
CONTACT_COST_WEIGHT = 5e-4
HEALTHY_REWARD = 1.0
MAIN_BODY = 1
HEALTHY_Z_RANGE = (0.2, 1.0)
CONTACT_FORCE_RANGE = (-1.0, 1.0)
RESET_NOISE_SCALE = 0.1


def _contact_forces(data):
    import jax.numpy as jnp

    return jnp.clip(cfrc_ext(data), *CONTACT_FORCE_RANGE)


def observation(data):
    """``qpos[2:]``, ``qvel``, ``clip(cfrc_ext[1:], -1, 1)`` (Ant-v5 ``_get_obs``)."""
    import jax.numpy as jnp

    return jnp.concatenate([data.qpos[2:], data.qvel, _contact_forces(data)[1:].ravel()])


def reward(data, action, xy_velocity):
    """Ant-v5 ``_get_rew`` and ``is_healthy``: (reward, healthy)."""
    import jax.numpy as jnp

    state = jnp.concatenate([data.qpos, data.qvel])
    z = data.qpos[2]
    healthy = jnp.all(jnp.isfinite(state)) & (HEALTHY_Z_RANGE[0] <= z) & (z <= HEALTHY_Z_RANGE[1])
    ctrl_cost = CTRL_COST_WEIGHT * jnp.sum(jnp.square(action))
    contact_cost = CONTACT_COST_WEIGHT * jnp.sum(jnp.square(_contact_forces(data)))
    forward = FORWARD_REWARD_WEIGHT * xy_velocity[0]
    return forward + HEALTHY_REWARD * healthy - ctrl_cost - contact_cost, healthy


def reset_noise(key, qpos0, qvel0):
    """``qpos0 + U(-0.1, 0.1)``, ``qvel0 + 0.1 * N(0, 1)`` (Ant-v5 ``reset_model``)."""
    import jax

    kq, kv = jax.random.split(key)
    s = RESET_NOISE_SCALE
    qpos = qpos0 + jax.random.uniform(kq, qpos0.shape, qpos0.dtype, -s, s)
    qvel = qvel0 + s * jax.random.normal(kv, qvel0.shape, qvel0.dtype)
    return qpos, qvel


RULES = Rules(
    name="ant",
    xml="ant.xml",
    frame_skip=FRAME_SKIP,
    observation_size=105,
    action_size=8,
    observation=observation,
    position=lambda model, data: data.xpos[MAIN_BODY, :2],
    reward=reward,
    reset_noise=reset_noise,
    contact_forces=True,
)
