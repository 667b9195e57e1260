"""Dynamics grids for evaluation sweeps: parsing `--sweep P=LO..HI[:N]`, `--hold P=v` and
`--dynamics sweep:…`, and naming the grid's points and output files.

One range grammar across adarl (issue 62): a range is `LO..HI`, as `--dynamics uniform:P=LO..HI`
trains over it; a sweep samples it at N evenly spaced points, `P=LO..HI:N` (`P=LO..HI` alone:
`DEFAULT_POINTS`); `P=LO:HI:N` is the same sweep in the older spelling, still read.

`P` is a named parameter (`torso_length`, `mass_scale`) or an addressed one, `KIND:NAME.ATTR[i]`
(`body:torso.mass`, `geom:floor.friction[0]`: adarl.envs.elements), whose own colon is why a
name is split from its values at the last `=` (no value holds one).

A grid is the Cartesian product of its swept axes, with the held parameters fixed at one value;
every point is a dict `{parameter: value}` that is passed to the environment as fixed parameter
overrides on top of a base dynamics spec (`nominal` by default). Pure functions, no I/O.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from adarl.errors import UsageError
from adarl.train.guards import check_memory

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
#: The most episodes one `adarl evaluate` runs (points x seeds x episodes, over all its runs),
#: counted before any grid is built: 10⁷ episodes of up to 1,000 steps are 14 (Hopper) to 33
#: (Humanoid) core-days at the 8,000 and 3,500 steps/s one core of the project's machine runs
#: with a 256-256 policy (docs/reliability.md).
MAX_EPISODES = 10_000_000
#: Memory per episode until its run's table is written: its row as a dict and then a DataFrame
#: row, 3.3 kB for Hopper's 10 columns (tracemalloc), rounded up.
EPISODE_BYTES = 4096
SPLIT = "evaluate fewer points, episodes, seeds or runs per command"
#: Points of a `--sweep P=LO..HI` that gives no count (the training summary's suggestion too).
DEFAULT_POINTS = 9


def sweep_forms(name: str = "P") -> str:
    """The forms `--sweep` takes, for its error messages."""
    return (
        f"allowed: {name}=LO..HI[:N] (N evenly spaced points, both ends included, default "
        f"{DEFAULT_POINTS}), {name}=LO:HI:N (the same), {name}=V1,V2,… or {name}=V"
    )


def check_episodes(count: int, what: str) -> None:
    """A one-line UsageError if an evaluation of `count` episodes (`what`: how they add up) is
    more than `MAX_EPISODES` or its rows more than the machine's memory."""
    if count > MAX_EPISODES:
        raise UsageError(
            f"{what} are {count:,} episodes; allowed: at most {MAX_EPISODES:,} per command; {SPLIT}"
        )
    check_memory(count * EPISODE_BYTES, f"{what} ({count:,} episodes)", SPLIT)


@dataclass(frozen=True)
class Axis:
    """One swept parameter and the values it takes, in the order given."""

    name: str
    values: tuple[float, ...]
    text: str  # how the user wrote it, e.g. "torso_length=0.2:0.6:9"


def _number(text: str, what: str, allowed: str = "") -> float:
    allowed = f"; {allowed}" if allowed else ""
    try:
        value = float(text)
    except ValueError:
        raise UsageError(f"{what}: {text.strip()!r} is not a number{allowed}") from None
    if not math.isfinite(value):
        raise UsageError(f"{what}: {text.strip()!r} is not a finite number{allowed}")
    return value


def _clean(value: float) -> float:
    """Round away floating-point noise from linspace (0.30000000000000004 -> 0.3)."""
    return float(f"{value:.12g}")


def _split_assignment(text: str, flag: str) -> tuple[str, str]:
    """`PARAM=VALUE` -> (PARAM, VALUE), split at the last `=`: an addressed name holds a colon,
    as `LO:HI:N` does, and no value holds an `=`."""
    name, sep, rhs = text.rpartition("=")
    name = name.strip()
    if not sep or not rhs.strip() or not name:
        forms = "P=LO..HI[:N], P=V1,V2,… or P=V" if flag == "--sweep" else "P=V"
        raise UsageError(f"{flag} {text!r}: expected PARAM=VALUE; allowed: {forms}")
    check_name(name, f"{flag} {text!r}")
    return name, rhs.strip()


