"""The device Walker2d (`adarl.device.walker2d`, MJX) against the host task (`adarl.envs`, MuJoCo C).

Float64, four lanes in one vmapped computation (the nominal episode and three `paper` episodes,
their model fields from `adarl.device.physics`; each host env compiles its own episode's model):
the same initial states and actions give the same observation and reward to 1e-8 (measured
worst 1.9e-12 in the observation, 8.3e-14 in the reward) for 200 env steps per lane, with the same terminations; both sides restart from
the device's reset state after a termination, the host through ``mj_resetData`` as Gymnasium's
reset does (keeping the previous step's warm start put the groundwork test 2.2e-8 apart).
"""

import pytest
from host_compare import setup as build
from task_tests import check_against_host, check_reset_noise

from adarl.device import missing_reason

pytestmark = [
    pytest.mark.skipif(missing_reason() is not None, reason=str(missing_reason())),
    pytest.mark.slow,
]


@pytest.fixture(scope="module")
def setup():
    import jax

    with jax.enable_x64(True):
        yield build("walker2d")


def test_walker2d_matches_the_host_task_under_four_physics(setup):
    result = check_against_host(setup, 1e-8)
    assert result.termination_mismatches == 0
    assert result.terminations > 3  # random actions: restarts were exercised


def test_walker2d_reset_noise(setup):
    check_reset_noise(setup, "Walker2d-v5")


def test_walker2d_with_the_line_search_capped_at_4_still_matches_the_host_task():
    """`--device-solver 100,4` (the cap that made MJX 4.6 times faster on this CPU, 64 lanes):
    the same 1e-8 against MuJoCo C's XML solver, the same terminations."""
    import jax

    with jax.enable_x64(True):
        result = check_against_host(build("walker2d", solver=(100, 4)), 1e-8)
    assert result.termination_mismatches == 0 and result.terminations > 3
