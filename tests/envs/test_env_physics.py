"""`physics="ompo"` (the compiled default model edited as OMPO does) and `version="v4"` models."""

import copy
import json

import gymnasium
import mujoco
import numpy as np
import pytest
from gymnasium.envs.mujoco.mujoco_env import expand_model_path

from adarl.envs import PHYSICS, VERSIONS, env_options, get_task, make, make_vec
from adarl.envs.dynamics import KINDS
from adarl.envs.model import XML_FILES, XML_FILES_V4, ModelEditor, compile_model, nominal_masses
from adarl.envs.rollout import run_episodes
from adarl.errors import UsageError

TASKS = ("hopper", "walker2d", "ant", "humanoid")
LENGTHS = [(0.2, 0.195), (0.6, 0.59), (0.3, 0.49), (0.1, 0.05)]  # torso, foot half-lengths


def gymnasium_model(task, version="v5"):
    files = XML_FILES_V4 if version == "v4" else XML_FILES
    return mujoco.MjModel.from_xml_path(expand_model_path(files[task]))


def rollout(env, n, seed=0):
    """n random steps with resets; returns observations, rewards and each step's parameters."""
    rng = np.random.default_rng(seed)
    space = env.action_space
    out = []
    for _ in range(n):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(space.low, space.high))
        out.append((obs, reward, terminated, truncated, dict(info["dynamics"])))
        if terminated or truncated:
            out.append(env.reset()[:1])
    return out


def assert_same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        for u, v in zip(x, y):
            assert np.array_equal(u, v) if isinstance(u, np.ndarray) else u == v


# ------------------------------------------------------------------ masses and geometry
@pytest.mark.parametrize("task", ["hopper", "walker2d"])
@pytest.mark.parametrize("version", VERSIONS)
def test_ompo_keeps_default_masses_while_geometry_follows(task, version):
    default = gymnasium_model(task, version)
    for torso, foot in LENGTHS:
        params = {"torso_length": torso, "foot_length": foot}
        ompo = compile_model(task, params, physics="ompo", version=version)
        consistent = compile_model(task, params, version=version)
        for field in ("body_mass", "body_inertia", "body_ipos", "geom_rbound", "body_subtreemass"):
            assert np.array_equal(getattr(ompo, field), getattr(default, field)), field
        # the geometry is the same under both physics (the root slides' anchors aside, which
        # do not act on a slide joint); only what follows from it differs
        for field in ("body_pos", "geom_size", "geom_pos", "qpos0"):
            np.testing.assert_allclose(getattr(ompo, field), getattr(consistent, field), atol=1e-15)
        # under consistent, masses follow the geometry: the torso's and feet's, nothing else
        feet = [
            ompo.geom(g).bodyid[0]
            for g in ("foot_geom", "foot_left_geom")[: 1 + (task == "walker2d")]
        ]
        torso_id = ompo.body("torso").id
        follows = consistent.body_mass != default.body_mass
        assert follows[torso_id] == (torso != 0.2)
        assert all(follows[f] == (foot != get_task(task).params["foot_length"]) for f in feet)
        assert np.count_nonzero(follows) == follows[torso_id] + sum(follows[f] for f in feet)


# ------------------------------------------------------------------ contacts (MuJoCo 2.x's)
THIGHS = {"hopper": ("thigh",), "walker2d": ("thigh", "thigh_left")}
FEET = {"hopper": ("foot_geom",), "walker2d": ("foot_geom", "foot_left_geom")}


def spec_model(task, torso, foot, version="v5"):
    """OMPO's edit made in an MjSpec of Gymnasium's XML and compiled: the edited robot with every
    bound MuJoCo's compiler derives from its geometry (masses too, unused here)."""
    files = XML_FILES_V4 if version == "v4" else XML_FILES
    spec = mujoco.MjSpec.from_file(expand_model_path(files[task]))
    spec.body("torso").pos = [0.0, 0.0, 1.05 + torso]
    for name in THIGHS[task]:
        spec.body(name).pos = [0.0, 0.0, -torso]
    spec.geom("torso_geom").size = [0.05, torso, 0.0]
    for name in FEET[task]:
        spec.geom(name).size = [0.06, foot, 0.0]
    return spec.compile()


