"""The task contract (adarl.envs.contract), one suite over every task kind: the paper's tasks,
a generic Gymnasium MuJoCo task, a user's own robot (its XML written here, its env class
registered by tests/user_env.py) and a plain Gymnasium env. Expected values come from MuJoCo's
compiled models and Gymnasium's registry, not from the code under test."""

import gymnasium
import mujoco
import numpy as np
import pytest
import user_env

from adarl.envs import get_task, make, parse_dynamics
from adarl.envs.contract import Task
from adarl.errors import UsageError


@pytest.fixture
def xml(tmp_path):
    return str(user_env.write_xml(tmp_path))


def kinds(xml):
    """(name, make kwargs, a parameter that varies) of each task kind."""
    return {
        "paper": ("hopper", {"dynamics": "paper"}, "torso_length"),
        "generic": (
            "HalfCheetah-v5",
            {"dynamics": "uniform:body:torso.mass=4..9,joint:bthigh.damping=3..9"},
            "body:torso.mass",
        ),
        "user-xml": (
            user_env.ENV_ID,
            {"dynamics": "uniform:geom:floor.friction=0.3..1.5", "env_kwargs": f"xml_file={xml}"},
            "geom:floor.friction",
        ),
        "plain": ("Pendulum-v1", {"dynamics": "default"}, None),
    }


KINDS = ("paper", "generic", "user-xml", "plain")


@pytest.mark.parametrize("kind", KINDS)
def test_every_task_kind_keeps_the_contract(kind, xml):
    name, kwargs, varied = kinds(xml)[kind]
    env = make(name, seed=3, **kwargs)
    assert isinstance(env, Task)
    assert env.dynamics_params is None or kind == "plain"
    seen = []
    for episode in range(3):
        obs, info = env.reset()
        assert info["episode_index"] == episode == env.episode_index
        assert info["dynamics"] == (env.dynamics_params or {})
        assert env.observation_space.contains(obs.astype(env.observation_space.dtype))
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert info["episode_index"] == episode and np.isfinite(reward)
        seen.append(dict(info["dynamics"]))
    if varied:  # the varied parameter changes from episode to episode
        assert len({round(d[varied], 12) for d in seen}) == 3
    else:
        assert seen == [{}] * 3
    env.close()


@pytest.mark.parametrize("kind", KINDS)
def test_a_task_restored_from_get_state_continues_bit_for_bit(kind, xml):
    name, kwargs, _ = kinds(xml)[kind]
    rng = np.random.default_rng(0)
    env = make(name, seed=5, **kwargs)
    low, high = env.action_space.low, env.action_space.high
    actions = [rng.uniform(low, high).astype(env.action_space.dtype) for _ in range(40)]
    env.reset()
    for a in actions[:15]:
        env.step(a)
    state = env.get_state()
    rest = [env.step(a) for a in actions[15:]] + [env.reset()]
    fresh = make(name, seed=99, **kwargs)  # another seed: everything must come from the state
    fresh.reset()
    fresh.set_state(state)
    again = [fresh.step(a) for a in actions[15:]] + [fresh.reset()]
    for one, other in zip(rest, again):  # steps, then the next episode's reset
        np.testing.assert_array_equal(one[0], other[0])
        if len(one) == 5:
            assert one[1:4] == other[1:4]  # reward, terminated, truncated
        else:
            assert one[1]["dynamics"] == other[1]["dynamics"]


def test_a_generic_task_at_its_defaults_is_gymnasiums_model():
    env = make("HalfCheetah-v5", "nominal", seed=0)
    env.reset()
    ours, theirs = env.unwrapped.model, gymnasium.make("HalfCheetah-v5").unwrapped.model
    for field in ("body_mass", "body_inertia", "geom_friction", "dof_damping", "actuator_gear"):
        np.testing.assert_allclose(getattr(ours, field), getattr(theirs, field), rtol=1e-12)
    # HalfCheetah's settotalmass (14 kg) survives as the densities it stands for
    assert ours.body_mass.sum() == pytest.approx(14.0, rel=1e-12)


def test_generic_and_addressed_parameters_reach_the_compiled_model(xml):
    env = make(
        user_env.ENV_ID,
        "fixed:mass_scale=2,body:ball.mass=3,joint:slide_x.damping=2.5,actuator:push_y.gear=7,"
        "geom:floor.friction[1]=0.02,gravity=5,damping_scale=3",
        seed=0,
        env_kwargs=f"xml_file={xml}",
    )
    env.reset()
    m = env.unwrapped.model
    assert m.body("ball").mass[0] == pytest.approx(3.0)  # absolute: mass_scale does not act on it
    assert m.dof_damping[m.joint("slide_x").dofadr[0]] == 2.5  # absolute
    assert m.dof_damping[m.joint("slide_y").dofadr[0]] == pytest.approx(1.5)  # 0.5 x damping_scale
    assert m.actuator_gear[m.actuator("push_y").id, 0] == 7.0
    assert m.actuator_gear[m.actuator("push_x").id, 0] == 5.0
    assert m.geom_friction[m.geom("floor").id, 1] == 0.02
    np.testing.assert_allclose(m.opt.gravity, [0, 0, -5.0])
    # the inertia follows the mass (a solid sphere: 2/5 m r^2)
    np.testing.assert_allclose(m.body_inertia[m.body("ball").id], 0.4 * 3.0 * 0.1**2, rtol=1e-9)


def test_a_fromto_capsule_stretches_about_its_centre():
    env = make("HalfCheetah-v5", "fixed:geom:torso.size[1]=0.7", seed=0)
    env.reset()
    m = env.unwrapped.model
    base = mujoco.MjModel.from_xml_path(get_task("HalfCheetah-v5").xml_path)
    g = m.geom("torso").id
    assert m.geom_size[g, 1] == pytest.approx(0.7)
    np.testing.assert_allclose(m.geom_pos[g], base.geom_pos[g], atol=1e-12)
    assert m.body_mass[m.body("torso").id] > base.body_mass[base.body("torso").id]  # mass followed


