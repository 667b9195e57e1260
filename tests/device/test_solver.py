"""`--device-solver` (adarl.device.tasks.solver_caps and make's `solver`): the XML's solver, or
its Newton and line-search iterations capped on a copy of the model.

Measured beside these tests (float64, tests/device/host_compare.py's four Hopper and Walker2d
lanes, 200 env steps, 2026-12-04): capping the line search at 4 (``100,4``) leaves the device
task exactly as far from MuJoCo C as the XML's solver (Hopper 9.6e-8, where C stops at its tolerance; Walker2d 1.9e-12, the same
terminations); capping Newton at 1 (``1,4``) does not (observation 1.8 and 18 apart, 9 and 14
terminations that differ): docs/envs.md, "Device physics"."""

import pytest

from adarl.device import missing_reason
from adarl.device.tasks import solver_caps
from adarl.errors import UsageError


@pytest.mark.parametrize("value, caps", [("xml", None), ("1,4", (1, 4)), ("100,4", (100, 4))])
def test_solver_caps_parse(value, caps):
    assert solver_caps(value) == caps


@pytest.mark.parametrize("value", ["", "4", "0,4", "1,0", "1,4,2", "-1,4", "1.5,4", "fast"])
def test_solver_caps_refuse_what_is_not_two_positive_integers(value):
    with pytest.raises(UsageError, match=f"device-solver must be .* got '{value}'"):
        solver_caps(value)


@pytest.mark.skipif(missing_reason() is not None, reason=str(missing_reason()))
def test_a_capped_task_runs_a_copy_with_the_caps():
    from adarl.device.common import gymnasium_model
    from adarl.device.tasks import RULES, make

    host = gymnasium_model(RULES["walker2d"].xml)
    xml = (int(host.opt.iterations), int(host.opt.ls_iterations))
    assert xml == (100, 50)  # Gymnasium's walker2d.xml leaves MuJoCo's defaults
    capped = make("walker2d", mj_model=host, solver=(3, 4))
    assert (capped.model.opt.iterations, capped.model.opt.ls_iterations) == (3, 4)
    assert (capped.mj_model.opt.iterations, capped.mj_model.opt.ls_iterations) == (3, 4)
    assert (int(host.opt.iterations), int(host.opt.ls_iterations)) == xml  # the caller's model
    plain = make("walker2d", mj_model=host)
    assert (plain.model.opt.iterations, plain.model.opt.ls_iterations) == xml
