"""The env wrapper: info, episode index, caching, time limit, state round trip, vector form."""

import copy
import json

import gymnasium
import numpy as np
import pytest

from adarl.envs import get_task, make, make_vec, parse_dynamics
from adarl.errors import UsageError


def actions(env, n, seed=0):
    space = env.action_space
    rng = np.random.default_rng(seed)
    return rng.uniform(space.low, space.high, size=(n, *space.shape)).astype(space.dtype)


def rollout(env, acts):
    """Step through `acts`, resetting after episode ends; returns every transition."""
    out = []
    for a in acts:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append(
            (obs, reward, terminated, truncated, dict(info["dynamics"]), info["episode_index"])
        )
        if terminated or truncated:
            obs, info = env.reset()
            out.append((obs, info["dynamics"], info["episode_index"]))
    return out


def assert_identical(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert len(x) == len(y)
        for u, v in zip(x, y):
            if isinstance(u, np.ndarray):
                assert u.dtype == v.dtype and np.array_equal(u, v)
            else:
                assert u == v


@pytest.mark.parametrize("task", ["hopper", "walker2d", "ant", "humanoid"])
def test_spaces_and_info(task):
    spec = get_task(task)
    env = make(task, "paper", seed=0)
    assert env.observation_space.shape == (spec.obs_dim,)
    assert env.action_space.shape == (spec.act_dim,)
    obs, info = env.reset()
    assert obs.shape == (spec.obs_dim,)
    assert info["episode_index"] == 0
    assert info["dynamics"] == parse_dynamics("paper", task).params_for_episode(0)
    _, _, _, _, info = env.step(env.action_space.sample())
    assert info["episode_index"] == 0 and info["dynamics"] == env.dynamics_params
    assert env.spec.max_episode_steps == 1000
    env.close()


def test_episode_index_advances_and_can_be_set():
    env = make("walker2d", "paper", seed=0)
    sched = parse_dynamics("paper", "walker2d")
    assert [env.reset()[1]["episode_index"] for _ in range(3)] == [0, 1, 2]
    assert env.episode_index == 2
    env.episode_index = 40
    assert env.episode_index == 40
    _, info = env.reset()
    assert info["episode_index"] == 40 and env.dynamics_params == sched.params_for_episode(40)
    assert env.reset()[1]["episode_index"] == 41
    with pytest.raises(UsageError):
        env.episode_index = -3
    env.close()


def test_compiles_once_per_change():
    nominal = make("hopper", "nominal", seed=0)
    for _ in range(4):
        nominal.reset()
    model = nominal.unwrapped.model
    nominal.reset()
    assert nominal.compiles == 1 and nominal.unwrapped.model is model
    paper = make("hopper", "paper", seed=0)
    for _ in range(4):
        paper.reset()
    assert paper.compiles == 4
    default = make("hopper", "default", seed=0)
    default.reset()
    assert default.compiles == 0


def test_time_limit():
    env = make("ant", "nominal", seed=0, max_episode_steps=3)
    env.reset()
    flags = [env.step(np.zeros(8))[3] for _ in range(3)]
    assert flags == [False, False, True]
    assert env.spec.max_episode_steps == 3


@pytest.mark.parametrize(
    "task,dynamics", [("hopper", "default"), ("ant", "default"), ("hopper", "fixed")]
)
def test_matches_plain_gymnasium(task, dynamics):
    """`default` (and, on Hopper, `fixed` at the defaults: no air) is Gymnasium's env bit for bit."""
    ours = make(task, dynamics, seed=7)
    plain = gymnasium.make(get_task(task).gym_id)
    o1, _ = ours.reset()
    o2, _ = plain.reset(seed=7)
    assert np.array_equal(o1, o2)
    for a in actions(ours, 40):
        r1, r2 = ours.step(a), plain.step(a)
        assert np.array_equal(r1[0], r2[0]) and r1[1:4] == r2[1:4]
        if r1[2]:
            break


@pytest.mark.parametrize(
    "task,dynamics,warmup",
    [
        ("hopper", "paper", 30),
        ("walker2d", "uniform", 25),
        ("ant", "uniform", 20),
        ("humanoid", "paper", 15),
    ],
)
def test_state_round_trip_is_bit_exact(task, dynamics, warmup):
    a = make(task, dynamics, seed=3, max_episode_steps=40)  # truncations test the step count too
    a.reset()
    acts = actions(a, warmup + 80, seed=1)
    rollout(a, acts[:warmup])
    # through JSON (arrays as lists), as a checkpoint stores it
    state = json.loads(json.dumps(a.get_state(), default=np.ndarray.tolist))
    # a different seed, never reset: the state alone decides what follows
    b = make(task, dynamics, seed=11, max_episode_steps=40)
    b.set_state(copy.deepcopy(state))
    assert b.episode_index == a.episode_index and b.dynamics_params == a.dynamics_params
    after_a, after_b = rollout(a, acts[warmup:]), rollout(b, acts[warmup:])
    assert_identical(after_a, after_b)
    resets = sum(len(t) == 3 for t in after_a)
    assert resets >= 1  # a reset (and a recompile) happened after restoring


def test_state_rejects_other_task():
    state = make("hopper", "paper").get_state()
    with pytest.raises(UsageError, match="hopper"):
        make("walker2d", "paper").set_state(state)


def test_make_vec():
    vec = make_vec("hopper", "uniform", seeds=[0, 1, 2], mass_scale=1.1)
    obs, info = vec.reset()
    assert obs.shape == (3, 11)
    assert list(info["episode_index"]) == [0, 0, 0]
    assert np.all(info["dynamics"]["mass_scale"] == 1.1)
    assert len(set(info["dynamics"]["torso_length"])) == 3  # one draw per seed
    single = make("hopper", "uniform", seed=1, mass_scale=1.1)
    assert single.reset()[1]["dynamics"]["torso_length"] == info["dynamics"]["torso_length"][1]
    for _ in range(5):
        obs, reward, terminated, truncated, info = vec.step(vec.action_space.sample())
    assert reward.shape == (3,) and list(vec.get_attr("episode_index")) == [0, 0, 0]
    vec.close()


def test_state_before_first_reset():
    a = make("hopper", "uniform", seed=5)
    b = make("hopper", "uniform", seed=6)
    b.set_state(a.get_state())
    (o1, i1), (o2, i2) = a.reset(), b.reset()
    assert np.array_equal(o1, o2) and i1["dynamics"] == i2["dynamics"]
