"""Gymnasium v5 Hopper on MJX: `gymnasium/envs/mujoco/hopper_v5.py` with its default arguments.

- observation: ``qpos[1:]`` then ``clip(qvel, -10, 10)`` (11 numbers);
- reward: ``forward_reward_weight * x_velocity + healthy_reward * is_healthy
  - ctrl_cost_weight * sum(action**2)`` with weights 1, 1, 1e-3 and
  ``x_velocity = (x_after - x_before) / dt``, ``dt = timestep * frame_skip`` (0.008 s);
- termination: not healthy, where healthy is ``0.7 < z``, ``-0.2 < angle < 0.2`` and every entry of
  ``(qpos[2:], qvel)`` strictly inside ``(-100, 100)``;
- reset: ``init_qpos + U(-5e-3, 5e-3)`` and ``init_qvel + U(-5e-3, 5e-3)``;
- frame skip 4 (MuJoCo clamps the action to the actuators' ctrlrange, as in C).

Walker2d shares the observation and reward (`planar_rules`); `adarl.device.common` runs them.
"""

from __future__ import annotations

from adarl.device.common import DeviceTask, Rules, State, inside, uniform_noise

__all__ = ["RULES", "HopperTask", "State", "gymnasium_model", "planar_rules"]

FRAME_SKIP = 4
FORWARD_REWARD_WEIGHT = 1.0
CTRL_COST_WEIGHT = 1e-3
HEALTHY_REWARD = 1.0
HEALTHY_STATE_RANGE = (-100.0, 100.0)
HEALTHY_Z_RANGE = (0.7, float("inf"))
HEALTHY_ANGLE_RANGE = (-0.2, 0.2)
RESET_NOISE_SCALE = 5e-3
VELOCITY_CLIP = 10.0


def planar_rules(name, xml, action_size, nq, nv, z_range, angle_range, state_range=None) -> Rules:
    """Hopper-v5 / Walker2d-v5: observation ``qpos[1:]``, ``clip(qvel, -10, 10)``; reward
    ``x_velocity + healthy - 1e-3 * sum(action**2)``; healthy: ``z`` and ``angle`` (qpos[1], qpos[2])
    inside their open ranges and, where `state_range` is given, ``(qpos[2:], qvel)`` inside it."""

    def observation(data):
        import jax.numpy as jnp

        qvel = jnp.clip(data.qvel, -VELOCITY_CLIP, VELOCITY_CLIP)
        return jnp.concatenate([data.qpos[1:], qvel])

    def is_healthy(data):
        import jax.numpy as jnp

        z, angle = data.qpos[1], data.qpos[2]
        healthy = inside(z, z_range) & inside(angle, angle_range)
        if state_range is not None:
            state = jnp.concatenate([data.qpos[2:], data.qvel])
            healthy = healthy & jnp.all(inside(state, state_range))
        return healthy

    def reward(data, action, x_velocity):
        import jax.numpy as jnp

        healthy = is_healthy(data)
        ctrl_cost = CTRL_COST_WEIGHT * jnp.sum(jnp.square(action))
        value = FORWARD_REWARD_WEIGHT * x_velocity + HEALTHY_REWARD * healthy - ctrl_cost
        return value, healthy

    return Rules(
        name=name,
        xml=xml,
        frame_skip=FRAME_SKIP,
        observation_size=nq - 1 + nv,
        action_size=action_size,
        observation=observation,
        position=lambda model, data: data.qpos[0],
        reward=reward,
        reset_noise=uniform_noise(RESET_NOISE_SCALE),
    )


RULES = planar_rules(
    "hopper", "hopper.xml", 3, 6, 6, HEALTHY_Z_RANGE, HEALTHY_ANGLE_RANGE, HEALTHY_STATE_RANGE
)


def gymnasium_model():
    """Gymnasium's own hopper.xml as a compiled `mujoco.MjModel` (the host task's model)."""
    from adarl.device.common import gymnasium_model as load

    return load(RULES.xml)


def HopperTask(mj_model=None, dtype=None) -> DeviceTask:  # the groundwork's name, kept
    """Hopper-v5 on an MJX model (`DeviceTask` of `RULES`; Gymnasium's hopper.xml by default)."""
    return DeviceTask(RULES, mj_model, dtype)
