"""The device chunk's time limit and uniform exploration (`adarl.algos.sac_device`), on a task
written here in plain JAX that never terminates, so that no MJX model is compiled: every
episode must end after exactly `max_episode_steps` steps (Gymnasium's TimeLimit, as the host
backend's), a deterministic evaluation must run exactly `max_steps`, and exactly the first
`start_steps` actions must be uniform draws, re-drawn here from the chunk's documented keys."""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import registry, replay, sac, sac_device

OBS, ACT, SEEDS = 3, 2, (0, 1)
LOW, HIGH = np.array([-1.0, -0.5]), np.array([1.0, 2.0])


class Position(NamedTuple):
    data: jax.Array  # the step count since the reset, plus the reset's offset
    fields: dict


class EndlessTask:
    """Never terminates; the observation is the position, moved by 1 each step."""

    def reset(self, key, fields=None):
        return Position(jax.random.uniform(key, ()), {} if fields is None else dict(fields))

    def observation(self, data):
        return jnp.stack([data, 2 * data, jnp.ones(())])

    def step(self, state, action):
        data = state.data + 1.0
        reward = jnp.sum(action) + 0.0 * data
        return Position(data, state.fields), self.observation(data), reward, False, False


def setup(**fields):
    values = {"hidden": (8, 8), "buffer_size": 64, "batch_size": 8, "update_every": 1}
    config = registry.resolve_config("sac", "smoke", values | fields)
    spec = sac.make_spec(config, OBS, ACT, LOW, HIGH)
    states = [sac.init_state(spec, s, with_buffer=False) for s in SEEDS]
    state = jax.tree_util.tree_map(lambda *a: np.stack(a), *states)
    state["buffer"] = replay.empty_buffers(len(SEEDS), config.buffer_size, OBS, ACT)
    task = EndlessTask()
    keys = np.stack([sac_device.env_key(s) for s in SEEDS])
    envs = jax.vmap(functools.partial(sac_device.init_env, task), in_axes=(0, None))(keys, {})
    return spec, task, state, envs


LIMIT, START, STEPS = 3, 3, 7  # episodes end at steps 3 and 6; steps 1-3 explore uniformly


@pytest.fixture(scope="module")
def chunked():
    """One chunk of 7 steps from the start of training, compiled once for the tests below."""
    spec, task, state, envs = setup(max_episode_steps=LIMIT, start_steps=START)
    keys = np.asarray(envs["key"])
    chunk = jax.jit(functools.partial(sac_device.chunk, spec, task, STEPS))
    state, envs, ended, _ = chunk(state, envs, {}, np.int32(0), np.bool_(False))
    return spec, keys, state, envs, tuple(np.asarray(x) for x in ended)


def test_every_device_episode_ends_after_exactly_max_episode_steps(chunked):
    _, _, _, envs, (done, _, lengths, episode) = chunked
    for i in range(len(SEEDS)):
        ends = np.flatnonzero(done[i]) + 1  # 1-based steps at which an episode ended
        assert list(ends) == [3, 6]
        assert list(lengths[i][done[i]]) == [LIMIT, LIMIT]
        assert list(episode[i][done[i]]) == [0, 1]
    assert list(np.asarray(envs["episode"])) == [2] * len(SEEDS)
    assert list(np.asarray(envs["ep_length"])) == [1] * len(SEEDS)


def test_a_device_evaluation_runs_exactly_max_steps():
    spec, task, state, _ = setup()
    keys = np.stack([sac_device.eval_key(s) for s in SEEDS])
    evaluate = jax.jit(functools.partial(sac_device.evaluate, spec, task, 5, 2))
    returns, lengths = evaluate(state["actor"], state["masks"]["actor"], keys, {})
    np.testing.assert_array_equal(np.asarray(lengths), np.full((len(SEEDS), 2), 5))


def test_exactly_the_first_start_steps_actions_are_uniform(chunked):
    spec, keys0, state, _, (done, *_) = chunked
    acts = np.asarray(state["buffer"]["act"])
    obs = np.asarray(state["buffer"]["obs"])
    low, high = jnp.asarray(LOW, jnp.float32), jnp.asarray(HIGH, jnp.float32)
    for i in range(len(SEEDS)):
        actor = jax.tree_util.tree_map(lambda a, i=i: a[i], state["actor"])
        masks = jax.tree_util.tree_map(lambda a, i=i: a[i], state["masks"]["actor"])
        key = jax.random.split(keys0[i])[0]  # the chunk's: the first half is the action stream
        row = 0  # step t's transition row: a step writes 2 rows, 3 where its episode ends
        for t in range(1, STEPS + 1):
            key, k_act = jax.random.split(key)
            uniform = np.asarray(jax.random.uniform(k_act, (ACT,), jnp.float32, low, high))
            if t <= START:
                np.testing.assert_array_equal(acts[i, row], uniform, f"seed {i} step {t}")
            else:
                sampled, _ = sac.sample_action(spec, actor, masks, obs[i, row][None], k_act)
                np.testing.assert_allclose(acts[i, row], np.asarray(sampled[0]), rtol=1e-6)
                assert not np.array_equal(acts[i, row], uniform)
            row += 1 + int(done[i, t - 1])
