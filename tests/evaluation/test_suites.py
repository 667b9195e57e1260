"""Robustness suites: published grids, worst-case / average summaries, serial = parallel."""

import itertools

import numpy as np
import pandas as pd
import pytest

from adarl.errors import UsageError
from adarl.evaluation import grid, suites

# (suite, task) -> {param: (low, high)} as in M2TD3's configs/environment/*.yaml
M2TD3 = {
    ("m2td3-1d", "hopper"): {"floor_friction": (0.1, 3.0)},
    ("m2td3-2d", "hopper"): {"floor_friction": (0.1, 3.0), "torso_mass": (0.1, 3.0)},
    ("m2td3-3d", "hopper"): {
        "floor_friction": (0.1, 3.0),
        "torso_mass": (0.1, 3.0),
        "thigh_mass": (0.1, 4.0),
    },
    ("m2td3-3d", "walker2d"): {
        "floor_friction": (0.1, 4.0),
        "torso_mass": (0.1, 5.0),
        "thigh_mass": (0.1, 6.0),
    },
    ("m2td3-3d", "ant"): {
        "torso_mass": (0.1, 3.0),
        "front_left_leg_mass": (0.01, 3.0),
        "front_right_leg_mass": (0.01, 3.0),
    },
}


@pytest.mark.parametrize("key", list(M2TD3))
def test_m2td3_grids_are_linspace_10_per_dimension(key):
    name, task = key
    suite = suites.get_suite(name, task)
    axes = suite.axes()
    assert [a.name for a in axes] == list(M2TD3[key])
    for axis, (low, high) in zip(axes, M2TD3[key].values()):
        np.testing.assert_allclose(axis.values, np.linspace(low, high, 10))
    points = grid.build_grid(axes, (), suites_params(task), task)
    assert len(points) == 10 ** len(axes) == suite.size
    assert suite.episodes == 30 and suite.base == "fixed"


def test_rrls_grids_include_both_ends():
    """RRLS's rrls/evaluate.py:44-48 spaces its grids with np.arange(min, max, (max-min)/10),
    which leaves max out of the set it evaluates: not copied, every rrls suite has both ends."""
    for suite in suites.SUITES["rrls-3d"].values():
        for axis, r in zip(suite.axes(), suite.ranges):
            assert axis.values[0] == r.low and axis.values[-1] == r.high and len(axis.values) == 10
    for task in ("hopper", "walker2d", "ant"):  # there RRLS's sets are M2TD3's
        for dim in (1, 2, 3):
            rrls, m2td3 = (
                suites.get_suite(f"rrls-{dim}d", task),
                suites.get_suite(f"m2td3-{dim}d", task),
            )
            assert rrls.axes() == m2td3.axes() and rrls.source != m2td3.source
    # RRLS's own points stay available: arange's ten, the upper end left out
    np.testing.assert_allclose(
        suites.grid_values(0.1, 6.0, 10, "arange"), np.arange(0.1, 6.0, (6.0 - 0.1) / 10)
    )


# RRLS's uncertainty sets on Gymnasium tasks outside the paper's four, copied from SuReLI/RRLS at
# commit 0c43dc981c0e892a604c596e2bc399df187a87ac: [ONE_DIM, TWO_DIM, THREE_DIM] of each
# `*ParamsBound`, RRLS name -> [low, high], in RRLS's order.
RRLS_SETS = {
    "HalfCheetah-v5": [  # rrls/envs/half_cheetah.py:24-36
        {"worldfriction": [0.1, 3.0]},  # :26
        {"worldfriction": [0.1, 4.0], "torsomass": [0.1, 7.0]},  # :29-30
        {
            "worldfriction": [0.1, 4.0],
            "torsomass": [0.1, 7.0],
            "backthighmass": [0.1, 3.0],
        },  # :33-35
    ],
    "InvertedPendulum-v5": [  # rrls/envs/pendulum.py:15-22 (no THREE_DIM)
        {"polemass": [1.0, 31.0]},  # :17
        {"polemass": [1.0, 31.0], "cartmass": [1.0, 11.0]},  # :20-21
    ],
    "HumanoidStandup-v5": [  # rrls/envs/humanoid.py:26-38
        {"torsomass": [0.1, 16.0]},  # :28
        {"torsomass": [0.1, 16.0], "rightfootmass": [0.1, 8.0]},  # :31-32
        {
            "torsomass": [0.1, 16.0],
            "leftthighmass": [0.1, 5.0],
            "rightfootmass": [0.1, 8.0],
        },  # :35-37
    ],
}
# What each name writes in RRLS's `_change_params`: `model.body_mass[i]`, or every geom's
# sliding friction (`model.geom_friction[:, 0] = value`, half_cheetah.py:175).
RRLS_WRITES = {
    "HalfCheetah-v5": {
        "worldfriction": "every geom",
        "torsomass": 1,
        "backthighmass": 2,
    },  # :175-179
    "InvertedPendulum-v5": {"cartmass": 1, "polemass": 2},  # pendulum.py:88, :90
    "HumanoidStandup-v5": {
        "torsomass": 1,
        "rightfootmass": 6,
        "leftthighmass": 7,
    },  # humanoid.py:228, :243, :246
}
# RRLS's DEFAULT_PARAMS for those names (half_cheetah.py:13-15, pendulum.py:10-11,
# humanoid.py:10, :15, :16).
RRLS_DEFAULTS = {
    "HalfCheetah-v5": {"worldfriction": 0.4, "torsomass": 6.25020920502092, "backthighmass": 1.5435146443514645},
    "InvertedPendulum-v5": {"polemass": 10.47197551196598, "cartmass": 5.018591641363306},
    "HumanoidStandup-v5": {"torsomass": 8.907462370478262, "rightfootmass": 1.7671458676442586, "leftthighmass": 4.751750928806242},
}  # fmt: skip


