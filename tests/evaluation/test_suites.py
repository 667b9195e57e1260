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


def test_rrls_grids_leave_the_upper_end_out():
    suite = suites.get_suite("rrls-3d", "walker2d")
    values = {a.name: a.values for a in suite.axes()}
    np.testing.assert_allclose(values["thigh_mass"], np.arange(0.1, 6.0, (6.0 - 0.1) / 10))
    assert len(values["thigh_mass"]) == 10 and max(values["thigh_mass"]) < 6.0
    assert [r.param for r in suite.ranges] == [
        r.param for r in suites.get_suite("m2td3-3d", "walker2d").ranges
    ]


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
