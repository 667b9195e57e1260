"""Dynamics schedules: the physical parameters of each episode, as a function of its index i.

A schedule names every parameter of its task. Parameters with a `Sinusoid` vary with the episode
index (``c + a·sin(f·i)``, or, in `uniform` mode, a uniform draw from ``[c - |a|, c + |a|]``); the
others are constants. Modes by name (see `parse_dynamics`):

  paper     the AdaRL appendix formulas            ompo     same, Hopper amplitudes 0.1 (OMPO code)
  nominal   the centroid c of each formula         uniform  per-episode draws over the paper's ranges
  fixed     user values, e.g. fixed:torso_length=0.5,foot_length=0.39 (others at Gymnasium defaults)
  default   Gymnasium's own model, untouched (no recompile, no air for Ant/Humanoid)

Any mode but `default` takes overrides after a colon: ``paper:mass_scale=1.2``. A task's optional
parameters (`TaskSpec.optional_params`: body masses, floor friction) are part of a schedule only
when it sets them. On a task outside the paper's four, a spec that gives a range
(``uniform:body:bob.mass=0.2..1``) varies only the ranges it gives: the generic schedule's
mass_scale and friction_scale stay at 1 unless named (`DynamicsSchedule.inherited`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from adarl.envs.params import Sinusoid, check_given, check_once, param_check, parameter_key
from adarl.envs.tasks import TaskSpec, get_task
from adarl.errors import UsageError, check_choice

#: Schedule names `parse_dynamics` understands.
KINDS = ("paper", "ompo", "nominal", "uniform", "fixed", "default")
#: How a schedule turns its sinusoids into values.
MODES = ("sinusoid", "uniform", "default")
_SYNTAX = "paper, ompo, nominal, uniform, default, fixed:NAME=VALUE[,NAME=VALUE...]"


@dataclass(frozen=True)
class DynamicsSchedule:
    """Episode index -> physical parameters of one task.

    Build one by name with `parse_dynamics`, or in code, e.g.
    ``DynamicsSchedule("hopper", sinusoids={"torso_length": Sinusoid(0.4, 0.1, 0.2)})``;
    constants left out take the task's Gymnasium defaults.
    """

    task: str | TaskSpec
    name: str = "custom"
    constants: Mapping[str, float] = field(default_factory=dict)
    sinusoids: Mapping[str, Sinusoid] = field(default_factory=dict)
    mode: str = "sinusoid"
    #: sinusoids the base schedule brought without the user naming them: on a task outside the
    #: paper's four, the generic schedule's (mass_scale, friction_scale). A range given to
    #: `with_overrides` drops those it does not name (they go back to their defaults), so that a
    #: spec with ranges varies what it names and nothing else.
    inherited: tuple[str, ...] = field(default=(), compare=False)

    def __post_init__(self):
        spec = get_task(self.task)
        check_choice("dynamics mode", self.mode, MODES)
        for name in (*self.constants, *self.sinusoids):
            _check_name(spec, name)
        both = set(self.constants) & set(self.sinusoids)
        if both:
            raise UsageError(
                f"parameter {sorted(both)[0]!r} is both constant and varying; allowed: one of the two"
            )
        check_once([*self.constants, *self.sinusoids])  # body:a.mass is body:a.mass[0]
        for name, s in self.sinusoids.items():
            if name in spec.optional_params and spec.paper:
                raise UsageError(
                    f"parameter {name!r} cannot vary; allowed: a constant value (optional "
                    f"parameters of {spec.name}: {', '.join(spec.optional_params)})"
                )
            if not isinstance(s, Sinusoid):
                raise UsageError(f"bad varying value {s!r} for {name}; allowed: a Sinusoid")
            param_check(name, s.low), param_check(name, s.high)
        constants = {
            p: param_check(p, self.constants.get(p, default))
            for p, default in spec.params.items()
            if p not in self.sinusoids
        }
        # optional parameters (then addressed ones, in the order given) only where set
        extra = [p for p in spec.optional_params if p in self.constants or p in self.sinusoids]
        extra += [p for p in (*self.constants, *self.sinusoids) if _addressed(p) and p not in extra]
        constants |= {p: param_check(p, self.constants[p]) for p in extra if p in self.constants}
        if self.mode == "default" and (self.sinusoids or constants != dict(spec.params)):
            raise _default_takes_no_values("default")
        object.__setattr__(self, "task", spec.name)
        object.__setattr__(self, "spec", spec)
        object.__setattr__(self, "constants", constants)
        order = (*spec.params, *extra)
        object.__setattr__(
            self, "sinusoids", {p: self.sinusoids[p] for p in order if p in self.sinusoids}
        )
        object.__setattr__(self, "_order", order)
        object.__setattr__(
            self, "inherited", tuple(p for p in self.inherited if p in self.sinusoids)
        )

    @property
    def varies(self) -> bool:
        """Whether the parameters change from episode to episode."""
        return bool(self.sinusoids)

    @property
    def needs_rng(self) -> bool:
        """Whether `params_for_episode` draws random numbers (uniform mode)."""
        return self.mode == "uniform" and self.varies

    def params_for_episode(
        self, i: int, rng: np.random.Generator | None = None
    ) -> dict[str, float]:
        """Parameters of episode `i` (>= 0): ``c + a·sin(f·i)`` per varying parameter, or in
        uniform mode one ``rng.uniform(c - |a|, c + |a|)`` draw each (rng=None: ``default_rng([0, i])``)."""
        if isinstance(i, bool) or not isinstance(i, int | np.integer) or i < 0:
            raise UsageError(f"bad episode index {i!r}; allowed: an integer >= 0")
        if self.needs_rng:
            rng = np.random.default_rng([0, int(i)]) if rng is None else rng
            varied = {p: float(rng.uniform(s.low, s.high)) for p, s in self.sinusoids.items()}
        else:
            varied = {p: s(i) for p, s in self.sinusoids.items()}
        return {p: varied[p] if p in varied else self.constants[p] for p in self._order}

    def centroid(self) -> dict[str, float]:
        """The nominal parameters: each sinusoid's centre c, constants as they are."""
        return {
            p: self.sinusoids[p].center if p in self.sinusoids else self.constants[p]
            for p in self._order
        }

    def ranges(self) -> dict[str, tuple[float, float]]:
        """(low, high) each parameter takes: ``c ∓ |a|`` for varying ones, (v, v) for constants."""
        return {
            p: (self.sinusoids[p].low, self.sinusoids[p].high)
            if p in self.sinusoids
            else (self.constants[p],) * 2
            for p in self._order
        }

    def formulas(self) -> dict[str, str]:
        """Each parameter as text: a formula, a uniform range, or a constant."""
        out = {}
        for p in self._order:
            s = self.sinusoids.get(p)
            if s is None:
                out[p] = f"{self.constants[p]:g}"
            elif self.mode == "uniform":
                out[p] = f"U[{s.low:g}, {s.high:g}]"
            else:
                out[p] = s.formula()
        return out

    def with_overrides(self, **values) -> DynamicsSchedule:
        """A copy with `values` on top: a number fixes a parameter (its sinusoid dropped), a
        range `"LOW..HIGH"` (or `"LOW..HIGH@F"`) makes it vary over [LOW, HIGH]: a sinusoid of
        centre (LOW+HIGH)/2, amplitude (HIGH-LOW)/2 and frequency F (default: the schedule's, or
        0.5) in `paper`/`ompo`, a uniform draw in `uniform`. The name records them. Where
        `values` hold a range, the `inherited` sinusoids they do not name are dropped (back to
        their defaults): the schedule varies what is named and nothing else."""
        if not values:
            return self
        if self.mode == "default":
            raise _default_takes_no_values(f"{self.name} with {', '.join(values)}")
        spec = self.spec
        for name in values:
            _check_name(spec, name)
        check_once(values)
        replaced = {parameter_key(k) for k in values}  # under any spelling
        fixed, varying = {}, {}
        for k, v in values.items():
            _check_not_a_grid(k, v, self.name)
            if isinstance(v, str) and ".." in v:
                varying[k] = self._range(spec, k, v)
            else:
                fixed[k] = check_given(k, v, _default(spec, k))
        suffix = ",".join(
            f"{k}={fixed[k]!r}" if k in fixed else f"{k}={values[k].strip()}" for k in values
        )
        dropped = (
            {p for p in self.inherited if parameter_key(p) not in replaced} if varying else set()
        )
        kept = {
            p: s
            for p, s in self.sinusoids.items()
            if parameter_key(p) not in replaced and p not in dropped
        }
        return DynamicsSchedule(
            task=spec,
            name=f"{self.name}{',' if ':' in self.name else ':'}{suffix}",
            constants={
                **{p: c for p, c in self.constants.items() if parameter_key(p) not in replaced},
                **fixed,
            },
            sinusoids={**kept, **varying},
            mode=self.mode,
            inherited=() if varying else tuple(p for p in self.inherited if p not in values),
        )

    def _range(self, spec, name: str, text: str) -> Sinusoid:
        """`"LOW..HIGH[@F]"` -> the Sinusoid over [LOW, HIGH] (bounds checked as given values)."""
        body, _, freq = text.strip().partition("@")
        low, _, high = body.partition("..")
        if self.name.split(":")[0] in ("nominal", "fixed") or self.mode == "default":
            raise UsageError(
                f"range {name}={text.strip()} in dynamics {self.name!r}; allowed: a range in "
                "paper, ompo or uniform (nominal and fixed hold values)"
            )
        try:
            lo, hi = (check_given(name, x.strip(), _default(spec, name)) for x in (low, high))
            f = float(freq) if freq else _frequency(self)
        except (UsageError, ValueError):
            raise UsageError(
                f"bad range {name}={text.strip()!r}; allowed: LOW..HIGH[@FREQUENCY] with LOW <= "
                f"HIGH, both plausible for {name} (default {_default(spec, name):g})"
            ) from None
        if not lo <= hi or not np.isfinite(f):
            raise UsageError(
                f"bad range {name}={text.strip()!r}; allowed: LOW <= HIGH, a finite frequency"
            )
        return Sinusoid((lo + hi) / 2, (hi - lo) / 2, f)