def gymnasium_model(task):
    mujoco = pytest.importorskip("mujoco")
    from adarl.envs import get_task

    return mujoco.MjModel.from_xml_path(get_task(task).xml_path)


def as_adarl(task, model, name, low, high):
    """An RRLS parameter as adarl's, from what RRLS writes and Gymnasium's model alone: the body
    at RRLS's index by name, world friction as friction_scale over the model's one friction."""
    where = RRLS_WRITES[task][name]
    if where == "every geom":
        (friction,) = set(model.geom_friction[:, 0])
        return "friction_scale", low / friction, high / friction
    return f"body:{model.body(where).name}.mass", low, high


@pytest.mark.parametrize("task", list(RRLS_SETS))
def test_rrls_sets_of_gymnasium_tasks_are_rrls_values(task):
    model = gymnasium_model(task)
    for dim, bounds in enumerate(RRLS_SETS[task], start=1):
        suite = suites.get_suite(f"rrls-{dim}d", task)
        expected = [as_adarl(task, model, n, *lh) for n, lh in bounds.items()]
        got = [(r.param, r.low, r.high) for r in suite.ranges]
        assert [g[0] for g in got] == [e[0] for e in expected]
        np.testing.assert_allclose([g[1:] for g in got], [e[1:] for e in expected], rtol=1e-12)
        assert suite.points == 10 and suite.spacing == "linspace" and suite.base == "fixed"
        assert "SuReLI/RRLS rrls/envs/" in suite.source and suite.source.endswith(
            ("ONE_DIM", "TWO_DIM", "THREE_DIM")[dim - 1]
        )
    covering = {name for name, by_task in suites.SUITES.items() if task in by_task}
    assert covering == {f"rrls-{d}d" for d in range(1, len(RRLS_SETS[task]) + 1)}


def test_rrls_names_are_the_bodies_of_gymnasiums_models():
    """RRLS addresses bodies by index; its defaults are Gymnasium's masses at those indices,
    except InvertedPendulum's, which swap pole and cart (a defect: RRLS's 1-D pendulum set
    leaves the cart at the pole's 5.02 kg). Our base is Gymnasium's robot (`fixed`)."""
    for task, defaults in RRLS_DEFAULTS.items():
        model = gymnasium_model(task)
        for name, value in defaults.items():
            where = RRLS_WRITES[task][name]
            if where == "every geom":
                assert set(model.geom_friction[:, 0]) == {value} and set(model.geom_condim) == {3}
            elif task == "InvertedPendulum-v5":
                other = {1: 2, 2: 1}[where]
                assert model.body_mass[other] == pytest.approx(value, rel=1e-12)
            else:
                assert model.body_mass[where] == pytest.approx(value, rel=1e-12), (task, name)
    from adarl.envs import parse_dynamics

    fixed = parse_dynamics("fixed", "InvertedPendulum-v5")
    assert not [p for p in fixed.centroid() if p.startswith("body:")]