def check_name(name: str, what: str) -> None:
    """A one-line `UsageError` unless `name` is a parameter name (`torso_length`) or a
    well-formed addressed one (`KIND:NAME.ATTR[i]`; whether the element exists is the task's
    to say, `build_grid`)."""
    from adarl.envs.params import is_addressed

    if is_addressed(name):
        from adarl.envs.params import parse_address

        try:
            parse_address(name)
        except UsageError as exc:
            raise UsageError(f"{what}: {exc}") from None
    elif not _NAME.match(name):
        raise UsageError(
            f"{what}: {name!r} is not a parameter name; allowed: a task's parameter "
            "(adarl tasks TASK) or KIND:NAME.ATTR[i] such as body:torso.mass"
        )


def parse_axis(text: str, episodes: int = 1) -> Axis:
    """Parse one `--sweep` value.

    Forms: `P=LO..HI:N` (N evenly spaced values from LO to HI, both included, as
    numpy.linspace), `P=LO..HI` (`DEFAULT_POINTS` of them), `P=LO:HI:N` (the older spelling of
    the first), `P=v1,v2,…` (explicit values) or `P=v` (a single value). N must be a positive
    integer; n = 0 or an empty list is an empty grid and raises `UsageError`, and so does an n
    whose points at `episodes` each are more than an evaluation may run (`check_episodes`),
    before any value is computed. Every error names the forms.
    """
    name, rhs = _split_assignment(text, "--sweep")
    what = f"--sweep {text!r}"
    forms = sweep_forms(name)
    if "@" in rhs:
        raise UsageError(
            f"{what}: @FREQUENCY is for training schedules (--dynamics paper:P=LO..HI@F); {forms}"
        )
    if ".." in rhs:
        span, colon, count = rhs.partition(":")
        bounds = span.split("..")
        if len(bounds) != 2 or ":" in count:
            raise UsageError(f"{what}: expected {name}=LO..HI[:N], e.g. {name}=0.2..0.6:9; {forms}")
        lo, hi = (_number(b, what, forms) for b in bounds)
        n_text = count if colon else str(DEFAULT_POINTS)
    elif ":" in rhs:
        parts = rhs.split(":")
        if len(parts) != 3:
            raise UsageError(f"{what}: expected {name}=LO..HI[:N], e.g. {name}=0.2..0.6:9; {forms}")
        lo, hi = _number(parts[0], what, forms), _number(parts[1], what, forms)
        n_text = parts[2]
    else:
        items = [item.strip() for item in rhs.split(",")]
        if not any(items):
            raise UsageError(f"{what}: empty grid (no values); {forms}")
        values = tuple(_clean(_number(item, what, forms)) for item in items if item)
        if len(set(values)) != len(values):
            raise UsageError(f"{what}: repeated values {list(values)}")
        return Axis(name=name, values=values, text=text)
    try:
        n = int(n_text)
    except ValueError:
        raise UsageError(
            f"{what}: the number of points {n_text.strip()!r} is not an integer; {forms}"
        ) from None
    if n < 0:
        raise UsageError(f"{what}: the number of points must be ≥ 1, got {n}; {forms}")
    if n == 0:
        raise UsageError(f"{what}: empty grid (0 points); use N ≥ 1")
    if n == 1 and lo != hi:
        raise UsageError(f"{what}: one point cannot span {lo:g}..{hi:g}; use N ≥ 2 or LO = HI")
    check_episodes(n * episodes, f"{what}: {n:,} points x {episodes} episodes")
    values = tuple(_clean(v) for v in np.linspace(lo, hi, n))
    if len(set(values)) != len(values):
        raise UsageError(f"{what}: repeated values {list(values)}")
    return Axis(name=name, values=values, text=text)


def parse_hold(text: str) -> tuple[str, float]:
    """Parse one `--hold P=v` value into `(P, v)`; a range is a one-line error pointing at
    `--sweep`."""
    name, rhs = _split_assignment(text, "--hold")
    if ".." in rhs or ":" in rhs:
        raise UsageError(
            f"--hold {text!r}: --hold takes one value, {name}=V; to vary {name} use "
            f"--sweep {name}={rhs}"
        )
    return name, _clean(_number(rhs, f"--hold {text!r}", f"allowed: {name}=V, one number"))