def parse_dynamics(text: str | DynamicsSchedule, task: str) -> DynamicsSchedule:
    """Schedule for `task` from a name: paper, ompo, nominal, uniform, default, or
    ``fixed:NAME=VALUE,...``; every name but default accepts ``:NAME=VALUE,...`` overrides."""
    spec = get_task(task)
    if isinstance(text, DynamicsSchedule):
        if text.task != spec.name:
            raise UsageError(
                f"dynamics schedule is for task {text.task!r}; allowed: a schedule for {spec.name!r}"
            )
        return text
    if not isinstance(text, str):
        raise UsageError(f"unknown dynamics {text!r}; allowed: {_SYNTAX}")
    head, colon, tail = text.strip().partition(":")
    kind = head.strip().lower()
    if kind not in KINDS:
        raise UsageError(f"unknown dynamics {text!r}; allowed: {_SYNTAX}")
    values = _parse_values(text, kind, tail, spec) if colon else {}
    if kind == "default":
        return DynamicsSchedule(spec, name="default", mode="default")
    paper = spec.schedules["paper"]
    # a task outside the paper's four: its schedule is the generic one, which a range replaces
    inherited = () if spec.paper else tuple(paper)
    base = {
        "paper": DynamicsSchedule(spec, "paper", sinusoids=paper, inherited=inherited),
        "ompo": DynamicsSchedule(
            spec, "ompo", sinusoids=spec.schedules["ompo"], inherited=inherited
        ),
        "nominal": DynamicsSchedule(
            spec, "nominal", constants={p: s.center for p, s in paper.items()}
        ),
        "uniform": DynamicsSchedule(
            spec, "uniform", sinusoids=paper, mode="uniform", inherited=inherited
        ),
        "fixed": DynamicsSchedule(spec, "fixed"),
    }[kind]
    return base.with_overrides(**values)


