"""Physics of the compiled models: geometry, masses, contacts, gravity, wind, generic params."""

import math

import mujoco
import numpy as np
import pytest
from gymnasium.envs.mujoco.mujoco_env import expand_model_path

from adarl.envs import get_task, make
from adarl.envs.model import XML_FILES, ModelBuilder, compile_model

TORSO_RADIUS, DENSITY = 0.05, 1000.0


def capsule_mass(radius, half_length, density=DENSITY):
    """ρ·(π r²·2h + 4/3 π r³)."""
    return density * (math.pi * radius**2 * 2 * half_length + 4 / 3 * math.pi * radius**3)


def lowest_point(model, data, geom):
    """Lowest z of a capsule/sphere geom: centre z - (radius + half-length·|axis_z|)."""
    axis_z = data.geom_xmat[geom].reshape(3, 3)[2, 2]
    half = (
        model.geom_size[geom][1] if model.geom_type[geom] == mujoco.mjtGeom.mjGEOM_CAPSULE else 0.0
    )
    return data.geom_xpos[geom][2] - model.geom_size[geom][0] - half * abs(axis_z)


def contacts_between(model, data, geom_a, geom_b):
    pairs = {(c.geom1, c.geom2) for c in data.contact[: data.ncon]}
    return sum(pair in {(geom_a, geom_b), (geom_b, geom_a)} for pair in pairs)


@pytest.mark.parametrize("task", ["hopper", "walker2d"])
def test_torso_mass_grows_with_length(task):
    builder = ModelBuilder(task, textures=False)
    defaults = dict(get_task(task).params)
    masses = []
    for length in (0.1, 0.2, 0.4, 0.6):
        model = builder.compile(defaults | {"torso_length": length})
        torso = model.body("torso").id
        masses.append(model.body_mass[torso])
        assert model.body_mass[torso] == pytest.approx(capsule_mass(TORSO_RADIUS, length), rel=1e-9)
        assert model.geom_rbound[model.geom("torso_geom").id] == pytest.approx(
            TORSO_RADIUS + length
        )
    assert np.all(np.diff(masses) > 0)


def test_torso_matches_independently_recompiled_xml():
    """Ours equals compiling Gymnasium's XML with the torso edited as text."""
    ours = compile_model("hopper", {"torso_length": 0.5, "foot_length": 0.39})
    xml = open(expand_model_path(XML_FILES["hopper"])).read()
    xml = (
        xml.replace('<body name="torso" pos="0 0 1.25">', '<body name="torso" pos="0 0 1.55">')
        .replace(
            'name="torso_geom" size="0.05 0.19999999999999996"', 'name="torso_geom" size="0.05 0.5"'
        )
        .replace(
            '<body name="thigh" pos="0 0 -0.19999999999999996">',
            '<body name="thigh" pos="0 0 -0.5">',
        )
        .replace('name="foot_geom" size="0.06 0.195"', 'name="foot_geom" size="0.06 0.39"')
        .replace('pos="0 0 -1.25"', 'pos="0 0 -1.55"')  # root slides stay at the origin
    )
    ref = mujoco.MjModel.from_xml_string(xml)
    for field in (
        "body_mass",
        "body_inertia",
        "body_pos",
        "geom_size",
        "geom_rbound",
        "qpos0",
        "jnt_pos",
    ):
        np.testing.assert_allclose(
            getattr(ours, field), getattr(ref, field), rtol=1e-12, err_msg=field
        )
    assert ours.body_mass[ours.body("torso").id] == pytest.approx(8.38, abs=0.01)


def test_tilted_long_foot_touches_floor():
    """A tilted foot a few mm into the floor has a contact once recompiled (stale rbound: none)."""
    foot_length, depth = 0.5, 0.003
    ours = compile_model("hopper", {"foot_length": foot_length})
    stale = mujoco.MjModel.from_xml_path(expand_model_path(XML_FILES["hopper"]))
    stale.geom_size[stale.geom("foot_geom").id][1] = foot_length  # OMPO's in-place edit
    floor, foot = ours.geom("floor").id, ours.geom("foot_geom").id
    data = mujoco.MjData(ours)
    data.qpos[:] = ours.qpos0
    data.qpos[ours.joint("foot_joint").qposadr[0]] = math.radians(25)
    mujoco.mj_kinematics(ours, data)
    data.qpos[ours.joint("rootz").qposadr[0]] -= lowest_point(ours, data, foot) + depth
    mujoco.mj_forward(ours, data)
    assert lowest_point(ours, data, foot) == pytest.approx(-depth)
    # the case the issue names: the foot centre is higher than the stale bounding radius reaches
    assert data.geom_xpos[foot][2] > stale.geom_rbound[foot] + stale.geom_margin[foot]
    assert contacts_between(ours, data, floor, foot) >= 1
    stale_data = mujoco.MjData(stale)
    stale_data.qpos[:] = data.qpos
    mujoco.mj_forward(stale, stale_data)
    assert contacts_between(stale, stale_data, floor, foot) == 0


