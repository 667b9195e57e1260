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
