"""Dynamics schedules against their documented rules (docs/envs.md, "Dynamics schedules" and
"Ranges"): the values are computed here by hand from the formula the docs state, not by the
schedule under test."""

import math

import numpy as np
import pytest

from adarl.envs import DynamicsSchedule, Sinusoid, make, parse_dynamics
from adarl.errors import UsageError


def test_a_negative_amplitude_keeps_its_sign():
    s = Sinusoid(5.0, -2.0, 0.5)
    for i in (1, 2, 9):
        assert s(i) == 5.0 - 2.0 * math.sin(0.5 * i)
    assert (s.low, s.high) == (3.0, 7.0)
    assert s.formula() == "5 - 2·sin(0.5·i)"
    sched = DynamicsSchedule("HalfCheetah-v5", sinusoids={"body:torso.mass": s})
    assert sched.params_for_episode(1)["body:torso.mass"] == 5.0 - 2.0 * math.sin(0.5)
    assert sched.ranges()["body:torso.mass"] == (3.0, 7.0)


@pytest.mark.parametrize("amplitude", [2.0, -2.0])
@pytest.mark.parametrize(
    "task, name", [("HalfCheetah-v5", "body:torso.mass"), ("HalfCheetah-v5", "mass_scale")]
)
def test_a_sinusoid_reaching_a_negative_mass_is_refused_whatever_its_amplitudes_sign(
    task, name, amplitude
):
    # 1 ± 2·sin(f·i) reaches -1: a negative mass, for either sign of the amplitude
    with pytest.raises(UsageError, match="-1") as info:
        DynamicsSchedule(task, sinusoids={name: Sinusoid(1.0, amplitude, 0.5)})
    assert "\n" not in str(info.value)
    with pytest.raises(UsageError, match="-1"):
        DynamicsSchedule(task, sinusoids={name: Sinusoid(1.0, amplitude, 0.5)}, mode="uniform")


def test_a_uniform_draw_stays_within_the_range_of_a_negative_amplitude():
    sched = DynamicsSchedule(
        "hopper", sinusoids={"torso_length": Sinusoid(0.4, -0.2, 0.2)}, mode="uniform"
    )
    values = [sched.params_for_episode(i)["torso_length"] for i in range(200)]
    assert 0.2 <= min(values) and max(values) <= 0.6 + 1e-12
    assert max(values) - min(values) > 0.3


def test_a_uniform_draw_without_an_rng_is_the_documented_default_rng_0_i():
    # docs/envs.md: the draw of episode i uses numpy.random.default_rng([seed, i]) (seed 0 here)
    sched = DynamicsSchedule(
        "hopper", sinusoids={"torso_length": Sinusoid(0.4, 0.2, 0.2)}, mode="uniform"
    )
    for i in (0, 1, 7, 50):
        expected = np.random.default_rng([0, i]).uniform(0.2, 0.6)
        assert sched.params_for_episode(i)["torso_length"] == pytest.approx(expected, rel=1e-12)


def test_a_uniform_task_draws_episode_i_from_default_rng_seed_i():
    sched = DynamicsSchedule(
        "hopper", sinusoids={"torso_length": Sinusoid(0.4, 0.2, 0.2)}, mode="uniform"
    )
    env = make("hopper", sched, seed=3)
    for i in range(3):
        got = env.reset()[1]["dynamics"]["torso_length"]
        expected = np.random.default_rng([3, i]).uniform(0.2, 0.6)
        assert got == pytest.approx(expected, rel=1e-12)
    env.close()


@pytest.mark.parametrize(
    "task, dynamics, name, centre, amplitude, frequency",
    [
        # the schedule's own frequency: Walker2d's paper sinusoids run at 0.3, Hopper's at 0.2
        ("walker2d", "paper:foot_length=0.05..0.15", "foot_length", 0.1, 0.05, 0.3),
        ("hopper", "paper:torso_length=0.3..0.5", "torso_length", 0.4, 0.1, 0.2),
        # an explicit @F wins
        ("walker2d", "paper:foot_length=0.05..0.15@0.7", "foot_length", 0.1, 0.05, 0.7),
        # a generic task's paper schedule runs at 0.5
        ("HalfCheetah-v5", "paper:body:torso.mass=4..8", "body:torso.mass", 6.0, 2.0, 0.5),
    ],
)
def test_a_range_without_a_frequency_varies_at_the_schedules_own(
    task, dynamics, name, centre, amplitude, frequency
):
    sched = parse_dynamics(dynamics, task)
    for i in (1, 2, 5, 11):
        expected = centre + amplitude * math.sin(frequency * i)
        assert sched.params_for_episode(i)[name] == pytest.approx(expected, rel=1e-12)


def test_a_range_added_to_a_schedule_built_in_code_takes_its_frequency():
    slow = DynamicsSchedule("HalfCheetah-v5", sinusoids={"mass_scale": Sinusoid(1.0, 0.1, 0.05)})
    sched = slow.with_overrides(**{"body:torso.mass": "4..8"})
    for i in (1, 3, 20):
        expected = 6.0 + 2.0 * math.sin(0.05 * i)
        assert sched.params_for_episode(i)["body:torso.mass"] == pytest.approx(expected, rel=1e-12)
