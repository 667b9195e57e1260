"""The sweep grid parser: `--sweep P=lo:hi:n`, `--hold P=v`, `--dynamics sweep:…`, names."""

import pytest

from adarl.errors import UsageError
from adarl.evaluation import grid

HOPPER = ["torso_length", "foot_length", "mass_scale", "friction_scale", "damping_scale"]


def test_linspace_axis_includes_both_ends_without_float_noise():
    axis = grid.parse_axis("torso_length=0.2:0.6:9")
    assert axis.name == "torso_length"
    assert axis.values == (0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6)


def test_list_and_single_value_axes():
    assert grid.parse_axis("mass_scale=0.5,1,2").values == (0.5, 1.0, 2.0)
    assert grid.parse_axis("wind=3").values == (3.0,)
    assert grid.parse_axis("gravity=9.81:9.81:1").values == (9.81,)


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("torso_length=0.2:0.6:0", "empty grid"),
        ("torso_length=0.2:0.6:-3", "≥ 1"),
        ("torso_length=0.2:0.6:x", "not an integer"),
        ("torso_length=0.2:0.6", "LO:HI:N"),
        ("torso_length=a:0.6:3", "not a number"),
        ("torso_length=", "PARAM=VALUE"),
        ("torso_length", "PARAM=VALUE"),
        ("torso_length=0.2:0.6:1", "one point"),
        ("torso_length=0.2,0.2", "repeated"),
        ("torso_length=nan", "finite"),
    ],
)
def test_bad_axes_raise_one_line_usage_errors(text, fragment):
    with pytest.raises(UsageError) as err:
        grid.parse_axis(text)
    assert fragment in str(err.value) and "\n" not in str(err.value)


def test_hold():
    assert grid.parse_hold("foot_length=0.39") == ("foot_length", 0.39)
    with pytest.raises(UsageError, match="not a number"):
        grid.parse_hold("foot_length=big")


def test_dynamics_sweep_form_splits_axes_and_holds():
    base, axes, holds = grid.split_dynamics("sweep:torso_length=0.2:0.6:3,foot_length=0.39")
    assert base == "nominal"
    assert [(a.name, a.values) for a in axes] == [("torso_length", (0.2, 0.4, 0.6))]
    assert holds == [("foot_length", 0.39)]
    assert grid.split_dynamics("fixed:torso_length=0.5") == ("fixed:torso_length=0.5", [], [])
    with pytest.raises(UsageError, match="empty grid"):
        grid.split_dynamics("sweep:foot_length=0.39")


def test_grid_is_the_product_with_the_last_axis_fastest():
    axes = [grid.parse_axis("torso_length=0.2:0.4:2"), grid.parse_axis("mass_scale=1,2")]
    points = grid.build_grid(axes, [("foot_length", 0.39)], HOPPER, "hopper")
    assert points == [
        {"torso_length": 0.2, "mass_scale": 1.0, "foot_length": 0.39},
        {"torso_length": 0.2, "mass_scale": 2.0, "foot_length": 0.39},
        {"torso_length": 0.4, "mass_scale": 1.0, "foot_length": 0.39},
        {"torso_length": 0.4, "mass_scale": 2.0, "foot_length": 0.39},
    ]
    assert grid.build_grid([], [], HOPPER) == [{}]


def test_unknown_and_repeated_parameters_are_refused():
    with pytest.raises(UsageError) as err:
        grid.build_grid([grid.parse_axis("gravity=5:15:3")], [], HOPPER, "hopper")
    message = str(err.value)
    assert "'gravity'" in message and "hopper" in message and "torso_length" in message
    with pytest.raises(UsageError, match="more than once"):
        grid.build_grid(
            [grid.parse_axis("torso_length=0.2:0.4:2")], [("torso_length", 0.3)], HOPPER
        )


def test_point_labels_are_dynamics_specs_and_names_are_file_safe():
    point = {"torso_length": 0.25, "foot_length": 0.39}
    assert grid.point_label("nominal", point) == "nominal:torso_length=0.25,foot_length=0.39"
    assert grid.point_label("fixed:mass_scale=2", {"wind": 1}) == "fixed:mass_scale=2,wind=1"
    assert grid.point_label("nominal", {}) == "nominal"
    axes = [grid.parse_axis("torso_length=0.2:0.6:9")]
    assert (
        grid.evaluation_name("nominal", axes, [("foot_length", 0.39)])
        == "sweep-torso_length-0.2-0.6-9_hold-foot_length-0.39"
    )
    assert grid.evaluation_name("nominal") == "nominal"
    assert grid.evaluation_name("nominal", step=5000) == "nominal_step-5000"
    assert "/" not in grid.evaluation_name("fixed:torso_length=0.5,foot_length=0.3")


