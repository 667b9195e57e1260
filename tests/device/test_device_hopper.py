"""The device Hopper task (`adarl.device.hopper`, MJX) against Gymnasium's Hopper-v5 on MuJoCo C.

Float64, same initial state and actions: observation, reward and termination agree to 1e-7 over 300
env steps (measured worst 2.2e-8; issue 36 asks 1e-8: open), the host and device resynchronised at
each termination (as training resets there). Skipped where `mujoco.mjx` is not installed (the
project venv; see docs/benchmarks.md, "Accelerator groundwork", for the scratch venv that runs it).
"""

import numpy as np
import pytest

from adarl.device import missing_reason

pytestmark = pytest.mark.skipif(missing_reason() is not None, reason=str(missing_reason()))

STEPS = 300
TOL = 1e-7


@pytest.fixture(scope="module")
def x64():
    import jax

    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module")
def task(x64):
    import jax.numpy as jnp

    from adarl.device.hopper import HopperTask

    return HopperTask(dtype=jnp.float64)


def test_device_hopper_matches_gymnasium(task):
    import gymnasium
    import jax

    env = gymnasium.make("Hopper-v5").unwrapped
    env.reset(seed=0)
    step = jax.jit(task.step)
    rng = np.random.default_rng(0)
    key = jax.random.key(0)
    worst, episodes = 0.0, 1
    state = task.reset(key)
    env.set_state(np.asarray(state.data.qpos), np.asarray(state.data.qvel))
    np.testing.assert_allclose(env._get_obs(), np.asarray(task.observation(state.data)), atol=TOL)
    for _ in range(STEPS):
        action = rng.uniform(-1.0, 1.0, 3)
        obs, reward, terminated, truncated, _ = env.step(action)
        state, obs_d, reward_d, terminated_d, truncated_d = step(state, action)
        worst = max(worst, np.abs(obs - np.asarray(obs_d)).max(), abs(reward - float(reward_d)))
        assert bool(terminated_d) == terminated and not bool(truncated_d)
        if terminated:  # both restart from the device's next reset state
            key, sub = jax.random.split(key)
            state = task.reset(sub)
            env.set_state(np.asarray(state.data.qpos), np.asarray(state.data.qvel))
            episodes += 1
    assert worst < TOL, worst
    assert episodes > 3  # random actions: terminations were exercised


def test_device_hopper_reset_noise(task):
    import jax

    states = jax.vmap(task.reset)(jax.random.split(jax.random.key(1), 64))
    qpos = np.asarray(states.data.qpos)
    qvel = np.asarray(states.data.qvel)
    init = np.asarray(task.mj_model.qpos0)
    assert qpos.shape == (64, 6) and qpos.dtype == np.float64
    assert np.all(np.abs(qpos - init) <= 5e-3) and np.all(np.abs(qvel) <= 5e-3)
    assert np.abs(qpos - init).max() > 4e-3  # the noise spans its range
    again = jax.vmap(task.reset)(jax.random.split(jax.random.key(1), 64))
    np.testing.assert_array_equal(qpos, np.asarray(again.data.qpos))
