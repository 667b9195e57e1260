"""Plain Gymnasium envs as tasks (adarl.envs.plain): the time limit, resume and resets a user
would get from Gymnasium itself, checked against Gymnasium's own env and registry."""

import gymnasium
import numpy as np

from adarl.envs import make

TASK = "Pendulum-v1"  # classic control: its `state` array is captured, so it resumes


def steps_to_truncation(env, limit=10_000):
    for steps in range(1, limit + 1):
        *_, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape, np.float32))
        assert not terminated
        if truncated:
            return steps
    raise AssertionError("never truncated")


def test_a_plain_env_runs_exactly_its_registered_time_limit():
    limit = gymnasium.spec(TASK).max_episode_steps  # 200
    env = make(TASK, "default", seed=0)
    for _ in range(2):  # the limit restarts with every episode
        env.reset()
        assert steps_to_truncation(env) == limit
    short = make(TASK, "default", seed=0, max_episode_steps=7)
    short.reset()
    assert steps_to_truncation(short) == 7


def test_a_plain_env_resumed_mid_episode_keeps_its_time_limit():
    limit = gymnasium.spec(TASK).max_episode_steps
    env = make(TASK, "default", seed=1)
    env.reset()
    for _ in range(150):
        env.step(np.zeros(1, np.float32))
    state = env.get_state()
    fresh = make(TASK, "default", seed=9)
    fresh.reset()
    fresh.set_state(state)
    assert steps_to_truncation(fresh) == limit - 150 == steps_to_truncation(env)


def test_plain_episodes_start_where_gymnasiums_env_would():
    """Seeded once, then every reset continues the env's RNG: each episode starts elsewhere."""
    env = make(TASK, "default", seed=3)
    reference = gymnasium.make(TASK).unwrapped
    starts = [env.reset()[0] for _ in range(4)]
    expected = [reference.reset(seed=3)[0]] + [reference.reset()[0] for _ in range(3)]
    for got, want in zip(starts, expected):
        np.testing.assert_array_equal(got, want)
    assert len({tuple(np.round(s, 12)) for s in starts}) == 4