def test_gymnasium_task_names_and_models_for_suites(tmp_path):
    assert suites.get_suite("rrls-2d", "gym:HalfCheetah-v5").task == "HalfCheetah-v5"
    with pytest.raises(UsageError) as err:
        suites.get_suite("rrls-3d", "InvertedPendulum-v5")
    assert "allowed for InvertedPendulum-v5: rrls-1d, rrls-2d" in str(err.value)
    with pytest.raises(UsageError, match="allowed for HalfCheetah-v4: none"):
        suites.get_suite("rrls-1d", "HalfCheetah-v4")
    pytest.importorskip("mujoco")
    import synthetic_runs

    from adarl.results.runs import load_run

    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(synthetic_runs.DIMS, "InvertedPendulum-v5", (4, 1))
        patch.setitem(synthetic_runs.PARAMS, "InvertedPendulum-v5", {})
        own = synthetic_runs.write_run(
            tmp_path, "own", algo="sac", task="InvertedPendulum-v5", seeds=(0,),
            extra_config={"env_kwargs": "xml_file=/somewhere/pendulum.xml"},
        )  # fmt: skip
    with pytest.raises(UsageError) as err:
        suites.plan_suite([load_run(own)], "rrls-1d")
    assert "defined on Gymnasium's InvertedPendulum-v5 model" in str(err.value)
    assert "xml_file=/somewhere/pendulum.xml" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    "task, ranges",
    [
        ("hopper", {"torso_length": (0.2, 0.6), "foot_length": (0.19, 0.59)}),
        ("walker2d", {"torso_length": (0.1, 0.3), "foot_length": (0.05, 0.15)}),
        ("ant", {"gravity": (9.81, 19.62), "wind": (0.8, 1.2)}),
        ("humanoid", {"gravity": (9.81, 19.62), "wind": (0.5, 1.5)}),
    ],
)
def test_paper_suite_spans_the_training_ranges(task, ranges):
    suite = suites.get_suite("paper", task)
    got = {r.param: (r.low, r.high) for r in suite.ranges}
    assert got.keys() == ranges.keys()
    for param, (low, high) in ranges.items():
        np.testing.assert_allclose(got[param], (low, high))
    assert suite.size == 100 and suite.base == "nominal"


def test_every_suite_point_is_a_valid_dynamics():
    from adarl.envs import parse_dynamics

    for by_task in suites.SUITES.values():
        for task, suite in by_task.items():
            for axis in suite.axes():  # the corners are enough: each axis at both ends
                for value in (axis.values[0], axis.values[-1]):
                    parse_dynamics(grid.point_label(suite.base, {axis.name: value}), task)


@pytest.mark.parametrize(
    "name, task, fragment",
    [
        ("m2td3-4d", "hopper", "unknown suite 'm2td3-4d'; allowed: m2td3-1d, m2td3-2d"),
        ("m2td3-1d", "humanoid", "suite 'm2td3-1d' does not apply to task 'humanoid'"),
        ("rrls-2d", "humanoid", "allowed for humanoid: paper"),
    ],
)
def test_bad_names_are_one_line_errors(name, task, fragment):
    with pytest.raises(UsageError) as err:
        suites.get_suite(name, task)
    assert fragment in str(err.value) and "\n" not in str(err.value)


def suites_params(task):
    from adarl.envs import get_task

    return list(get_task(task).all_params)


def constructed_table(returns: dict[int, np.ndarray], episodes: int = 2) -> pd.DataFrame:
    """An episode table over a 3 x 2 grid: seed -> (3, 2) array of point means; each point's
    episodes are mean ± 1 so that their mean is the given value."""
    rows = []
    for seed, means in returns.items():
        for (i, a), (j, b) in itertools.product(enumerate((0.1, 0.2, 0.3)), enumerate((1, 2))):
            for k in range(episodes):
                rows.append(
                    {
                        "step": 100,
                        "seed": seed,
                        "dynamics": f"fixed:a={a},b={b}",
                        "episode": k,
                        "return": means[i, j] + (1 if k % 2 else -1),
                        "length": 10,
                        "p_a": a,
                        "p_b": b,
                    }
                )
    return pd.DataFrame(rows)


def test_worst_case_and_average_of_a_constructed_table():
    rng = np.random.default_rng(0)
    means = {0: rng.uniform(0, 100, (3, 2)), 3: rng.uniform(0, 100, (3, 2))}
    summary = suites.seed_summary(constructed_table(means), "s")
    assert list(summary["seed"]) == [0, 3]
    for row, m in zip(summary.itertuples(), means.values()):
        assert row.worst == pytest.approx(m.min()) and row.average == pytest.approx(m.mean())
        i, j = np.unravel_index(m.argmin(), m.shape)
        assert row.worst_point == f"fixed:a={(0.1, 0.2, 0.3)[i]},b={(1, 2)[j]}"
        assert row.points == 6 and row.episodes == 2