def _check_not_a_grid(name: str, value, text: str) -> None:
    """A one-line UsageError for a sweep's `LO:HI:N` (or `LO..HI:N`) given to a training
    schedule, showing the range form it takes (one range grammar: docs/envs.md)."""
    if not isinstance(value, str) or ":" not in value:
        return
    bounds = value.replace("..", ":").split(":")
    example = f"{bounds[0].strip()}..{bounds[1].strip()}" if len(bounds) >= 2 else "LOW..HIGH"
    raise UsageError(
        f"bad value {value.strip()!r} for {name} in dynamics {text!r}; allowed: {name}=VALUE, "
        f"or {name}=LOW..HIGH[@FREQUENCY] to vary it by episode (e.g. {name}={example}); "
        "points LO..HI:N are for adarl evaluate --sweep"
    )


def _default_takes_no_values(what: str) -> UsageError:
    return UsageError(
        f"bad dynamics {what!r}: 'default' keeps Gymnasium's model untouched and takes no values; "
        "allowed: fixed:NAME=VALUE[,NAME=VALUE...] to set parameters"
    )


def _addressed(name: str) -> bool:
    from adarl.envs.params import is_addressed

    return is_addressed(name)


def _default(spec, name: str) -> float:
    """The default of a named or addressed parameter of `spec` (the compiled model's value)."""
    if name in spec.all_params:
        return spec.all_params[name]
    from adarl.envs.elements import address_default

    return address_default(xml_path(spec), name)


