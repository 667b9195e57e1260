"""Physical parameters of the tasks: what each one means and which values are allowed.

Every value a user can give (a `fixed:` string, a keyword override, a schedule built in code) is
checked here, before any MuJoCo model is built, and rejected with a one-line `UsageError`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from adarl.errors import UsageError


@dataclass(frozen=True)
class Param:
    """One physical parameter: its unit, meaning and the open/closed lower bound it must respect."""

    name: str
    unit: str
    meaning: str
    lower: float | None  # None: any finite number
    strict: bool  # True: value > lower; False: value >= lower

    @property
    def allowed(self) -> str:
        """The allowed values in words, e.g. 'a number > 0'."""
        if self.lower is None:
            return "any finite number"
        return f"a number {'>' if self.strict else '>='} {self.lower:g}"

    def check(self, value) -> float:
        """Return `value` as a float, or raise a one-line `UsageError` naming it and what is allowed."""
        try:
            number = float(value)
        except (TypeError, ValueError):
            number = math.nan
        ok = math.isfinite(number) and (
            self.lower is None or (number > self.lower if self.strict else number >= self.lower)
        )
        if not ok:
            raise UsageError(f"bad value {value!r} for {self.name}; allowed: {self.allowed}")
        return number


PARAMS: dict[str, Param] = {
    p.name: p
    for p in (
        Param("torso_length", "m", "torso capsule half-length", 0.0, True),
        Param("foot_length", "m", "foot capsule half-length (both feet on Walker2d)", 0.0, True),
        Param("gravity", "m/s^2", "gravity magnitude, pointing down", 0.0, False),
        Param("wind", "m/s", "head-wind speed along -x (opt.wind = (-W, 0, 0))", None, False),
        Param("mass_scale", "x", "factor on every body mass and inertia", 0.0, True),
        Param("friction_scale", "x", "factor on every geom friction coefficient", 0.0, False),
        Param("damping_scale", "x", "factor on every joint damping", 0.0, False),
        Param("stiffness", "N m/rad", "joint spring stiffness of the stiffened joints", 0.0, False),
        Param("actuator_scale", "x", "factor on every actuator gear (strength)", 0.0, True),
        # optional parameters (TaskSpec.optional_params): the M2TD3 / RRLS uncertainty sets
        Param("floor_friction", "", "sliding friction of the floor geom", 0.0, False),
        Param("torso_mass", "kg", "mass of the torso body (inertia kept)", 0.0, True),
        Param("thigh_mass", "kg", "mass of the (right) thigh body (inertia kept)", 0.0, True),
        Param("front_left_leg_mass", "kg", "mass of the front_left_leg body", 0.0, True),
        Param("front_right_leg_mass", "kg", "mass of the front_right_leg body", 0.0, True),
    )
}


#: A value a user gives (``fixed:``, ``:NAME=VALUE``, ``--hold``) must lie within this factor of
#: the task's default: |value| <= 10 x scale, and value >= scale / 10 where it must be > 0.
PLAUSIBLE_FACTOR = 10.0
#: The scale of a parameter whose default is 0 (wind, stiffness): a typical magnitude instead.
ZERO_DEFAULT_SCALE = {"wind": 2.0, "stiffness": 10.0, "gravity": 9.81}
#: Parameters whose published uncertainty sets reach further than `PLAUSIBLE_FACTOR`: M2TD3's
#: Ant leg masses go from 0.01 to 3.0 kg around a default of 0.039 kg (docs/evaluation.md).
WIDE_FACTOR = {
    name: 100.0
    for name in ("torso_mass", "thigh_mass", "front_left_leg_mass", "front_right_leg_mass")
}


def is_addressed(name) -> bool:
    """An addressed parameter name, `KIND:NAME.ATTR[i]` (adarl.envs.elements)?"""
    return (
        isinstance(name, str)
        and ":" in name
        and name.split(":", 1)[0]
        in (
            "body",
            "geom",
            "joint",
            "actuator",
        )
    )


# The addressed names' grammar, `KIND:NAME.ATTR[i]`, and each attribute's bound: here, below the
# model code, so that checking a name needs no MuJoCo (adarl.envs.elements writes the values).
@dataclass(frozen=True)
class Attr:
    """One addressable attribute: its unit, meaning, lower bound, whether the bound is strict,
    and how many components [i] it has (1: no index)."""

    unit: str
    meaning: str
    lower: float
    strict: bool
    size: int = 1


ATTRS: dict[str, dict[str, Attr]] = {
    "body": {"mass": Attr("kg", "mass of the body (inertia follows)", 0.0, True)},
    "geom": {
        "friction": Attr(
            "", "friction coefficient (0 sliding, 1 torsional, 2 rolling)", 0.0, False, 3
        ),
        "size": Attr("m", "geom size", 0.0, True, 3),
    },
    "joint": {
        "damping": Attr("N m s/rad", "joint damping", 0.0, False),
        "stiffness": Attr("N m/rad", "joint stiffness", 0.0, False),
        "armature": Attr("kg m^2", "joint armature", 0.0, False),
        "frictionloss": Attr("N m", "joint dry friction", 0.0, False),
    },
    "actuator": {"gear": Attr("", "actuator gear (strength)", 0.0, True)},
}
SYNTAX = "KIND:NAME.ATTR[i] with " + "; ".join(
    f"{kind}: {', '.join(attrs)}" for kind, attrs in ATTRS.items()
)
_ADDRESS = re.compile(r"^(body|geom|joint|actuator):(.+)\.([a-z]+)(?:\[(\d+)\])?$")


@dataclass(frozen=True)
class Address:
    """A parsed addressed parameter name."""

    kind: str
    element: str
    attr: str
    index: int

    @property
    def info(self) -> Attr:
        return ATTRS[self.kind][self.attr]


def parse_address(name: str) -> Address:
    """`KIND:NAME.ATTR[i]` -> `Address`, or a one-line `UsageError` saying what is allowed."""
    match = _ADDRESS.match(name.strip()) if isinstance(name, str) else None
    if not match:
        raise UsageError(f"malformed parameter {name!r}; allowed: {SYNTAX}")
    kind, element, attr, index = match.groups()
    if attr not in ATTRS[kind]:
        raise UsageError(
            f"unknown attribute {attr!r} in {name!r}; allowed for {kind}: {', '.join(ATTRS[kind])}"
        )
    i = int(index) if index is not None else 0
    if i >= ATTRS[kind][attr].size:
        allowed = (
            "no index" if ATTRS[kind][attr].size == 1 else f"[0] to [{ATTRS[kind][attr].size - 1}]"
        )
        raise UsageError(f"bad index [{i}] in {name!r}; allowed: {allowed}")
    return Address(kind, element, attr, i)


def parameter_key(name: str):
    """What `name` sets: itself, or for an addressed name its element and component, so that
    `geom:floor.friction` and `geom:floor.friction[0]` are the same parameter."""
    return parse_address(name) if is_addressed(name) else name


def check_once(names, where: str = "") -> None:
    """A one-line `UsageError` if two of `names` set the same parameter (`parameter_key`)."""
    seen: dict[object, str] = {}
    for name in names:
        key = parameter_key(name)
        if key in seen:
            same = "" if seen[key] == name else f" (as {seen[key]!r})"
            raise UsageError(f"parameter {name!r} given twice{where}{same}; allowed: once each")
        seen[key] = name


def param_info(name: str) -> Param:
    """The `Param` of a named parameter, or of an addressed one (its attribute's bound)."""
    if name in PARAMS:
        return PARAMS[name]
    if is_addressed(name):
        info = parse_address(name).info
        return Param(name, info.unit, info.meaning, info.lower, info.strict)
    raise UsageError(f"unknown parameter {name!r}")


def param_check(name: str, value) -> float:
    """`value` as a float of the sign `name` allows (`Param.check`), named or addressed."""
    return param_info(name).check(value)


def plausible_range(name: str, default: float) -> tuple[float, float, str]:
    """`(low, high, why)`: the values of `name` accepted from a user when the task's default is
    `default` (within `PLAUSIBLE_FACTOR` of it, and of the allowed sign)."""
    factor = WIDE_FACTOR.get(name, PLAUSIBLE_FACTOR)
    if is_addressed(name) and name.split(":", 1)[0] == "body":
        factor = 100.0  # a body's mass: M2TD3's published sets reach 100x (WIDE_FACTOR)
    info = param_info(name)
    scale = abs(default) or ZERO_DEFAULT_SCALE.get(name, 1.0)
    high = factor * scale
    low = scale / factor if info.strict else (-high if info.lower is None else 0.0)
    why = f"within {factor:g}x of {'its default' if default else 'a typical'} {scale:g}"
    return low, high, f"{why}; docs/envs.md"


def check_plausible(name: str, value: float, default: float) -> float:
    """`value` if it is within `PLAUSIBLE_FACTOR` of `default` (the task's), else a one-line
    `UsageError`: values far outside make MuJoCo unstable (a flood of warnings, NaN states)."""
    low, high, why = plausible_range(name, default)
    if not low <= value <= high:
        raise UsageError(
            f"implausible value {value:g} for {name}; allowed: {low:g} to {high:g} ({why})"
        )
    return value


def check_given(name: str, value, default: float) -> float:
    """A value a user gives for `name` (`fixed:NAME=VALUE`, a keyword, `--hold`): a number of
    the allowed sign within the plausible range around the task's `default`, as a float; else a
    one-line `UsageError` naming the value and that range (not only the sign)."""
    try:
        if type(value).__name__ in ("bool", "bool_"):  # True is 1 (numpy's too), no length
            raise UsageError(name)
        number = param_info(name).check(value)
    except UsageError:
        low, high, why = plausible_range(name, default)
        raise UsageError(
            f"bad value {value!r} for {name}; allowed: {low:g} to {high:g} "
            f"({param_info(name).allowed}, {why})"
        ) from None
    return check_plausible(name, number, default)


@dataclass(frozen=True)
class Sinusoid:
    """Episode-indexed parameter value ``center + amplitude * sin(frequency * i)``."""

    center: float
    amplitude: float
    frequency: float

    def __call__(self, episode: int) -> float:
        return self.center + self.amplitude * math.sin(self.frequency * episode)

    @property
    def low(self) -> float:
        """Smallest value the sinusoid reaches: center - |amplitude|."""
        return self.center - abs(self.amplitude)

    @property
    def high(self) -> float:
        """Largest value the sinusoid reaches: center + |amplitude|."""
        return self.center + abs(self.amplitude)

    def formula(self) -> str:
        """The formula as text, e.g. '0.4 + 0.2·sin(0.2·i)'."""
        sign = "-" if self.amplitude < 0 else "+"
        return f"{self.center:g} {sign} {abs(self.amplitude):g}·sin({self.frequency:g}·i)"
