"""Addressed parameters (adarl.envs.elements, docs/envs.md "Any element of the model"): what a
user loses when one edit reaches the wrong element. Expected values are read from MuJoCo's own
compile of the task's XML, never from adarl's builders."""

import mujoco
import numpy as np
import pytest

from adarl.envs import get_task, make, parse_dynamics
from adarl.envs.dynamics import xml_path
from adarl.envs.elements import address_default
from adarl.errors import UsageError


def compiled(task):
    """MuJoCo's compile of the task's XML, untouched by adarl."""
    return mujoco.MjModel.from_xml_path(xml_path(get_task(task)))


def edited(task, dynamics):
    env = make(task, dynamics, seed=0)
    env.reset()
    model = env.unwrapped.model
    env.close()
    return model


@pytest.mark.parametrize(
    "task, body, value",
    [
        ("HalfCheetah-v5", "torso", 8.0),  # a generic task (its XML's settotalmass baked)
        ("Ant-v5", "torso", 0.5),  # a model with a free joint
        ("hopper", "thigh", 6.0),  # a paper task: its own builder, then the addressed edit
    ],
)
def test_setting_one_bodys_mass_leaves_every_other_body_as_compiled(task, body, value):
    base = compiled(task)
    model = edited(task, f"fixed:body:{body}.mass={value}")
    i = base.body(body).id
    assert model.body_mass[i] == pytest.approx(value, rel=1e-9)
    others = [b for b in range(base.nbody) if b != i]
    # e.g. HalfCheetah's bthigh stays 1.5435 kg (not rescaled with the torso)
    np.testing.assert_allclose(model.body_mass[others], base.body_mass[others], rtol=1e-12)
    np.testing.assert_allclose(model.body_inertia[others], base.body_inertia[others], rtol=1e-12)
    # the edited body's inertia follows its mass, in proportion
    ratio = value / base.body_mass[i]
    np.testing.assert_allclose(model.body_inertia[i], base.body_inertia[i] * ratio, rtol=1e-9)


def test_a_mass_and_a_size_of_the_same_body_are_both_applied():
    base = compiled("HalfCheetah-v5")
    model = edited("HalfCheetah-v5", "fixed:body:torso.mass=8,geom:torso.size[1]=0.7")
    assert model.body("torso").mass[0] == pytest.approx(8.0, rel=1e-9)
    assert model.geom("torso").size[1] == pytest.approx(0.7, rel=1e-12)
    assert model.geom("torso").size[0] == base.geom("torso").size[0]
    others = [b for b in range(base.nbody) if b != base.body("torso").id]
    np.testing.assert_allclose(model.body_mass[others], base.body_mass[others], rtol=1e-12)


def test_a_joint_default_on_a_model_with_a_free_joint_is_its_own_dofs():
    """Ant's free joint takes dofs 0-5 (damping 0); hip_1 is joint 1 but dof 6 (damping 1)."""
    base = compiled("Ant-v5")
    assert base.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    path = xml_path(get_task("Ant-v5"))
    assert address_default(path, "joint:hip_1.damping") == 1.0
    for j in range(1, base.njnt):
        name, dof = base.joint(j).name, base.jnt_dofadr[j]
        assert address_default(path, f"joint:{name}.damping") == base.dof_damping[dof]
        assert address_default(path, f"joint:{name}.armature") == base.dof_armature[dof]
        assert address_default(path, f"joint:{name}.frictionloss") == base.dof_frictionloss[dof]
        assert address_default(path, f"joint:{name}.stiffness") == base.jnt_stiffness[j]
    # what a user sees: a range's error names the model's default
    with pytest.raises(UsageError, match=r"default 1\)"):
        parse_dynamics("uniform:joint:hip_1.damping=0..20", "Ant-v5")


@pytest.mark.parametrize(
    "dynamics",
    [
        "fixed:geom:torso.size[3]=1",
        "fixed:geom:torso.size[4]=1",
        "fixed:geom:torso.friction[3]=1",
        "uniform:geom:torso.size[3]=0.1..0.2",
        "fixed:body:torso.mass[1]=1",
        "fixed:joint:bthigh.damping[1]=1",
    ],
)
def test_any_out_of_range_index_is_a_one_line_error(dynamics):
    with pytest.raises(UsageError, match=r"bad index \[\d\]") as info:
        make("HalfCheetah-v5", dynamics, seed=0)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("address", "needle"),
    [
        ("geom:torso.size[2]", "a capsule's physics does not use size\\[2\\]"),  # HalfCheetah's torso
        ("geom:floor.size[0]", "a plane's physics does not use size\\[0\\]"),
    ],
)  # fmt: skip
def test_a_size_component_the_geom_type_does_not_use_is_refused(address, needle):
    # issue 61 §5: geom:torso.size[2] on a capsule was accepted and changed nothing
    from adarl.envs.dynamics import parse_dynamics
    from adarl.errors import UsageError

    with pytest.raises(UsageError, match=needle):
        parse_dynamics(f"fixed:{address}=0.1", "HalfCheetah-v5")
    parse_dynamics("fixed:geom:torso.size[0]=0.05", "HalfCheetah-v5")  # a radius: used