def contact_list(model, qpos):
    """Sorted (geom1, geom2, distance) of every contact at `qpos`."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    con = data.contact
    return sorted(zip(con.geom1.tolist(), con.geom2.tolist(), con.dist.tolist()))


def mujoco2_kept(model, data_xpos, rbound, g1, g2):
    """MuJoCo 2.x's pair filter with bounding radii `rbound`: a plane and a geom are kept unless
    the geom's centre is farther from the plane than its radius (+ margins), two geoms unless
    their centres are farther apart than the sum of their radii (+ margins)."""
    margin = model.geom_margin[g1] + model.geom_margin[g2]
    if model.geom_type[g1] == mujoco.mjtGeom.mjGEOM_PLANE:  # the floor, z = 0
        return data_xpos[g2][2] <= rbound[g2] + margin
    return np.linalg.norm(data_xpos[g1] - data_xpos[g2]) <= rbound[g1] + rbound[g2] + margin


@pytest.mark.parametrize("task", ["hopper", "walker2d"])
@pytest.mark.parametrize("lengths", [(0.6, 0.59), (0.4, 0.39), (0.3, 0.15)])
def test_ompo_contacts_are_those_of_mujoco2(task, lengths):
    """Over a grid of poses, `ompo`'s contacts are the edited robot's true contacts (a model
    compiled from an MjSpec, whose bounds all fit the geometry) that MuJoCo 2.x's filter on
    the default robot's bounding radii keeps: OMPO's edit on mujoco-py. The stale `geom_aabb` of
    an in-place edit loses more (Hopper's self-contacts); refreshed radii would keep too many."""
    torso, foot = lengths
    default = gymnasium_model(task)
    ompo = compile_model(task, {"torso_length": torso, "foot_length": foot}, physics="ompo")
    truth = spec_model(task, torso, foot)
    np.testing.assert_allclose(ompo.geom_size, truth.geom_size, atol=1e-15)
    np.testing.assert_allclose(ompo.body_pos[:4], truth.body_pos[:4], atol=1e-15)
    stale_aabb = copy.copy(ompo)
    stale_aabb.geom_aabb[:] = default.geom_aabb  # OMPO's edit alone, as before the fix
    rng = np.random.default_rng(0)
    lows, highs = default.jnt_range[3:].T
    kinds = {"pruned": 0, "stale aabb differs": 0}
    for _ in range(400):
        qpos = default.qpos0.copy()
        qpos[1] += rng.uniform(-1.7, 0.3)  # rootz (1.25 at reset): from the floor to the air
        qpos[2] = rng.uniform(-np.pi, np.pi)  # rooty
        qpos[3:] = rng.uniform(lows, highs)
        data = mujoco.MjData(truth)
        data.qpos[:] = qpos
        mujoco.mj_kinematics(truth, data)
        true = contact_list(truth, qpos)
        expected = [
            c for c in true if mujoco2_kept(truth, data.geom_xpos, default.geom_rbound, *c[:2])
        ]
        got = contact_list(ompo, qpos)
        assert [c[:2] for c in got] == [c[:2] for c in expected], qpos
        np.testing.assert_allclose([c[2] for c in got], [c[2] for c in expected], atol=1e-12)
        kinds["pruned"] += len(expected) < len(true)
        kinds["stale aabb differs"] += contact_list(stale_aabb, qpos) != got
    # the grid has poses whose true contacts 2.x's stale radii drop (so refreshed radii would
    # fail this test); on Hopper, whose robot geoms collide with each other, poses where the
    # stale aabb drops pairs 2.x kept (so the edit without the fix fails it)
    assert kinds["pruned"] > 0, kinds
    assert kinds["stale aabb differs"] > 0 or task == "walker2d", kinds
    assert np.array_equal(ompo.body_mass, default.body_mass)
    assert np.array_equal(ompo.geom_rbound, default.geom_rbound)


@pytest.mark.parametrize("version", VERSIONS)
def test_ompo_formulas(version):
    """OMPO's edits, by its own indices: Hopper body_pos[1][2] = 1.05 + L, body_pos[2][2] = -L,
    geom_size[1][1] = L, geom_size[4][1] = F; Walker2d also body 5 and geom 7."""
    length, foot = 0.37, 0.43
    hopper = compile_model(
        "hopper", {"torso_length": length, "foot_length": foot}, physics="ompo", version=version
    )
    assert hopper.body_pos[1][2] == 1.05 + length and hopper.body_pos[2][2] == -length
    assert hopper.geom_size[1][1] == length and hopper.geom_size[4][1] == foot
    walker = compile_model(
        "walker2d", {"torso_length": length, "foot_length": foot}, physics="ompo", version=version
    )
    assert walker.body_pos[1][2] == 1.05 + length
    assert walker.body_pos[2][2] == walker.body_pos[5][2] == -length
    assert walker.geom_size[1][1] == length
    assert walker.geom_size[4][1] == walker.geom_size[7][1] == foot
    # the indices are the bodies and capsules OMPO means
    names = [walker.body(i).name for i in (1, 2, 5)] + [walker.geom(i).name for i in (1, 4, 7)]
    assert names == ["torso", "thigh", "thigh_left", "torso_geom", "foot_geom", "foot_left_geom"]
    assert [hopper.body(i).name for i in (1, 2)] == ["torso", "thigh"]
    assert [hopper.geom(i).name for i in (1, 4)] == ["torso_geom", "foot_geom"]
    assert all(hopper.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE for g in (1, 4))


def test_nominal_masses_match_the_issue():
    """Hopper at 0.4 / 0.39: torso 3.67 -> 6.81 kg, foot 5.32 -> 9.73 kg once recompiled."""
    ompo, consistent = nominal_masses("hopper", "ompo"), nominal_masses("hopper", "consistent")
    assert round(ompo["torso"], 2) == 3.67 and round(consistent["torso"], 2) == 6.81
    assert round(ompo["foot"], 2) == 5.32 and round(consistent["foot"], 2) == 9.73
    for task in TASKS:
        default = gymnasium_model(task).body_mass[1:]
        assert np.array_equal(list(nominal_masses(task, "ompo").values()), default)
        assert nominal_masses(task, "ompo", "v4") == nominal_masses(task, "ompo")


def test_ompo_generic_parameters_scale_the_compiled_fields():
    base = gymnasium_model("hopper")
    params = {"mass_scale": 1.5, "friction_scale": 0.5, "damping_scale": 3.0, "stiffness": 20.0}
    ompo = compile_model("hopper", params, physics="ompo")
    consistent = compile_model("hopper", params)
    for field, factor in (
        ("body_mass", 1.5),
        ("body_inertia", 1.5),
        ("geom_friction", 0.5),
        ("dof_damping", 3.0),
    ):
        np.testing.assert_array_equal(getattr(ompo, field), factor * getattr(base, field))
        np.testing.assert_allclose(getattr(ompo, field), getattr(consistent, field), rtol=1e-12)
    legs = [ompo.joint(n).id for n in ("leg_joint", "foot_joint")]
    assert np.all(ompo.jnt_stiffness[legs] == 20.0) and np.count_nonzero(ompo.jnt_stiffness) == 2
    assert np.all(ompo.qpos_spring[[ompo.jnt_qposadr[j] for j in legs]] == 2.0)


def test_editor_writes_absolutely():
    """Any history of parameters gives the same model; the defaults give Gymnasium's back."""
    model = gymnasium_model("walker2d")
    editor = ModelEditor("walker2d", model)
    defaults = dict(get_task("walker2d").params)
    editor.compile(defaults | {"torso_length": 0.5, "mass_scale": 2.0, "stiffness": 5.0})
    editor.compile(defaults | {"foot_length": 0.3, "friction_scale": 0.1})
    fresh = ModelEditor("walker2d", gymnasium_model("walker2d")).compile(
        defaults | {"foot_length": 0.3, "friction_scale": 0.1}
    )
    for field in (
        "body_pos",
        "geom_size",
        "geom_aabb",
        "body_mass",
        "geom_friction",
        "jnt_stiffness",
    ):
        assert np.array_equal(getattr(model, field), getattr(fresh, field)), field
    editor.compile(defaults)
    reference = gymnasium_model("walker2d")
    for field in (
        "body_pos",
        "geom_size",
        "geom_aabb",
        "body_mass",
        "body_inertia",
        "geom_friction",
        "qpos_spring",
    ):
        assert np.array_equal(getattr(model, field), getattr(reference, field)), field
    assert np.array_equal(model.opt.gravity, reference.opt.gravity)


# ------------------------------------------------------------------ envs
@pytest.mark.parametrize("task", ["ant", "humanoid"])
def test_gravity_and_wind_tasks_are_the_same_under_both_physics(task):
    """Only `opt` changes on Ant and Humanoid: both physics simulate identically."""
    a = make(task, "paper", seed=2, max_episode_steps=30)
    b = make(task, "paper", seed=2, max_episode_steps=30, physics="ompo")
    a.reset(), b.reset()
    assert_same(rollout(a, 70), rollout(b, 70))
    assert b.unwrapped.model.opt.density == 1.2


@pytest.mark.filterwarnings("ignore:.*is out of date")  # gymnasium.make of a -v4 id
@pytest.mark.parametrize("task", ["hopper", "walker2d"])
def test_ompo_at_the_defaults_is_gymnasium(task):
    """`fixed` at the defaults under ompo edits nothing: Gymnasium's env bit for bit."""
    ours = make(task, "fixed", seed=7, physics="ompo", model_version="v4")
    plain = gymnasium.make(get_task(task, "v4").gym_id)
    o1, _ = ours.reset()
    o2, _ = plain.reset(seed=7)
    assert np.array_equal(o1, o2)
    rng = np.random.default_rng(0)
    for _ in range(40):
        a = rng.uniform(-1, 1, ours.action_space.shape)
        r1, r2 = ours.step(a), plain.step(a)
        assert np.array_equal(r1[0], r2[0]) and r1[1:4] == r2[1:4]
        if r1[2]:
            break


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("version", VERSIONS)
def test_tasks_step_reset_and_change_dynamics(task, version):
    obs_dim = {"v5": get_task(task).obs_dim, "v4": get_task(task).v4_obs_dim}[version]
    assert get_task(task, version).obs_dim == obs_dim
    for physics in PHYSICS:
        env = make(
            task, "paper", seed=0, physics=physics, model_version=version, max_episode_steps=5
        )
        assert env.spec.id == f"{get_task(task).gym_id[:-3]}-{version}"
        assert env.observation_space.shape == (obs_dim,)
        seen, models = [], []
        for _ in range(3):
            obs, info = env.reset()
            assert obs.shape == (obs_dim,)
            seen.append(dict(info["dynamics"]))
            model = env.unwrapped.model
            models.append(tuple(model.opt.gravity) + tuple(model.geom_size[1]))
            for _ in range(5):
                obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
                assert np.isfinite(obs).all() and np.isfinite(reward)
                if terminated or truncated:
                    break
        assert seen[0] != seen[1] != seen[2]  # paper dynamics vary with the episode
        assert models[0] != models[1] != models[2]  # and the model follows
        env.close()


@pytest.mark.parametrize("physics", PHYSICS)
def test_every_dynamics_mode_works_under_both_physics(physics):
    for kind in KINDS:
        dynamics = "fixed:torso_length=0.5" if kind == "fixed" else kind
        for version in VERSIONS:
            env = make("hopper", dynamics, seed=1, physics=physics, model_version=version)
            _, info = env.reset()
            env.step(env.action_space.sample())
            torso = env.unwrapped.model.geom_size[1][1]
            assert torso == info["dynamics"]["torso_length"] or kind == "default"
            env.close()


def test_walker2d_v4_keeps_its_feet_frictions():
    """Walker2d-v4's right foot has friction 0.9 (v5: 1.9); both physics keep the model's own."""
    for physics in PHYSICS:
        env = make("walker2d", "paper", physics=physics, model_version="v4")
        env.reset()
        model = env.unwrapped.model
        frictions = [
            model.geom_friction[model.geom(g).id][0] for g in ("foot_geom", "foot_left_geom")
        ]
        assert frictions == [0.9, 1.9]


@pytest.mark.parametrize("task", TASKS)
def test_default_dynamics_evaluates_every_task(task):
    """`--eval-dynamics default` (OMPO's Hopper evaluation): Gymnasium's model untouched."""
    act_dim = get_task(task).act_dim
    for physics in PHYSICS:
        for version in VERSIONS:
            rows = run_episodes(
                lambda obs: np.zeros(act_dim),
                task,
                "default",
                1,
                seed=5,
                max_steps=3,
                physics=physics,
                model_version=version,
            )
            assert rows[0]["length"] == 3
    env = make(task, "default", physics="ompo", model_version="v4")
    env.reset()
    reference = gymnasium_model(task, "v4")
    for field in ("body_pos", "geom_size", "body_mass"):
        assert np.array_equal(getattr(env.unwrapped.model, field), getattr(reference, field))
    assert env.unwrapped.model.opt.density == 0.0


@pytest.mark.parametrize(
    "task,dynamics,warmup",
    [("hopper", "ompo", 30), ("walker2d", "uniform", 25), ("ant", "paper", 20)],
)
def test_state_round_trip_is_bit_exact_under_ompo_and_v4(task, dynamics, warmup):
    a = make(task, dynamics, seed=3, max_episode_steps=40, physics="ompo", model_version="v4")
    a.reset()
    rollout(a, warmup, seed=1)
    state = json.loads(json.dumps(a.get_state(), default=np.ndarray.tolist))
    assert state["physics"] == "ompo" and state["model_version"] == "v4"
    # another env that already ran other episodes (its model was edited for other lengths)
    b = make(task, dynamics, seed=11, max_episode_steps=40, physics="ompo", model_version="v4")
    b.reset()
    rollout(b, 60, seed=4)
    b.set_state(copy.deepcopy(state))
    assert b.episode_index == a.episode_index and b.dynamics_params == a.dynamics_params
    after_a, after_b = rollout(a, 90, seed=2), rollout(b, 90, seed=2)
    assert_same(after_a, after_b)
    assert sum(len(t) == 1 for t in after_a) >= 1  # a reset (and a model edit) after restoring


def test_state_rejects_other_physics_and_version():
    state = make("hopper", "paper", physics="ompo", model_version="v4").get_state()
    with pytest.raises(UsageError, match="physics 'ompo'; allowed: 'consistent'"):
        make("hopper", "paper", model_version="v4").set_state(state)
    with pytest.raises(UsageError, match="model_version 'v4'; allowed: 'v5'"):
        make("hopper", "paper", physics="ompo").set_state(state)
    old = make("hopper", "paper").get_state()  # states from before the switches: consistent v5
    del old["physics"], old["model_version"]
    make("hopper", "paper").set_state(old)
    with pytest.raises(UsageError, match="physics 'consistent'"):
        make("hopper", "paper", physics="ompo").set_state(old)


def test_make_vec_passes_physics_and_version():
    vec = make_vec("ant", "paper", seeds=[0, 1], physics="ompo", model_version="v4")
    obs, _ = vec.reset()
    assert obs.shape == (2, 27)
    assert vec.get_attr("physics") == ("ompo", "ompo")
    vec.close()


def test_env_options_from_configs():
    assert env_options({"task": "hopper"}) == {"physics": "consistent", "model_version": "v5"}
    flat = {"task": "hopper", "physics": "ompo", "model_version": "v4"}
    assert env_options(flat) == {"physics": "ompo", "model_version": "v4"}
    # a fork's record is no section of fields: nothing is looked up inside it
    forked = {"task": "hopper", "fork": {"changed": {"physics": {"from": "a", "to": "b"}}}}
    assert env_options(forked) == {"physics": "consistent", "model_version": "v5"}


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "kwargs, needle",
    [
        ({"physics": "newton"}, "unknown physics 'newton'; allowed: consistent, ompo"),
        ({"model_version": "v3"}, "unknown model version 'v3'; allowed: v5, v4"),
        ({"model_version": "V4"}, "unknown model version 'V4'"),
    ],
)
def test_bad_physics_or_version(kwargs, needle):
    with pytest.raises(UsageError) as info:
        make("hopper", "paper", **kwargs)
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_gym_tasks_have_no_physics_or_versions():
    for kwargs in ({"physics": "ompo"}, {"model_version": "v4"}):
        with pytest.raises(UsageError, match="applies to hopper, walker2d, ant, humanoid; allowed"):
            make("gym:Pendulum-v1", "default", **kwargs)
    make("gym:Pendulum-v1", "default", physics="consistent", model_version="v5").close()
    with pytest.raises(UsageError, match="unknown physics 'x'"):
        make("gym:Pendulum-v1", "default", physics="x")
    with pytest.raises(UsageError, match="unknown physics"):
        compile_model("hopper", physics="x")


