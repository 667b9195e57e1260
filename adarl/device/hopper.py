"""Gymnasium v5 Hopper as pure JAX functions on MJX (`mujoco.mjx`, ``impl="jax"``).

Implements `gymnasium/envs/mujoco/hopper_v5.py` with its default arguments:

- observation: ``qpos[1:]`` then ``clip(qvel, -10, 10)`` (11 numbers);
- reward: ``forward_reward_weight * x_velocity + healthy_reward * is_healthy
  - ctrl_cost_weight * sum(action**2)`` with weights 1, 1, 1e-3 and
  ``x_velocity = (x_after - x_before) / dt``, ``dt = timestep * frame_skip`` (0.008 s);
- termination: not healthy, where healthy is ``0.7 < z``, ``-0.2 < angle < 0.2`` and every entry of
  ``(qpos[2:], qvel)`` strictly inside ``(-100, 100)``; the task never truncates (the 1,000-step
  time limit belongs to the training loop, as with Gymnasium's TimeLimit wrapper);
- reset: ``init_qpos + U(-5e-3, 5e-3)`` and ``init_qvel + U(-5e-3, 5e-3)`` (JAX's generator, so
  the draws differ from NumPy's for the same seed);
- frame skip: the action is written to ``ctrl`` and the physics steps 4 times (MuJoCo clamps it to
  the actuators' ctrlrange, as in C).

Per-episode physics: ``reset(key, fields)`` takes a dict of `mjx.Model` leaves by dotted name
(e.g. ``{"body_mass": ..., "opt.gravity": ...}``) that replace the base model's for that episode;
the state carries them, so a vmapped batch can run a different model per lane.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

FRAME_SKIP = 4
FORWARD_REWARD_WEIGHT = 1.0
CTRL_COST_WEIGHT = 1e-3
HEALTHY_REWARD = 1.0
HEALTHY_STATE_RANGE = (-100.0, 100.0)
HEALTHY_Z_RANGE = (0.7, float("inf"))
HEALTHY_ANGLE_RANGE = (-0.2, 0.2)
RESET_NOISE_SCALE = 5e-3
VELOCITY_CLIP = 10.0


class State(NamedTuple):
    """One lane's task state: MJX data, the episode's model fields and the step's outputs."""

    data: Any  # mjx.Data
    fields: dict  # dotted mjx.Model name -> array, replacing the base model's leaves


def gymnasium_model():
    """Gymnasium's own hopper.xml as a compiled `mujoco.MjModel` (the host task's model)."""
    import os

    import gymnasium
    import mujoco

    path = os.path.join(os.path.dirname(gymnasium.__file__), "envs/mujoco/assets/hopper.xml")
    return mujoco.MjModel.from_xml_path(path)