@pytest.mark.parametrize("task", ["hopper", "walker2d"])
@pytest.mark.parametrize("torso", [0.05, 1.0])
@pytest.mark.parametrize("foot", [0.02, 1.0])
def test_stands_on_floor_and_stays_connected(task, torso, foot):
    env = make(task, f"fixed:torso_length={torso},foot_length={foot}", seed=0)
    env.reset()
    model, data = env.unwrapped.model, env.unwrapped.data
    robot = [g for g in range(model.ngeom) if model.geom_bodyid[g] != 0]
    lowest = min(lowest_point(model, data, g) for g in robot)
    assert -0.005 < lowest < 0.06  # Gymnasium's own hopper starts 4 cm up
    torso_id = model.body("torso").id
    for thigh in ("thigh", "thigh_left") if task == "walker2d" else ("thigh",):
        gap = np.linalg.norm(data.xpos[model.body(thigh).id] - data.xpos[torso_id])
        assert gap == pytest.approx(torso, abs=1e-3)  # hip at the torso's lower end
    feet = ("foot_geom", "foot_left_geom") if task == "walker2d" else ("foot_geom",)
    for name in feet:
        assert model.geom_size[model.geom(name).id][1] == foot
    env.close()


def test_defaults_compile_to_gymnasiums_model():
    for task in ("hopper", "walker2d", "ant", "humanoid"):
        ours = compile_model(task)
        ref = mujoco.MjModel.from_xml_path(expand_model_path(XML_FILES[task]))
        for field in (
            "body_mass",
            "body_inertia",
            "body_pos",
            "geom_size",
            "geom_rbound",
            "geom_friction",
            "dof_damping",
        ):
            assert np.array_equal(getattr(ours, field), getattr(ref, field)), (task, field)
        assert ours.opt.density == (1.2 if task in ("ant", "humanoid") else 0.0)


def test_generic_parameters():
    base = compile_model("walker2d")
    model = compile_model(
        "walker2d",
        {"mass_scale": 1.5, "friction_scale": 0.5, "damping_scale": 3.0, "stiffness": 20.0},
    )
    np.testing.assert_allclose(model.body_mass, 1.5 * base.body_mass, rtol=1e-12)
    np.testing.assert_allclose(model.body_inertia, 1.5 * base.body_inertia, rtol=1e-12)
    np.testing.assert_allclose(model.geom_friction, 0.5 * base.geom_friction, rtol=1e-12)
    np.testing.assert_allclose(model.dof_damping, 3.0 * base.dof_damping, rtol=1e-12)
    feet = [model.joint(n).id for n in ("foot_joint", "foot_left_joint")]
    assert np.all(model.jnt_stiffness[feet] == 20.0)
    assert np.count_nonzero(model.jnt_stiffness) == 2
    hopper = compile_model("hopper", {"stiffness": 55.0})
    legs = [hopper.joint(n).id for n in ("leg_joint", "foot_joint")]
    assert np.all(hopper.jnt_stiffness[legs] == 55.0)
    springs = hopper.qpos_spring[[hopper.jnt_qposadr[j] for j in legs]]
    assert np.all(springs == 2.0)  # RNAC's reference, in rad (the XML's springref is in degrees)


def settle(model, steps=300):
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data, nstep=steps)
    return data


def total_normal_force(model, data):
    force = np.zeros(6)
    total = 0.0
    for i in range(data.ncon):
        mujoco.mj_contactForce(model, data, i, force)
        total += force[0]
    return total


def test_gravity_increases_contact_force_of_resting_ant():
    weak, strong = compile_model("ant", {"gravity": 9.81}), compile_model("ant", {"gravity": 19.62})
    mass = weak.body_subtreemass[0]
    f_weak, f_strong = (
        total_normal_force(weak, settle(weak)),
        total_normal_force(strong, settle(strong)),
    )
    assert f_weak == pytest.approx(mass * 9.81, rel=0.05)
    assert f_strong == pytest.approx(mass * 19.62, rel=0.05)
    assert f_strong > 1.9 * f_weak


@pytest.mark.parametrize("task", ["ant", "humanoid"])
def test_wind_pushes_resting_body_along_minus_x(task):
    def fluid_force_x(wind):
        model = compile_model(task, {"wind": wind})
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)  # at rest, at the initial pose
        return data.qfrc_fluid[0]  # x component on the free root joint

    calm, breeze, gale = fluid_force_x(0.0), fluid_force_x(1.0), fluid_force_x(2.0)
    assert calm == 0.0
    assert gale < breeze < 0.0
    default = make(task, "default")
    default.reset()
    assert default.unwrapped.model.opt.density == 0.0  # Gymnasium's model: no air, wind inert
    default.close()


def test_air_drags_a_moving_ant_without_wind():
    model = compile_model("ant", {"wind": 0.0})
    data = mujoco.MjData(model)
    data.qvel[0] = 3.0
    mujoco.mj_forward(model, data)
    assert data.qfrc_fluid[0] < 0.0


def test_reused_mjdata_matches_fresh_mjdata():
    """The env reuses MjData across recompiles; after mj_resetData it equals a fresh one."""
    builder = ModelBuilder("hopper", textures=False)
    defaults = dict(get_task("hopper").params)
    first = builder.compile(defaults)
    reused = mujoco.MjData(first)
    mujoco.mj_step(first, reused, nstep=50)
    second = builder.compile(defaults | {"torso_length": 0.55, "foot_length": 0.3})
    mujoco.mj_resetData(second, reused)
    fresh = mujoco.MjData(second)
    for data in (reused, fresh):
        data.ctrl[:] = [0.3, -0.2, 0.1]
        mujoco.mj_step(second, data, nstep=200)
    assert np.array_equal(reused.qpos, fresh.qpos) and np.array_equal(reused.qvel, fresh.qvel)