def split_dynamics(spec: str, episodes: int = 1) -> tuple[str, list[Axis], list[tuple[str, float]]]:
    """Split a `--dynamics` value into a base spec, swept axes and held values.

    `sweep:torso_length=0.2..0.6:9,foot_length=0.39` sweeps torso_length over the nominal
    dynamics and holds foot_length (an item with a range, LO..HI[:N] or LO:HI:N, is swept, a
    single value is held). Any other spec
    (`nominal`, `default`, `paper`, `fixed:…`) is returned as the base with no axes.
    """
    spec = spec.strip()
    if not spec.startswith("sweep:"):
        if not spec:
            raise UsageError(
                "--dynamics is empty; allowed: nominal, default, fixed:P=V,…, sweep:P=LO..HI[:N],…"
            )
        return spec, [], []
    body = spec[len("sweep:") :]
    axes, holds = [], []
    for item in (part.strip() for part in body.split(",")):
        if not item:
            continue
        value = item.rpartition("=")[2]
        if ":" in value or ".." in value:
            axes.append(parse_axis(item, episodes))
        else:
            holds.append(parse_hold(item))
    if not axes:
        raise UsageError(f"--dynamics {spec!r}: empty grid (no P=LO..HI[:N] item to sweep)")
    return "nominal", axes, holds


def build_grid(
    axes: Sequence[Axis],
    holds: Iterable[tuple[str, float]],
    allowed: Iterable[str],
    task: str = "",
    addressed: Callable[[str], object] | None = None,
) -> list[dict[str, float]]:
    """All points of the grid, in row-major order of `axes` (the last axis varies fastest).

    Checks that every parameter is one of `allowed` (the task's parameters) or, where the task
    has addressable elements, an addressed name `addressed` accepts (it raises a one-line
    `UsageError` naming an element the model does not have), and that none is swept twice or
    both swept and held (`geom:floor.friction` is `geom:floor.friction[0]`); raises a one-line
    `UsageError` otherwise. With no axes the grid is the single point of the held values
    (possibly empty: the base dynamics alone).
    """
    from adarl.envs.params import is_addressed, parameter_key

    allowed = list(allowed)
    holds = list(holds)
    where = f" of task {task}" if task else ""
    seen: dict[object, str] = {}
    for name in [a.name for a in axes] + [h[0] for h in holds]:
        if is_addressed(name) and addressed is not None:
            addressed(name)
        elif name not in allowed:
            more = " or KIND:NAME.ATTR (body:torso.mass, ...)" if addressed is not None else ""
            raise UsageError(
                f"unknown parameter {name!r}{where}; allowed: "
                f"{', '.join(allowed) or '(none: fixed dynamics)'}{more}"
            )
        key = parameter_key(name)
        if key in seen:
            same = "" if seen[key] == name else f" (as {seen[key]!r})"
            raise UsageError(f"parameter {name!r} is swept or held more than once{same}")
        seen[key] = name
    points = []
    for combo in itertools.product(*(a.values for a in axes)):
        point = {a.name: v for a, v in zip(axes, combo)}
        point.update(dict(holds))
        points.append(point)
    if not points:
        raise UsageError("empty grid: no dynamics to evaluate")
    return points


def format_value(value: float) -> str:
    return f"{value:g}"


def point_label(base: str, point: dict[str, float]) -> str:
    """The dynamics spec of one grid point: the base with the point's values as overrides, in
    the syntax `adarl.envs.parse_dynamics` reads (`nominal:torso_length=0.3,foot_length=0.39`,
    `fixed:a=1` + b=2 -> `fixed:a=1,b=2`), so it can be passed to `adarl play --dynamics`."""
    if not point:
        return base
    values = ",".join(f"{k}={format_value(v)}" for k, v in point.items())
    return f"{base}{',' if ':' in base else ':'}{values}"


def evaluation_name(
    base: str,
    axes: Sequence[Axis] = (),
    holds: Iterable[tuple[str, float]] = (),
    step: int | None = None,
) -> str:
    """A file-name-safe name for an evaluation, e.g. `nominal` or
    `sweep-torso_length-0.2-0.6-9_hold-foot_length-0.39` (plus `_step-N` for a chosen checkpoint).
    """
    parts = [] if axes else [base]
    if axes and base != "nominal":
        parts.append(base)
    for a in axes:
        vals = a.values
        parts.append(f"sweep-{a.name}-{format_value(vals[0])}-{format_value(vals[-1])}-{len(vals)}")
    for name, value in holds:
        parts.append(f"hold-{name}-{format_value(value)}")
    if step is not None:
        parts.append(f"step-{step}")
    name = re.sub(r"\[(\d+)\]", r".\1", "_".join(parts))  # friction[1] -> friction.1
    return re.sub(r"[^A-Za-z0-9_.=+-]+", "-", name).strip("-") or "evaluation"
