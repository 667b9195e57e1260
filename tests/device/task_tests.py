"""The checks every device task's test module runs (tests/device/test_<task>.py): against the
host task on MuJoCo C from the same states and actions, and its reset noise."""

from __future__ import annotations

import inspect

import gymnasium
import mujoco
import numpy as np
from gymnasium.envs.registration import load_env_creator
from host_compare import compare

STEPS = 200


def gymnasium_default(gym_id: str, argument: str):
    """The default of `argument` of Gymnasium's env class `gym_id` (read from its signature)."""
    creator = load_env_creator(gymnasium.spec(gym_id).entry_point)
    return inspect.signature(creator.__init__).parameters[argument].default


def check_reset_noise(setup, gym_id: str, normal_qvel: bool = False):
    """Reset states of every lane lie within Gymnasium's noise around qpos0/qvel0 (qvel: a
    normal of that standard deviation where `normal_qvel`); the same keys give the same states."""
    import jax

    scale = gymnasium_default(gym_id, "reset_noise_scale")
    lanes = len(setup.envs)
    keys = jax.random.split(jax.random.key(7), 16 * lanes).reshape(16, lanes)
    states = [setup.lanes.reset(k, setup.fields) for k in keys]
    qpos = np.concatenate([np.asarray(s.data.qpos) for s in states])
    qvel = np.concatenate([np.asarray(s.data.qvel) for s in states])
    model = setup.envs[0].model
    qpos0 = model.qpos0
    assert qpos.dtype == np.float64
    if model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE:
        # MJX's forward writes the free joint's quaternion back normalised (C keeps qpos as set
        # and normalises only inside its kinematics), so those four numbers may leave the noise
        # box; they are unit quaternions instead
        quaternion = qpos[:, 3:7]
        np.testing.assert_allclose(np.linalg.norm(quaternion, axis=1), 1.0, atol=1e-12)
        qpos, qpos0 = np.delete(qpos, np.s_[3:7], axis=1), np.delete(qpos0, np.s_[3:7])
    assert np.all(np.abs(qpos - qpos0) <= scale) and np.abs(qpos - qpos0).max() > 0.95 * scale
    if normal_qvel:
        assert abs(qvel.std() / scale - 1) < 0.1 and abs(qvel.mean()) < 0.1 * scale
    else:
        assert np.all(np.abs(qvel) <= scale) and np.abs(qvel).max() > 0.95 * scale
    again = setup.lanes.reset(keys[0], setup.fields)
    np.testing.assert_array_equal(np.asarray(again.data.qpos), np.asarray(states[0].data.qpos))


def check_against_host(setup, bound: float, resync_every_step: bool = False, **kwargs):
    """Every lane's observation and reward within `bound` of its host env's for `STEPS` env
    steps, and the same terminations; returns the `Comparison`."""
    result = compare(
        setup.lanes, setup.fields, setup.envs, STEPS, resync_every_step=resync_every_step, **kwargs
    )
    assert result.worst < bound, (result.obs, result.reward, result.worst_at)
    return result
