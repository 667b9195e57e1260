"""Task table, dynamics schedules and the one-line errors for bad input."""

import math

import numpy as np
import pytest

import adarl.envs.env as env_module
import adarl.envs.model as model_module
from adarl.envs import DynamicsSchedule, Sinusoid, get_task, list_tasks, make, parse_dynamics
from adarl.errors import UsageError

PAPER = {
    "hopper": {"torso_length": (0.4, 0.2, 0.2), "foot_length": (0.39, 0.2, 0.2)},
    "walker2d": {"torso_length": (0.2, 0.1, 0.3), "foot_length": (0.1, 0.05, 0.3)},
    "ant": {"gravity": (14.715, 4.905, 0.5), "wind": (1.0, 0.2, 0.5)},
    "humanoid": {"gravity": (14.715, 4.905, 0.5), "wind": (1.0, 0.5, 0.5)},
}


def test_task_table():
    assert list_tasks() == ["hopper", "walker2d", "ant", "humanoid"]
    ranks = {t: get_task(t).intrinsic_rank for t in list_tasks()}
    assert ranks == {"hopper": 7, "walker2d": 13, "ant": 17, "humanoid": 35}
    assert get_task("hopper").params["foot_length"] == 0.195
    assert get_task("walker2d").params["foot_length"] == 0.1
    assert get_task("ant").params["gravity"] == 9.81
    assert get_task("Hopper").name == "hopper"


@pytest.mark.parametrize("task", list(PAPER))
def test_paper_formulas(task):
    sched = parse_dynamics("paper", task)
    for i in (0, 1, 7, 123):
        params = sched.params_for_episode(i)
        for name, (c, a, f) in PAPER[task].items():
            assert params[name] == c + a * math.sin(f * i)
    assert set(params) == set(get_task(task).params)


def test_ompo_differs_only_in_hopper_amplitude():
    hop = parse_dynamics("ompo", "hopper").params_for_episode(3)
    assert hop["torso_length"] == 0.4 + 0.1 * math.sin(0.6)
    assert hop["foot_length"] == 0.39 + 0.1 * math.sin(0.6)
    for task in ("walker2d", "ant", "humanoid"):
        assert parse_dynamics("ompo", task).params_for_episode(5) == parse_dynamics(
            "paper", task
        ).params_for_episode(5)


@pytest.mark.parametrize("task", list(PAPER))
def test_nominal_equals_centroid(task):
    nominal = parse_dynamics("nominal", task)
    centroid = parse_dynamics("paper", task).centroid()
    assert not nominal.varies
    for i in (0, 4, 99):
        assert nominal.params_for_episode(i) == centroid
    for name, (c, _, _) in PAPER[task].items():
        assert centroid[name] == c


def test_fixed_and_overrides():
    sched = parse_dynamics("fixed:torso_length=0.5,foot_length=0.39", "hopper")
    assert sched.params_for_episode(10) == dict(get_task("hopper").params) | {
        "torso_length": 0.5,
        "foot_length": 0.39,
    }
    partial = parse_dynamics(" fixed: torso_length = 0.5 ", "hopper").params_for_episode(0)
    assert partial["foot_length"] == 0.195  # unspecified: Gymnasium default
    paper = parse_dynamics("paper:mass_scale=1.2", "ant")
    assert paper.params_for_episode(2)["mass_scale"] == 1.2
    assert paper.params_for_episode(2)["gravity"] == 14.715 + 4.905 * math.sin(1.0)
    # an override of a varying parameter freezes it; names round-trip through parse_dynamics
    frozen = parse_dynamics("paper", "hopper").with_overrides(torso_length=0.3)
    assert frozen.params_for_episode(9)["torso_length"] == 0.3
    assert parse_dynamics(frozen.name, "hopper") == frozen
    assert parse_dynamics("default", "hopper").params_for_episode(0) == dict(
        get_task("hopper").params
    )


def test_uniform_within_range_and_seeded():
    sched = parse_dynamics("uniform", "humanoid")
    low_high = {p: (c - a, c + a) for p, (c, a, _) in PAPER["humanoid"].items()}
    draws = [sched.params_for_episode(i, np.random.default_rng([5, i])) for i in range(200)]
    for name, (low, high) in low_high.items():
        values = np.array([d[name] for d in draws])
        assert values.min() >= low and values.max() <= high
        assert values.max() - values.min() > 0.8 * (high - low)  # spreads over the range
    again = [sched.params_for_episode(i, np.random.default_rng([5, i])) for i in range(200)]
    assert draws == again
    assert sched.params_for_episode(3) == sched.params_for_episode(3)  # rng=None: reproducible