@pytest.mark.parametrize(
    "dynamics, message",
    [
        ("fixed:body:nosuch.mass=1", "unknown body 'nosuch'"),
        ("fixed:joint:bthigh.color=1", "unknown attribute 'color'"),
        ("fixed:geom:torso.size[5]=1", r"bad index \[5\]"),
        ("fixed:body:torso.mass=-1", "bad value"),
        ("fixed:body:torso.mass=1e6", "implausible value"),
        ("fixed:torso_length=0.3", "unknown HalfCheetah-v5 parameter 'torso_length'"),
        ("nominal:mass_scale=0.8..1.2", "allowed: a range in paper, ompo or uniform"),
        ("uniform:mass_scale=1.2..0.8", "bad range"),
        # a sweep's grid given to training: the form it takes (issue 62)
        ("uniform:mass_scale=0.8:1.2:9", "allowed: mass_scale=VALUE, or mass_scale=LOW..HIGH"),
        ("uniform:body:torso.mass=4..9:5", "(e.g. body:torso.mass=4..9)"),
    ],
)
def test_bad_parameters_are_one_line_errors(dynamics, message):
    with pytest.raises(UsageError, match=message) as info:
        make("HalfCheetah-v5", dynamics, seed=0)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "task, message",
    [
        ("CartPole-v1", "has actions Discrete"),
        ("NoSuchEnv-v0", "unknown task 'NoSuchEnv-v0'"),
        ("nosuch", "unknown task 'nosuch'"),
    ],
)
def test_tasks_adarl_cannot_train_are_one_line_errors(task, message):
    with pytest.raises(UsageError, match=message) as info:
        make(task, "default", seed=0)
    assert "\n" not in str(info.value)


def test_a_gymnasium_id_takes_its_registered_time_limit():
    assert (
        get_task("Reacher-v5").max_episode_steps
        == gymnasium.spec("Reacher-v5").max_episode_steps
        == 50
    )
    assert get_task("hopper").max_episode_steps == 1000
    env = make("Reacher-v5", "nominal", seed=0)
    env.reset()
    steps = 0
    while True:
        steps += 1
        *_, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            break
    assert steps == 50


def test_a_plain_env_without_a_state_array_refuses_set_state():
    env = make("Pendulum-v1", "default", seed=0)
    env.reset()
    state = env.get_state()
    del state["state"]
    state["uncapturable"] = "MyEnv keeps its state outside a `state` array"
    with pytest.raises(UsageError, match="cannot resume this run exactly.*MyEnv"):
        env.set_state(state)


def _episodes(task, dynamics, n=6, **kwargs):
    """The parameters of `n` episodes of `make(task, dynamics)`, as the env reports them."""
    env = make(task, dynamics, seed=4, **kwargs)
    seen = [dict(env.reset()[1]["dynamics"]) for _ in range(n)]
    env.close()
    return seen


def _varied(episodes) -> set[str]:
    return {p for p in episodes[0] if len({round(e[p], 12) for e in episodes}) > 1}


def test_a_range_varies_what_it_names_and_nothing_else(xml):
    """Issue 62: on a task outside the paper's four, a spec that gives a range varies only the
    ranges it gives; the generic scales stay at 1 unless named. Plain `uniform` and `paper`
    (no items) are the generic schedule, as before, and a value alone keeps it."""
    user = {"env_kwargs": f"xml_file={xml}"}
    named = _episodes(user_env.ENV_ID, "uniform:body:ball.mass=0.5..2", **user)
    assert _varied(named) == {"body:ball.mass"}
    assert all(e["mass_scale"] == 1.0 and e["friction_scale"] == 1.0 for e in named)
    assert all(0.5 <= e["body:ball.mass"] <= 2 for e in named)
    generic = _episodes(user_env.ENV_ID, "paper:mass_scale=0.5..1.5", **user)
    assert _varied(generic) == {"mass_scale"}
    # naming a generic scale with the range: both vary, the other scale stays at 1
    both = _episodes(
        user_env.ENV_ID, "uniform:friction_scale=0.9..1.1,body:ball.mass=0.5..2", **user
    )
    assert _varied(both) == {"friction_scale", "body:ball.mass"}
    # no range given: the generic schedule, mass_scale and friction_scale in [0.8, 1.2]
    for spec in ("uniform", "paper", "ompo", "uniform:gravity=5", "paper:body:ball.mass=3"):
        episodes = _episodes(user_env.ENV_ID, spec, **user)
        assert _varied(episodes) == {"mass_scale", "friction_scale"}, spec
        assert all(0.8 <= e["mass_scale"] <= 1.2 for e in episodes)
    # keyword overrides follow the same rule, and the name parses back to the same schedule
    kw = _episodes("HalfCheetah-v5", "uniform", **{"body:torso.mass": "4..9"})
    assert _varied(kw) == {"body:torso.mass"}
    task = get_task("HalfCheetah-v5")
    chained = parse_dynamics("uniform:mass_scale=1.1", task).with_overrides(
        **{"body:torso.mass": "4..9"}
    )
    assert parse_dynamics(chained.name, task) == chained and not chained.sinusoids.keys() - {
        "body:torso.mass"
    }
    # the paper's four tasks keep their schedules under a range: the paper's parameters vary too
    hopper = _episodes("hopper", "uniform:body:torso.mass=3..5")
    assert _varied(hopper) == {"torso_length", "foot_length", "body:torso.mass"}