def xml_path(spec) -> str:
    """The XML of `spec`'s model (the paper's tasks: Gymnasium's own file)."""
    if spec.xml_path:
        return spec.xml_path
    from adarl.envs.model import _xml_path

    return _xml_path(spec)


def _frequency(schedule: DynamicsSchedule) -> float:
    """The frequency a range takes by default: the schedule's first sinusoid's, else 0.5 (a range
    is read before the generic sinusoids it replaces are dropped, so on a task outside the
    paper's four a spec's range takes the generic schedule's 0.5)."""
    first = next(iter(schedule.sinusoids.values()), None)
    return first.frequency if first is not None else 0.5


def _check_name(spec, name: str) -> None:
    if name in spec.all_params:
        return
    if spec.kind != "gym" and _addressed(name):
        default = _default(spec, name)  # the element must exist in the model: one line naming it
        if name.startswith("body:") and not default > 0:  # a massless body (the world) scales not
            raise UsageError(
                f"cannot set {name}: its compiled mass is {default:g}; allowed: bodies with mass"
            )
        return
    allowed = ", ".join(spec.all_params) or "none (fixed dynamics)"
    where = (
        " or KIND:NAME.ATTR (body:torso.mass, ...; adarl tasks TASK)" if spec.kind != "gym" else ""
    )
    raise UsageError(f"unknown {spec.name} parameter {name!r}; allowed: {allowed}{where}")


def _parse_values(text: str, kind: str, tail: str, spec) -> dict[str, float]:
    """``NAME=VALUE,NAME=VALUE`` -> {NAME: VALUE}, with one-line errors."""
    if kind == "default":
        raise _default_takes_no_values(text)
    values: dict[str, float] = {}
    given = []
    for item in tail.split(","):
        name, eq, value = (part.strip() for part in item.partition("="))
        if not eq or not name or not value:
            raise UsageError(
                f"malformed dynamics {text!r} (at {item.strip()!r}); allowed: "
                f"{kind}:NAME=VALUE[,NAME=VALUE...] with NAME one of {', '.join(spec.all_params)}"
            )
        _check_name(spec, name)
        given.append(name)
        check_once(given, f" in dynamics {text!r}")
        _check_not_a_grid(name, value, text)
        values[name] = value if ".." in value else check_given(name, value, _default(spec, name))
    return values