def test_addressed_names_are_split_from_their_values_at_the_last_equals_sign():
    axis = grid.parse_axis("body:torso.mass=4:9:3")
    assert (axis.name, axis.values) == ("body:torso.mass", (4.0, 6.5, 9.0))
    assert grid.parse_axis("geom:floor.friction[1]=0.1,0.2").name == "geom:floor.friction[1]"
    assert grid.parse_hold("joint:bthigh.damping=3") == ("joint:bthigh.damping", 3.0)
    base, axes, holds = grid.split_dynamics(
        "sweep:body:torso.mass=4:9:2,geom:floor.friction=0.5,mass_scale=0.5:1:2"
    )
    assert base == "nominal"
    assert [(a.name, a.values) for a in axes] == [
        ("body:torso.mass", (4.0, 9.0)),
        ("mass_scale", (0.5, 1.0)),
    ]
    assert holds == [("geom:floor.friction", 0.5)]


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("body:torso.masss=1:2:2", "unknown attribute 'masss'"),
        ("body:torso=1", "malformed parameter 'body:torso'"),
        ("geom:floor.friction[3]=1", "bad index [3]"),
        ("site:tip.x=1", "'site:tip.x' is not a parameter name"),
        ("body:torso.mass=", "PARAM=VALUE"),
    ],
)
def test_bad_addressed_names_are_one_line_errors(text, fragment):
    with pytest.raises(UsageError) as err:
        grid.parse_axis(text)
    assert fragment in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_addressed_names_in_a_grid_go_through_the_tasks_check():
    checked = []

    def exists(name):
        checked.append(name)
        if "nothing" in name:
            raise UsageError(f"unknown body 'nothing' in {name!r}")

    axes = [grid.parse_axis("body:torso.mass=4:9:2")]
    holds = [("geom:floor.friction", 0.5)]
    points = grid.build_grid(axes, holds, ["mass_scale"], "HalfCheetah-v5", exists)
    assert points == [
        {"body:torso.mass": 4.0, "geom:floor.friction": 0.5},
        {"body:torso.mass": 9.0, "geom:floor.friction": 0.5},
    ]
    assert checked == ["body:torso.mass", "geom:floor.friction"]
    with pytest.raises(UsageError, match="unknown body 'nothing'"):
        grid.build_grid([grid.parse_axis("body:nothing.mass=1,2")], [], [], "x", exists)
    # friction without an index is its sliding component, friction[0]
    with pytest.raises(UsageError, match=r"more than once \(as 'geom:floor.friction'\)"):
        grid.build_grid(axes, [*holds, ("geom:floor.friction[0]", 0.4)], [], "x", exists)
    grid.build_grid(axes, [*holds, ("geom:floor.friction[1]", 0.1)], [], "x", exists)
    # a task without addressable elements (fixed dynamics) refuses them
    with pytest.raises(UsageError) as err:
        grid.build_grid(axes, [], [], "Pendulum-v1")
    assert "unknown parameter 'body:torso.mass' of task Pendulum-v1" in str(err.value)
    assert "(none: fixed dynamics)" in str(err.value)


def test_addressed_names_in_file_names():
    axes = [grid.parse_axis("body:torso.mass=4:9:3"), grid.parse_axis("geom:floor.friction[1]=1,2")]
    name = grid.evaluation_name("nominal", axes, [("joint:bthigh.damping", 3.0)])
    assert name == (
        "sweep-body-torso.mass-4-9-3_sweep-geom-floor.friction.1-1-2-2_hold-joint-bthigh.damping-3"
    )
    label = grid.point_label("fixed", {"body:torso.mass": 4.0, "geom:floor.friction[1]": 1.0})
    assert label == "fixed:body:torso.mass=4,geom:floor.friction[1]=1"


def test_one_range_grammar_lo_dot_dot_hi_with_an_optional_point_count():
    """Issue 62: a range is LO..HI everywhere; a sweep over it takes N points (LO..HI:N, default
    9); LO:HI:N is the same sweep in the older spelling."""
    nine = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
    assert grid.parse_axis("body:bob.mass=0.2..1.0").values == nine
    assert grid.parse_axis("body:bob.mass=0.2..1.0:9").values == nine
    assert grid.parse_axis("body:bob.mass=0.2:1.0:9").values == nine
    assert grid.parse_axis("wind=-1..1:3").values == (-1.0, 0.0, 1.0)
    assert grid.DEFAULT_POINTS == 9
    base, axes, holds = grid.split_dynamics("sweep:torso_length=0.2..0.6:3,foot_length=0.39")
    assert [(a.name, a.values) for a in axes] == [("torso_length", (0.2, 0.4, 0.6))]
    assert holds == [("foot_length", 0.39)]
    # the same grid, however it is written, is the same evaluation (file name)
    assert grid.evaluation_name("nominal", [grid.parse_axis("torso_length=0.2..0.6:3")]) == (
        grid.evaluation_name("nominal", [grid.parse_axis("torso_length=0.2:0.6:3")])
    )


@pytest.mark.parametrize(
    "parse, text, fragment",
    [
        (grid.parse_axis, "body:bob.mass=a..1.0", "'a' is not a number"),
        (grid.parse_axis, "body:bob.mass=0.2..1.0:x", "not an integer"),
        (grid.parse_axis, "body:bob.mass=0.2..1.0@0.3", "@FREQUENCY is for training"),
        (grid.parse_axis, "body:bob.mass=0.2-1.0", "'0.2-1.0' is not a number"),
        (grid.parse_axis, "body:bob.mass=0.2:1.0", "LO..HI[:N]"),
        (grid.parse_axis, "body:bob.mass=1.0..0.2..3", "LO..HI[:N]"),
        (grid.parse_hold, "body:bob.mass=0.2..1.0", "--sweep body:bob.mass=0.2..1.0"),
        (grid.parse_hold, "body:bob.mass=heavy", "allowed: body:bob.mass=V"),
    ],
)
def test_range_errors_show_the_form_wanted(parse, text, fragment):
    with pytest.raises(UsageError) as err:
        parse(text)
    message = str(err.value)
    assert fragment in message and "\n" not in message
    if parse is grid.parse_axis:  # every --sweep error shows the forms it takes
        assert "body:bob.mass=LO..HI[:N]" in message