@pytest.fixture(scope="module")
def hopper_run(tmp_path_factory):
    pytest.importorskip("mujoco")
    from synthetic_runs import write_run

    return write_run(tmp_path_factory.mktemp("suite"), "r", seeds=(0, 1))


def test_parallel_result_equals_serial(hopper_run, monkeypatch):
    from adarl.results.runs import find_runs

    small = suites.Suite(
        "tiny", "hopper", (suites.Range("floor_friction", 0.5, 3.0), suites.Range("torso_mass", 0.5, 3.0)),
        "test", points=2, episodes=1,
    )  # fmt: skip
    monkeypatch.setitem(suites.SUITES, "tiny", {"hopper": small})
    runs = find_runs([hopper_run])
    kwargs = dict(max_steps=30, progress=False)
    (serial,) = suites.run_suite(runs, "tiny", workers=1, **kwargs)
    # spawned workers rebuild SUITES from the module, so they must not need "tiny": they get
    # fully planned units
    (parallel,) = suites.run_suite(runs, "tiny", workers=2, **kwargs)
    assert len(serial) == 4 * 2
    pd.testing.assert_frame_equal(serial, parallel)


def test_ray_backend_equals_serial(hopper_run, monkeypatch, local_ray_turn):
    pytest.importorskip("ray")
    from adarl.results.runs import find_runs

    runs = find_runs([hopper_run])
    kwargs = dict(max_steps=20, progress=False, episodes=1)
    (serial,) = suites.run_suite(runs, "m2td3-1d", workers=1, **kwargs)
    (on_ray,) = suites.run_suite(runs, "m2td3-1d", workers=2, backend="ray", **kwargs)
    assert len(serial) == 10 * 2
    pd.testing.assert_frame_equal(serial, on_ray)


def test_a_seeds_episode_count_is_that_of_its_point_with_the_fewest():
    """A point that ran fewer episodes (an interrupted evaluation) shows in the count."""
    rng = np.random.default_rng(1)
    table = constructed_table({0: rng.uniform(0, 100, (3, 2)), 3: rng.uniform(0, 100, (3, 2))}, 3)
    short = (table["seed"] == 3) & (table["dynamics"] == "fixed:a=0.2,b=2") & (table["episode"] > 0)
    summary = suites.seed_summary(table[~short], "s").set_index("seed")
    assert summary.at[0, "episodes"] == 3  # every point ran 3
    assert summary.at[3, "episodes"] == 1  # one point ran 1 of 3
    assert summary.at[3, "points"] == 6


@pytest.mark.parametrize("points", [1, 0, -3])
def test_fewer_than_two_points_per_dimension_are_refused(points):
    with pytest.raises(UsageError, match=rf"--points must be ≥ 2, got {points}") as err:
        suites.get_suite("m2td3-1d", "hopper", points)
    assert "\n" not in str(err.value)
    assert suites.get_suite("m2td3-1d", "hopper", 2).axes()[0].values == (0.1, 3.0)


def test_the_episode_budget_counts_every_seed(hopper_run, monkeypatch):
    """m2td3-2d at 2 points: 4 points x 2 seeds x 30 episodes = 240 episodes (120 per seed)."""
    from adarl.results.runs import find_runs

    runs = find_runs([hopper_run])
    assert len(runs[0].seeds) == 2
    monkeypatch.setattr(grid, "MAX_EPISODES", 239)
    with pytest.raises(UsageError, match="4 points x 2 seeds x 30 episodes are 240 episodes"):
        suites.plan_suite(runs, "m2td3-2d", points=2)
    monkeypatch.setattr(grid, "MAX_EPISODES", 240)
    assert len(suites.plan_suite(runs, "m2td3-2d", points=2)) == 4 * 2


def test_the_suites_episode_budget_counts_every_seed_of_every_run(
    hopper_run, tmp_path, monkeypatch
):
    """Two runs of 2 and 3 seeds: 4 points x 5 seeds x 30 episodes = 600, more than either
    run's own 240 and 360."""
    from synthetic_runs import write_run

    from adarl.results.runs import find_runs

    other = write_run(tmp_path, "other", seeds=(2, 3, 4))
    runs = find_runs([hopper_run, other])
    monkeypatch.setattr(grid, "MAX_EPISODES", 599)
    with pytest.raises(UsageError, match=r"4 points x 5 seeds x 30 episodes are 600 episodes"):
        suites.plan_suite(runs, "m2td3-2d", points=2)
    monkeypatch.setattr(grid, "MAX_EPISODES", 600)
    assert len(suites.plan_suite(runs, "m2td3-2d", points=2)) == 4 * 5
