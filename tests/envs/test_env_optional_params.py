"""Optional parameters (body masses, floor friction: the M2TD3 / RRLS uncertainty sets) reach the
compiled model under both physics, stay out of schedules that do not set them, and are checked."""

import numpy as np
import pytest

from adarl.envs import get_task, make, parse_dynamics
from adarl.errors import UsageError

mujoco = pytest.importorskip("mujoco")
from adarl.envs.model import BODY_MASSES, FLOOR_GEOM, compile_model  # noqa: E402

PHYSICS = ("consistent", "ompo")


@pytest.mark.parametrize("version", ["v5", "v4"])
@pytest.mark.parametrize("task", ["hopper", "walker2d", "ant"])
def test_defaults_are_gymnasiums_values(task, version):
    spec = get_task(task, version)
    model = compile_model(task, version=version)
    for name, default in spec.optional_params.items():
        if name == "floor_friction":
            assert model.geom_friction[model.geom(FLOOR_GEOM).id, 0] == default
        else:
            assert model.body_mass[model.body(BODY_MASSES[name]).id] == default


@pytest.mark.parametrize("physics", PHYSICS)
def test_mass_overrides_change_only_that_bodys_mass(physics):
    default = compile_model("hopper", physics=physics)
    model = compile_model("hopper", {"torso_mass": 0.5, "thigh_mass": 2.5}, physics=physics)
    torso, thigh = model.body("torso").id, model.body("thigh").id
    assert model.body_mass[torso] == 0.5 and model.body_mass[thigh] == 2.5
    others = np.ones(model.nbody, bool)
    others[[torso, thigh]] = False
    np.testing.assert_array_equal(model.body_mass[others], default.body_mass[others])
    # inertia kept, as M2TD3 and RRLS write body_mass alone
    np.testing.assert_array_equal(model.body_inertia, default.body_inertia)


@pytest.mark.parametrize("physics", PHYSICS)
def test_ant_leg_masses(physics):
    model = compile_model(
        "ant", {"front_left_leg_mass": 0.01, "front_right_leg_mass": 3.0}, physics=physics
    )
    assert model.body_mass[model.body("front_left_leg").id] == 0.01
    assert model.body_mass[model.body("front_right_leg").id] == 3.0


@pytest.mark.parametrize("physics", PHYSICS)
def test_floor_friction_sets_the_floor_geoms_sliding_friction(physics):
    default = compile_model("walker2d", physics=physics)
    model = compile_model("walker2d", {"floor_friction": 3.5}, physics=physics)
    floor = model.geom(FLOOR_GEOM).id
    assert model.geom_friction[floor, 0] == 3.5
    np.testing.assert_array_equal(model.geom_friction[floor, 1:], default.geom_friction[floor, 1:])
    rest = np.arange(model.ngeom) != floor
    np.testing.assert_array_equal(model.geom_friction[rest], default.geom_friction[rest])
    # on top of friction_scale: the floor's value is absolute, the others scaled
    both = compile_model(
        "walker2d", {"floor_friction": 3.5, "friction_scale": 2.0}, physics=physics
    )
    assert both.geom_friction[floor, 0] == 3.5
    np.testing.assert_allclose(both.geom_friction[rest], 2 * default.geom_friction[rest])


@pytest.mark.parametrize("physics", PHYSICS)
def test_the_env_applies_them_and_reverts_between_episodes(physics):
    env = make("hopper", "fixed:torso_mass=0.5,floor_friction=0.1", physics=physics)
    _, info = env.reset()
    model = env.unwrapped.model
    assert info["dynamics"]["torso_mass"] == 0.5 and info["dynamics"]["floor_friction"] == 0.1
    assert model.body_mass[model.body("torso").id] == 0.5
    assert model.geom_friction[model.geom(FLOOR_GEOM).id, 0] == 0.1
    env.close()
    env = make("hopper", "fixed", physics=physics)
    _, info = env.reset()
    model = env.unwrapped.model
    assert "torso_mass" not in info["dynamics"]  # not set: not part of the schedule or logs
    assert (
        model.body_mass[model.body("torso").id] == get_task("hopper").optional_params["torso_mass"]
    )
    env.close()


def test_schedules_without_them_keep_their_parameters():
    for task in ("hopper", "walker2d", "ant", "humanoid"):
        assert list(parse_dynamics("paper", task).params_for_episode(0)) == list(
            get_task(task).params
        )


@pytest.mark.parametrize(
    "task, dynamics, fragment",
    [
        ("humanoid", "fixed:torso_mass=3", "unknown humanoid parameter 'torso_mass'"),
        ("hopper", "fixed:torso_mass=0", "bad value"),
        ("hopper", "fixed:torso_mass=0.01", "implausible value 0.01 for torso_mass"),
        ("ant", "nominal:front_left_leg_mass=5", "implausible value 5"),
        ("walker2d", "fixed:floor_friction=-1", "bad value"),
        ("hopper", "default:torso_mass=1", "takes no values"),
    ],
)
def test_bad_values_are_one_line_errors(task, dynamics, fragment):
    with pytest.raises(UsageError, match=fragment) as err:
        parse_dynamics(dynamics, task)
    assert "\n" not in str(err.value)


def test_they_cannot_vary():
    from adarl.envs import DynamicsSchedule, Sinusoid

    with pytest.raises(UsageError, match="'torso_mass' cannot vary"):
        DynamicsSchedule("hopper", sinusoids={"torso_mass": Sinusoid(1.0, 0.5, 0.1)})


def test_one_builder_reverts_them_when_no_longer_set():
    from adarl.envs.model import ModelBuilder

    builder = ModelBuilder("hopper", textures=False)
    base = dict(get_task("hopper").params)
    builder.compile(base | {"floor_friction": 0.1, "torso_mass": 0.5})
    again = builder.compile(base)
    fresh = compile_model("hopper")
    np.testing.assert_array_equal(again.geom_friction, fresh.geom_friction)
    np.testing.assert_array_equal(again.body_mass, fresh.body_mass)