# ------------------------------------------------------------------ the switch at the env level
def capsule_mass(radius, half_length, density=1000.0):
    """A capsule's mass from its geometry (MuJoCo's default density), independent of adarl."""
    return density * (np.pi * radius**2 * 2 * half_length + 4 / 3 * np.pi * radius**3)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("dynamics", ["paper", "ompo", "fixed:torso_length=0.5"])
@pytest.mark.parametrize("physics", PHYSICS)
def test_the_env_follows_physics_not_the_dynamics_or_version(physics, dynamics, version):
    """The model an env steps has masses by `physics` alone: under `ompo` Gymnasium's default
    masses (read from its XML), under `consistent` the torso's capsule mass at the episode's
    torso length, whatever the dynamics are called and whichever model version."""
    default_torso = gymnasium_model("hopper", version).body("torso").mass[0]
    env = make("hopper", dynamics, seed=2, physics=physics, model_version=version)
    lengths = set()
    for _ in range(3):
        _, info = env.reset()
        model = env.unwrapped.model
        length = info["dynamics"]["torso_length"]
        lengths.add(length)
        assert model.geom("torso_geom").size[1] == pytest.approx(length)  # geometry: both
        expected = default_torso if physics == "ompo" else capsule_mass(0.05, length)
        assert model.body("torso").mass[0] == pytest.approx(expected, rel=1e-9)
    assert max(lengths) != 0.2  # the lengths differ from the default: the masses would tell
    env.close()