class HopperTask:
    """Hopper-v5's observation, reward, termination, reset noise and frame skip on an MJX model.

    `mj_model` is the host `mujoco.MjModel` (Gymnasium's hopper.xml when omitted); `dtype` is the
    floating type of the model and state (float64 needs ``jax_enable_x64``).
    """

    observation_size = 11
    action_size = 3

    def __init__(self, mj_model=None, dtype=None):
        import jax
        import jax.numpy as jnp
        from mujoco import mjx

        self._jax, self._jnp, self._mjx = jax, jnp, mjx
        self.mj_model = gymnasium_model() if mj_model is None else mj_model
        self.dtype = jnp.dtype(dtype or jnp.float32)
        mx = mjx.put_model(self.mj_model, impl="jax")
        self.model = jax.tree.map(self._cast, mx)
        self.dt = float(self.mj_model.opt.timestep) * FRAME_SKIP
        self.init_qpos = jnp.asarray(self.mj_model.qpos0, self.dtype)
        self.init_qvel = jnp.zeros(self.mj_model.nv, self.dtype)
        self._data0 = jax.tree.map(self._cast, mjx.make_data(self.model, impl="jax"))

    def _cast(self, x):
        jnp = self._jnp
        if isinstance(x, (np.ndarray, jnp.ndarray)) and jnp.issubdtype(x.dtype, jnp.floating):
            return jnp.asarray(x, self.dtype)
        return x

    def model_for(self, fields: dict):
        """The base MJX model with `fields` (dotted name -> array) in place of its leaves."""
        if not fields:
            return self.model
        return self.model.tree_replace({k: self._cast(v) for k, v in fields.items()})

    def reset(self, key, fields: dict | None = None) -> State:
        """Hopper-v5 ``reset_model``: init_qpos/qvel plus U(-5e-3, 5e-3) noise, then forward."""
        jax = self._jax
        fields = {} if fields is None else dict(fields)
        kq, kv = jax.random.split(key)
        nq, nv = self.mj_model.nq, self.mj_model.nv
        lo, hi = -RESET_NOISE_SCALE, RESET_NOISE_SCALE
        qpos = self.init_qpos + jax.random.uniform(kq, (nq,), self.dtype, lo, hi)
        qvel = self.init_qvel + jax.random.uniform(kv, (nv,), self.dtype, lo, hi)
        return self.reset_to(qpos, qvel, fields)

    def reset_to(self, qpos, qvel, fields: dict | None = None) -> State:
        """The state at (qpos, qvel), as Gymnasium's ``set_state`` (which runs mj_forward)."""
        jnp = self._jnp
        fields = {} if fields is None else dict(fields)
        data = self._data0.replace(
            qpos=jnp.asarray(qpos, self.dtype), qvel=jnp.asarray(qvel, self.dtype)
        )
        data = self._mjx.forward(self.model_for(fields), data)
        return State(data, fields)

    def observation(self, data):
        """``qpos[1:]`` then ``clip(qvel, -10, 10)`` (Hopper-v5 ``_get_obs``)."""
        jnp = self._jnp
        qvel = jnp.clip(data.qvel, -VELOCITY_CLIP, VELOCITY_CLIP)
        return jnp.concatenate([data.qpos[1:], qvel])

    def is_healthy(self, data):
        """Hopper-v5 ``is_healthy``: z, angle and the state vector inside their open ranges."""
        jnp = self._jnp
        z, angle = data.qpos[1], data.qpos[2]
        state = jnp.concatenate([data.qpos[2:], data.qvel])
        lo, hi = HEALTHY_STATE_RANGE
        healthy_state = jnp.all((lo < state) & (state < hi))
        healthy_z = (HEALTHY_Z_RANGE[0] < z) & (z < HEALTHY_Z_RANGE[1])
        healthy_angle = (HEALTHY_ANGLE_RANGE[0] < angle) & (angle < HEALTHY_ANGLE_RANGE[1])
        return healthy_state & healthy_z & healthy_angle

    def step(self, state: State, action):
        """Hopper-v5 ``step``: (state, obs, reward, terminated, truncated) after 4 physics steps.

        reward = forward_reward (x velocity) + healthy_reward (1 if healthy) - ctrl_cost
        (1e-3 * sum(action**2)); terminated = not healthy; truncated is always False here.
        """
        jax, jnp, mjx = self._jax, self._jnp, self._mjx
        model = self.model_for(state.fields)
        action = jnp.asarray(action, self.dtype)
        data = state.data.replace(ctrl=action)
        x_before = data.qpos[0]

        def physics_step(d, _):
            return mjx.step(model, d), None

        data, _ = jax.lax.scan(physics_step, data, None, length=FRAME_SKIP)
        x_velocity = (data.qpos[0] - x_before) / self.dt
        healthy = self.is_healthy(data)
        forward_reward = FORWARD_REWARD_WEIGHT * x_velocity
        healthy_reward = HEALTHY_REWARD * healthy.astype(self.dtype)
        ctrl_cost = CTRL_COST_WEIGHT * jnp.sum(jnp.square(action))
        reward = forward_reward + healthy_reward - ctrl_cost
        terminated = jnp.logical_not(healthy)
        truncated = jnp.zeros((), bool)
        return State(data, state.fields), self.observation(data), reward, terminated, truncated
