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


def test_the_capped_solver_is_the_default_exactly_where_a_capped_comparison_passes():
    """`default_solver`: `100,4` for the tasks whose test module compares the capped device task
    with MuJoCo C in float64 (a `solver=(100, 4)` build: Hopper, Walker2d), `xml` elsewhere."""
    from pathlib import Path

    from adarl.device.tasks import RULES, default_solver

    here = Path(__file__).parent
    for task in RULES:
        compared = "solver=(100, 4)" in (here / f"test_{task}.py").read_text()
        assert (default_solver(task) == "100,4") == compared, task
    assert [t for t in RULES if default_solver(t) == "100,4"] == ["hopper", "walker2d"]


@pytest.mark.parametrize(
    ("flags", "solver"),
    [
        ({"backend": "device", "task": "hopper"}, "100,4"),
        ({"backend": "device", "task": "walker2d"}, "100,4"),
        ({"backend": "device", "task": "ant"}, "xml"),
        ({"backend": "device", "task": "humanoid"}, "xml"),
        ({"backend": "device", "task": "hopper", "device_solver": "xml"}, "xml"),
        ({"backend": "device", "task": "ant", "device_solver": "100,4"}, "100,4"),
        ({"task": "hopper"}, "xml"),  # the host backend: the field as it always was
    ],
)
def test_a_device_run_gets_its_tasks_default_solver_unless_it_names_one(flags, solver):
    from adarl.algos import registry

    assert registry.resolve_config("adarl", None, flags).device_solver == solver


def test_rnac_on_the_device_is_refused_in_one_line_saying_why():
    from adarl.algos import registry

    with pytest.raises(UsageError, match=r"^rnac trains on the host backend only: .*SAC family$"):
        registry.resolve_config("rnac", None, {"backend": "device"})