def test_same_seed_same_parameter_sequence():
    def sequence(dynamics, seed):
        env = make("hopper", dynamics, seed=seed)
        out = [env.reset()[1]["dynamics"] for _ in range(4)]
        env.close()
        return out

    assert sequence("uniform", 3) == sequence("uniform", 3)
    assert sequence("uniform", 3) != sequence("uniform", 4)
    assert sequence("paper", 3) == sequence("paper", 4)  # paper depends on the index only


def test_schedule_built_in_code():
    sched = DynamicsSchedule(
        "walker2d",
        name="slow",
        sinusoids={"foot_length": Sinusoid(0.1, 0.02, 0.01)},
        constants={"stiffness": 5},
    )
    p = sched.params_for_episode(100)
    assert p["foot_length"] == 0.1 + 0.02 * math.sin(1.0)
    assert p["stiffness"] == 5.0 and p["torso_length"] == 0.2
    env = make("walker2d", sched, seed=0)
    assert env.reset()[1]["dynamics"] == sched.params_for_episode(0)
    env.close()


BAD = [
    (lambda: get_task("hoper"), "'hoper'", "hopper, walker2d"),
    (lambda: make("cheetah"), "'cheetah'", "hopper, walker2d, ant, humanoid"),
    (lambda: make("hopper", "papr"), "'papr'", "paper, ompo, nominal"),
    (
        lambda: make("hopper", "fixed:torso_lenght=0.5"),
        "'torso_lenght'",
        "torso_length, foot_length",
    ),
    (lambda: make("hopper", "paper", gravity=9.81), "'gravity'", "torso_length, foot_length"),
    (lambda: make("ant", "paper", stiffness=10.0), "'stiffness'", "gravity, wind"),
    (lambda: make("hopper", "fixed:torso_length=0"), "0", "a number > 0"),
    (lambda: make("walker2d", "nominal", foot_length=-0.1), "-0.1", "a number > 0"),
    (lambda: make("ant", "fixed:gravity=-9.81"), "-9.81", "a number >= 0"),
    (lambda: make("humanoid", "paper", mass_scale=-1.0), "-1.0", "a number > 0"),
    (lambda: make("hopper", "fixed:torso_length"), "'torso_length'", "NAME=VALUE"),
    (lambda: make("hopper", "fixed:torso_length=abc"), "'abc'", "a number > 0"),
    (lambda: make("hopper", "fixed:torso_length=0.5,,foot_length=0.3"), "''", "NAME=VALUE"),
    (lambda: make("hopper", "fixed:=0.5"), "'=0.5'", "NAME=VALUE"),
    (lambda: make("hopper", "fixed:foot_length=0.3,foot_length=0.4"), "'foot_length'", "once"),
    (lambda: make("hopper", "fixed:foot_length=nan"), "'nan'", "a number > 0"),
    (lambda: make("hopper", "default:mass_scale=2"), "default", "fixed:NAME=VALUE"),
    (lambda: make("hopper", "default", mass_scale=2.0), "default", "fixed:NAME=VALUE"),
    (lambda: make("hopper", parse_dynamics("paper", "ant")), "'ant'", "'hopper'"),
    (lambda: make("hopper", max_episode_steps=0), "0", "integer >= 1"),
    (lambda: make("hopper", seed=-1), "-1", "integer >= 0"),
    (lambda: parse_dynamics("uniform", "ant").params_for_episode(-1), "-1", "integer >= 0"),
    (
        lambda: DynamicsSchedule("hopper", sinusoids={"torso_length": Sinusoid(0.1, 0.2, 1.0)}),
        "-0.1",
        "a number > 0",
    ),
]


@pytest.mark.parametrize("call,bad,allowed", BAD)
def test_bad_input_one_line_before_any_model(call, bad, allowed, monkeypatch):
    def no_model(*args, **kwargs):
        raise AssertionError("a model was built before the input was checked")

    monkeypatch.setattr(env_module, "load_env_creator", no_model)
    monkeypatch.setattr(model_module.mujoco.MjSpec, "from_file", no_model)
    with pytest.raises(UsageError) as exc:
        call()
    message = str(exc.value)
    assert "\n" not in message
    assert bad in message and allowed in message and "allowed" in message
