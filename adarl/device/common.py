"""What every device task shares: Gymnasium's `MujocoEnv` on MJX (`mujoco.mjx`, ``impl="jax"``).

A task is a `Rules` (its XML, frame skip, observation, forward position, reward and health, reset
noise) run by one `DeviceTask`: the MJX model in one floating type, per-episode model fields,
``set_state`` (`DeviceTask.reset_to`) and ``do_simulation`` (the action written to ``ctrl``, then
``frame_skip`` physics steps, then ``mj_rnePostConstraint`` where the task reads ``cfrc_ext``),
their matmuls at `adarl.device.MATMUL_PRECISION` (float32, not a GPU's TF32).

Per-episode physics: ``reset(key, fields)`` takes a dict of `mjx.Model` leaves by dotted name
(``{"body_mass": ..., "opt.gravity": ...}``) that replace the base model's for that episode; the
state carries them, so a vmapped batch runs a different model per lane (`adarl.device.physics`
builds them per episode from the host's schedules).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from adarl.device import matmul_precision


class State(NamedTuple):
    """One lane's task state: MJX data and the episode's model fields."""

    data: Any  # mjx.Data
    fields: dict  # dotted mjx.Model name -> array, replacing the base model's leaves


@dataclass(frozen=True)
class Rules:
    """One Gymnasium v5 task as pure functions of MJX arrays (each task module defines one)."""

    name: str
    xml: str  # Gymnasium's XML file of the v5 env (its assets folder)
    frame_skip: int
    observation_size: int
    action_size: int
    observation: Callable  # (data) -> observation
    position: Callable  # (model, data) -> what the forward reward differentiates (x, or x and y)
    reward: Callable  # (data, action, velocity) -> (reward, healthy)
    reset_noise: Callable  # (key, qpos0, qvel0) -> (qpos, qvel)
    contact_forces: bool = False  # the task reads cfrc_ext: mj_rnePostConstraint after the step
    #: what the device model changes from the host's (MJX lacks a feature), as (MjModel -> None, why)
    device_change: tuple[Callable, str] | None = None


def gymnasium_model(xml: str):
    """Gymnasium's own `xml` (its MuJoCo assets folder) as a compiled `mujoco.MjModel`."""
    import gymnasium
    import mujoco

    path = os.path.join(os.path.dirname(gymnasium.__file__), "envs/mujoco/assets", xml)
    return mujoco.MjModel.from_xml_path(path)


def device_model(rules: Rules, mj_model):
    """`mj_model` as the device runs it: a copy with `rules.device_change` applied (Humanoid's
    solver), or `mj_model` itself."""
    import copy

    if rules.device_change is None:
        return mj_model
    model = copy.copy(mj_model)
    rules.device_change[0](model)
    return model


def cfrc_ext(data):
    """MJX's ``cfrc_ext`` (com-based external forces on each body, world first)."""
    return data._impl.cfrc_ext


def cinert(data):
    """MJX's ``cinert`` (com-based body inertias, world first)."""
    return data._impl.cinert


class DeviceTask:
    """A Gymnasium v5 MuJoCo task (`rules`) on an MJX model, as pure reset/step functions.

    `mj_model` is the host `mujoco.MjModel` (Gymnasium's XML when omitted); a task whose rules
    carry a `device_change` (Humanoid's solver) applies it to a copy. `dtype` is the floating type
    of the model and state (float64 needs ``jax_enable_x64``).
    """

    def __init__(self, rules: Rules, mj_model=None, dtype=None):
        import jax
        import jax.numpy as jnp
        from mujoco import mjx

        self._jax, self._jnp, self._mjx = jax, jnp, mjx
        self.rules = rules
        self.observation_size, self.action_size = rules.observation_size, rules.action_size
        self.mj_model = gymnasium_model(rules.xml) if mj_model is None else mj_model
        self.dtype = jnp.dtype(dtype or jnp.float32)
        self.model = jax.tree.map(
            self._cast, mjx.put_model(device_model(rules, self.mj_model), impl="jax")
        )
        self.dt = float(self.mj_model.opt.timestep) * rules.frame_skip
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
        """Gymnasium's ``reset_model``: init_qpos/qvel plus the task's noise, then ``set_state``."""
        qpos, qvel = self.rules.reset_noise(key, self.init_qpos, self.init_qvel)
        return self.reset_to(qpos, qvel, fields)

    def reset_to(self, qpos, qvel, fields: dict | None = None) -> State:
        """The state at (qpos, qvel) from fresh data, as Gymnasium's reset (``mj_resetData``, then
        ``set_state``, which runs ``mj_forward``)."""
        jnp = self._jnp
        fields = {} if fields is None else dict(fields)
        data = self._data0.replace(
            qpos=jnp.asarray(qpos, self.dtype), qvel=jnp.asarray(qvel, self.dtype)
        )
        with matmul_precision():
            data = self._mjx.forward(self.model_for(fields), data)
        return State(data, fields)

    def observation(self, data):
        """The task's ``_get_obs``."""
        return self.rules.observation(data)

    def step(self, state: State, action):
        """Gymnasium's ``step``: (state, obs, reward, terminated, truncated) after ``frame_skip``
        physics steps; velocity = (position after - position before) / dt, dt = timestep *
        frame_skip; terminated = not healthy; truncated is always False (the time limit belongs to
        the training loop, as with Gymnasium's TimeLimit wrapper)."""
        jax, jnp, mjx = self._jax, self._jnp, self._mjx
        rules = self.rules
        model = self.model_for(state.fields)
        action = jnp.asarray(action, self.dtype)
        data = state.data.replace(ctrl=action)
        before = rules.position(model, data)

        def physics_step(d, _):
            return mjx.step(model, d), None

        with matmul_precision():
            data, _ = jax.lax.scan(physics_step, data, None, length=rules.frame_skip)
            if rules.contact_forces:
                data = mjx.rne_postconstraint(model, data)
        velocity = (rules.position(model, data) - before) / self.dt
        reward, healthy = rules.reward(data, action, velocity)
        terminated = jnp.logical_not(healthy)
        truncated = jnp.zeros((), bool)
        return State(data, state.fields), rules.observation(data), reward, terminated, truncated


def uniform_noise(scale: float) -> Callable:
    """Reset noise of Hopper, Walker2d and Humanoid: ``U(-scale, scale)`` on qpos and qvel (JAX's
    generator, so the draws differ from NumPy's for the same seed)."""

    def noise(key, qpos0, qvel0):
        import jax

        kq, kv = jax.random.split(key)
        qpos = qpos0 + jax.random.uniform(kq, qpos0.shape, qpos0.dtype, -scale, scale)
        qvel = qvel0 + jax.random.uniform(kv, qvel0.shape, qvel0.dtype, -scale, scale)
        return qpos, qvel

    return noise


def inside(x, bounds: tuple[float, float]):
    """``low < x < high`` elementwise (Gymnasium's open healthy ranges)."""
    low, high = bounds
    return (low < x) & (x < high)
