"""Per-episode physics tables (`adarl.device.physics`): the host env's parameter sequence, the
changed MJX fields found by comparing compiled models, and rows equal to a fresh compile."""

import copy

import numpy as np
import pytest

from adarl.device import missing_reason
from adarl.envs import make
from adarl.envs.model import compile_model
from adarl.errors import UsageError

pytestmark = pytest.mark.skipif(missing_reason() is not None, reason=str(missing_reason()))

TASKS = ("hopper", "walker2d", "ant", "humanoid")


@pytest.fixture(scope="module")
def tables():
    from adarl.device.physics import physics_table

    return {task: physics_table(task, "paper", seed=0) for task in TASKS}


@pytest.mark.parametrize(
    "dynamics", ["paper", "ompo", "uniform", "nominal", "fixed:foot_length=0.3"]
)
def test_the_table_draws_the_host_envs_parameter_sequence(dynamics):
    from adarl.device.physics import physics_table

    table = physics_table("hopper", dynamics, seed=5)
    env = make("hopper", dynamics, seed=5)
    for episode in range(6):
        env.reset()
        assert table.params(episode) == env.dynamics_params


def test_changed_fields_include_the_derived_ones(tables):
    # issue 36 measured 19 array fields of a torso-length change, derived ones among them
    hopper = set(tables["hopper"].names)
    assert len(hopper) == 19
    derived = {"body_invweight0", "body_subtreemass", "geom_rbound", "geom_aabb", "actuator_acc0"}
    assert derived | {"body_pos", "geom_size", "body_mass", "body_inertia"} <= hopper
    assert any(name.startswith("stat.") for name in hopper)
    assert (
        sum(tables["hopper"].fields_at(tables["hopper"].params(0))[n].size for n in hopper) == 146
    )
    for task in ("ant", "humanoid"):
        assert tables[task].names == ("opt.gravity", "opt.wind")


@pytest.mark.parametrize("task", TASKS)
def test_rows_equal_a_freshly_compiled_model(tables, task):
    """For random parameters over (and beyond) the schedule's ranges, the centroid's MJX model
    with a row's fields in place equals, leaf for leaf and in its static part, the MJX model of
    a model compiled afresh at those parameters."""
    from adarl.device.physics import mjx_model
    from adarl.device.tasks import RULES

    table = tables[task]
    rules = RULES[task]
    base, base_static = mjx_model(table.mj_model, rules)
    rng = np.random.default_rng(11)
    ranges = table.schedule.ranges()
    for _ in range(3):
        params = {
            p: float(rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)))
            for p, (lo, hi) in ranges.items()
        }
        fresh, fresh_static = mjx_model(compile_model(task, params), rules)
        row = table.fields_at(params)
        assert fresh_static == base_static
        replaced = base | row
        assert replaced.keys() == fresh.keys()
        for name, value in fresh.items():
            np.testing.assert_array_equal(replaced[name], value, err_msg=name)


def test_rows_stack_episodes(tables):
    table = tables["walker2d"]
    rows = table.rows([0, 1, 2])
    torso = table.schedule.sinusoids["torso_length"]
    geom = table.mj_model.geom("torso_geom").id
    for i in range(3):  # the torso capsule's half-length is the schedule's value
        assert rows["geom_size"][i, geom, 1] == pytest.approx(torso(i), abs=1e-12)
        assert {n: v[i] for n, v in rows.items()}.keys() == set(table.names)


def test_fixed_dynamics_change_nothing_and_default_is_refused():
    from adarl.device.physics import physics_table

    table = physics_table("ant", "fixed:gravity=12")
    assert table.names == () and table.rows([0, 1]) == {}
    assert table.mj_model.opt.gravity[2] == -12.0
    with pytest.raises(UsageError, match="bad dynamics 'default' for a physics table; allowed"):
        physics_table("hopper", "default")


def test_ring_slot_k_holds_the_episode_that_is_k_mod_slots():
    from adarl.device.physics import ring_episodes

    # current 5 of 3 slots: episodes 5, 6, 7 in slots 2, 0, 1; current 7: 7, 8, 9 in 1, 2, 0
    expected = [[0, 1, 2], [6, 7, 5], [9, 7, 8]]
    np.testing.assert_array_equal(ring_episodes([0, 5, 7], 3), expected)


def host_models(task, dynamics, seed, episodes):
    """The host env's compiled model of each of its episodes 0 … episodes - 1, and their
    parameters (the env reset once per episode, as training resets it)."""
    env = make(task, dynamics, seed=seed)
    models, params = [], []
    for _ in range(episodes):
        env.reset()
        models.append(copy.copy(env.unwrapped.model))
        params.append(env.dynamics_params)
    env.close()
    return models, params


@pytest.mark.parametrize("dynamics", ["uniform", "paper"])
def test_a_ring_holds_each_seeds_next_episodes_as_the_host_env_compiles_them(dynamics):
    """Every slot of every seed's ring, as the current episodes move on, holds the fields of
    the model the host env (schedule seed = the run's seed) compiles for that episode, in the
    device's float32; `uniform` draws differ between seeds, `paper` rows do not."""
    from adarl.device.physics import PhysicsRing, host_value, physics_table

    seeds, slots = (3, 8), 4
    table = physics_table("hopper", dynamics)
    ring = PhysicsRing(table, seeds, slots)
    host = [host_models("hopper", dynamics, s, 12) for s in seeds]
    for current in ([0, 0], [2, 5], [3, 8]):
        assert ring.fill(current)
        assert not ring.fill(current)  # nothing stale
        for i, (models, params) in enumerate(host):
            for e in range(current[i], current[i] + slots):
                assert ring.episode_params(i, e) == params[e]
                for name, rows in ring.fields.items():
                    value = host_value(models[e], name, table.shapes[name]).astype(np.float32)
                    np.testing.assert_array_equal(rows[i, e % slots], value, err_msg=name)
    ring.fill([4, 4])
    same = np.array_equal(ring.fields["geom_size"][0], ring.fields["geom_size"][1])
    assert same == (dynamics == "paper")  # uniform: each seed its own draws


def test_refill_names_the_rows_it_rewrote():
    """`PhysicsRing.refill`: the (seed, slot) pairs whose episode changed, the only rows the
    device learner copies to the device."""
    from adarl.device.physics import PhysicsRing, physics_table

    ring = PhysicsRing(physics_table("hopper", "paper"), (3, 8), 4)
    assert len(ring.refill([0, 0])) == 8  # a fresh ring: every row
    # seed 0 moves on by one episode (4 into slot 0), seed 1 by three (4, 5, 6 into 0, 1, 2)
    assert ring.refill([1, 3]).tolist() == [[0, 0], [1, 0], [1, 1], [1, 2]]
    assert len(ring.refill([1, 3])) == 0
