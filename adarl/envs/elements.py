"""Physical parameters of any MuJoCo model: the generic ones every model has, and addressed ones,
`KIND:NAME.ATTR` or `KIND:NAME.ATTR[i]`, that name one element of the model's XML.

Generic parameters (every Gymnasium MuJoCo task outside the paper's four; the paper's four have
their own in `adarl.envs.tasks`):
  mass_scale      factor on every geom's density and mass: every body mass and inertia follows
  friction_scale  factor on every geom's friction (all three coefficients)
  damping_scale   factor on every joint's damping
  actuator_scale  factor on every actuator's gear (actuator strength)
  gravity         magnitude of opt.gravity, its direction kept (-z where the model has none)
  wind            optional: opt.wind = (-W, 0, 0), with air (density 1.2, viscosity 2e-5) where
                  the model has no medium, as for the paper's Ant and Humanoid

Addressed parameters (every task, the paper's four included), absolute values whose default is
the compiled model's own:
  body:NAME.mass          the body's mass (kg): its own geoms' density and mass (and an explicit
                          <inertial>'s mass and inertia) scaled so that the compiled mass is the
                          value; its inertia follows
  geom:NAME.friction[i]   friction coefficient i (0 sliding, 1 torsional, 2 rolling; no [i]: 0)
  geom:NAME.size[i]       size i (no [i]: 0). For a capsule or cylinder given by `fromto`, size[1]
                          (the half-length) stretches the segment about its centre; bodies
                          attached elsewhere do not move
  joint:NAME.damping      damping (N m s/rad or N s/m); .stiffness, .armature, .frictionloss too
  actuator:NAME.gear      the gear (first component; actuator strength); NAME may also be the
                          joint an unnamed motor drives
Every value is written into an `mujoco.MjSpec` of the XML absolutely, from a snapshot of the XML's
values, and the model recompiled, so masses, inertias and bounding volumes follow the edit and a
parameter at its default leaves the model exactly as Gymnasium's.
"""

from __future__ import annotations

import functools
import math
import sys

import numpy as np

from adarl.envs.params import Address, is_addressed, parse_address
from adarl.errors import UsageError

#: Generic parameters at their no-change values (gravity's default is the model's |g|).
GENERIC_SCALES = {
    "mass_scale": 1.0,
    "friction_scale": 1.0,
    "damping_scale": 1.0,
    "actuator_scale": 1.0,
}
#: Air, added with `wind` where a model has no medium (density kg/m^3, viscosity Pa s).
AIR = (1.2, 2e-5)


@functools.lru_cache(maxsize=1)
def quiet_settotalmass() -> None:
    """Drop MuJoCo's deprecation warning for `settotalmass` (Gymnasium's HalfCheetah XML sets it;
    adarl replaces it by the masses it stands for, `_bake_total_mass`), printed at every load
    otherwise; every other warning goes where it went."""
    import mujoco

    previous = mujoco.get_mju_user_warning()

    def warn(message: str) -> None:
        if "settotalmass" not in message:
            previous(message) if previous else print(f"WARNING: {message}", file=sys.stderr)

    mujoco.set_mju_user_warning(warn)


@functools.lru_cache(maxsize=32)
def _model(xml_path: str):
    import mujoco

    quiet_settotalmass()
    return mujoco.MjModel.from_xml_path(xml_path)


def element_names(xml_path: str) -> dict[str, list[str]]:
    """Named elements of the model at `xml_path`, by kind (those an address can name)."""
    import mujoco

    model = _model(xml_path)
    kinds = {
        "body": (mujoco.mjtObj.mjOBJ_BODY, model.nbody),
        "geom": (mujoco.mjtObj.mjOBJ_GEOM, model.ngeom),
        "joint": (mujoco.mjtObj.mjOBJ_JOINT, model.njnt),
        "actuator": (mujoco.mjtObj.mjOBJ_ACTUATOR, model.nu),
    }
    out = {}
    for kind, (obj, count) in kinds.items():
        names = [mujoco.mj_id2name(model, obj, i) for i in range(count)]
        out[kind] = [n for n in names if n and not (kind == "body" and n == "world")]
    return out


def address_default(xml_path: str, name: str) -> float:
    """The compiled model's value of the addressed parameter `name`; a one-line `UsageError`
    naming the element and the model's elements of that kind if it does not exist."""
    a = parse_address(name)
    model = _model(xml_path)
    try:
        element = _by_name_or_joint(model, a)
    except KeyError:
        names = element_names(xml_path)[a.kind]
        shown = ", ".join(names[:12]) + (", ..." if len(names) > 12 else "")
        raise UsageError(
            f"unknown {a.kind} {a.element!r} in {name!r}; allowed: {shown or f'(no named {a.kind}s)'}"
        ) from None
    i = element.id
    if a.kind == "body":
        return float(model.body_mass[i])
    if a.kind == "geom" and a.attr == "size":
        _check_size_component(model, i, name, a.index)
    if a.kind == "geom":
        return float((model.geom_friction if a.attr == "friction" else model.geom_size)[i, a.index])
    if a.kind == "joint":
        dof = model.jnt_dofadr[i]
        field = {
            "damping": model.dof_damping[dof],
            "stiffness": model.jnt_stiffness[i],
            "armature": model.dof_armature[dof],
            "frictionloss": model.dof_frictionloss[dof],
        }
        return float(field[a.attr])
    return float(model.actuator_gear[i, 0])


#: how many size components each geom type's physics uses (MuJoCo's geom `size`): a plane is
#: infinite, and a mesh's or height field's size comes from its asset
_SIZE_COMPONENTS = {"sphere": 1, "capsule": 2, "cylinder": 2, "ellipsoid": 3, "box": 3}


def _check_size_component(model, geom_id: int, name: str, index: int) -> None:
    """A one-line `UsageError` if geom `geom_id`'s type does not use size component `index`:
    the edit would be accepted and change nothing (issue 61 §5: a capsule's size[2])."""
    import mujoco

    kind = mujoco.mjtGeom(int(model.geom_type[geom_id])).name.removeprefix("mjGEOM_").lower()
    used = _SIZE_COMPONENTS.get(kind, 0)
    if index >= used:
        allowed = f"size[0]..size[{used - 1}]" if used > 1 else ("size[0]" if used else "none")
        raise UsageError(
            f"{name}: a {kind}'s physics does not use size[{index}], so setting it would change "
            f"nothing; allowed for a {kind}: {allowed}"
        )


def _by_name_or_joint(model, a: Address):
    """The element `a` names; an actuator may also be named by the joint it drives (Gymnasium's
    Ant, Hopper, Walker2d, Reacher, Swimmer and Pusher leave their motors unnamed)."""
    import mujoco

    try:
        return getattr(model, a.kind)(a.element)
    except KeyError:
        if a.kind != "actuator":
            raise
        joint = model.joint(a.element).id  # KeyError: neither an actuator nor a joint
        found = [
            i
            for i in range(model.nu)
            if model.actuator_trntype[i] == mujoco.mjtTrn.mjTRN_JOINT
            and model.actuator_trnid[i, 0] == joint
        ]
        if len(found) != 1:
            raise KeyError(a.element) from None
        return model.actuator(found[0])


def model_gravity(xml_path: str) -> float:
    """|opt.gravity| of the model at `xml_path` (the default of the generic `gravity`)."""
    return float(np.linalg.norm(_model(xml_path).opt.gravity))


class ElementEditor:
    """Writes generic and addressed parameters into an `MjSpec` (`spec`, read from `xml_path`),
    absolutely, from a snapshot of the XML's values taken at construction.

    `apply(params)` (a generic task) writes every field a generic parameter scales, then the
    addressed values. The paper's tasks, whose own code writes their parameters
    (`adarl.envs.model.apply_params`), call `restore()` first and `apply_addressed(params)` after.
    """

    def __init__(self, spec, xml_path: str):
        self.spec, self.xml_path = spec, xml_path
        _bake_total_mass(spec)
        self._geoms = [
            (g, g.density, g.mass, np.array(g.friction), np.array(g.size), np.array(g.fromto))
            for g in spec.geoms
        ]
        self._joints = [
            (j, np.array(j.damping), np.array(j.stiffness), j.armature, j.frictionloss)
            for j in spec.joints
        ]
        self._actuators = [(a, np.array(a.gear)) for a in spec.actuators]
        self._bodies = [(b, b.mass, np.array(b.inertia)) for b in spec.bodies]
        opt = spec.option
        self._option = (np.array(opt.gravity), np.array(opt.wind), opt.density, opt.viscosity)
        self.touched = False  # whether the spec holds addressed values

    def apply(self, params: dict[str, float]) -> None:
        """A generic task's parameters: every scaled field from the snapshot, then addressed ones."""
        self.restore()
        mass = params.get("mass_scale", 1.0)
        friction = params.get("friction_scale", 1.0)
        for geom, density, geom_mass, fric, _, _ in self._geoms:
            geom.density = density * mass
            geom.mass = geom_mass * mass  # NaN (mass from density) stays NaN
            geom.friction = fric * friction
        damping = params.get("damping_scale", 1.0)
        for joint, base, *_ in self._joints:
            joint.damping = base * damping
        gear = params.get("actuator_scale", 1.0)
        for actuator, base in self._actuators:
            actuator.gear = base * gear
        gravity, wind, density, viscosity = self._option
        opt = self.spec.option
        norm = float(np.linalg.norm(gravity))
        if "gravity" in params and params["gravity"] != norm:
            direction = gravity / norm if norm > 0 else np.array([0.0, 0.0, -1.0])
            opt.gravity = direction * params["gravity"]
        else:
            opt.gravity = gravity
        if "wind" in params:
            opt.wind = [0.0 - params["wind"], 0.0, 0.0]
            opt.density, opt.viscosity = (density, viscosity) if density > 0 else AIR
        else:
            opt.wind, opt.density, opt.viscosity = wind, density, viscosity
        self.apply_addressed(params)

    def restore(self) -> None:
        """Every field an addressed value writes back at the XML's value (no-op if none was)."""
        if not self.touched:
            return
        for geom, density, mass, friction, size, fromto in self._geoms:
            geom.density, geom.mass, geom.friction = density, mass, friction
            geom.size, geom.fromto = size, fromto
        for joint, damping, stiffness, armature, frictionloss in self._joints:
            joint.damping, joint.stiffness = damping, stiffness
            joint.armature, joint.frictionloss = armature, frictionloss
        for actuator, gear in self._actuators:
            actuator.gear = gear
        for body, mass, inertia in self._bodies:
            body.mass, body.inertia = mass, inertia
        self.touched = False

    def apply_addressed(self, params: dict[str, float]) -> None:
        """Write the addressed values of `params` (on top of what the spec holds)."""
        for name, value in params.items():
            if is_addressed(name):
                self.touched = True
                self._write(parse_address(name), float(value))

    def settle(self, model, params: dict[str, float]):
        """`model`, or the spec compiled again with each addressed body's geoms (and inertial)
        rescaled once more where other edits (a geom's size) moved its mass off the value: mass
        is linear in density at a fixed geometry, so one correction is exact. Then `check`."""
        off = []
        for name, value in params.items():
            if is_addressed(name) and name.startswith("body:"):
                body = self.spec.body(parse_address(name).element)
                got = float(model.body(body.name).mass[0])
                if got > 0 and not math.isclose(got, value, rel_tol=1e-9, abs_tol=1e-12):
                    off.append((body, value / got))
        for body, ratio in off:
            for geom in body.geoms:
                geom.density, geom.mass = geom.density * ratio, geom.mass * ratio
            body.mass, body.inertia = body.mass * ratio, np.array(body.inertia) * ratio
        if off:
            model = self.spec.compile()
        self.check(model, params)
        return model

    def check(self, model, params: dict[str, float]) -> None:
        """A one-line `UsageError` if a compiled body mass is not its value."""
        for name, value in params.items():
            if is_addressed(name) and name.startswith("body:"):
                got = float(model.body(parse_address(name).element).mass[0])
                if not math.isclose(got, value, rel_tol=1e-6, abs_tol=1e-12):
                    raise UsageError(
                        f"cannot set {name} to {value:g}: the compiled mass is {got:g}; "
                        "allowed: bodies whose mass comes from their geoms or an <inertial>"
                    )

    def _write(self, a: Address, value: float) -> None:
        element = getattr(self.spec, a.kind)(a.element)
        if element is None and a.kind == "actuator":  # named by the joint it drives
            driving = [x for x in self.spec.actuators if x.target == a.element]
            element = driving[0] if len(driving) == 1 else None
        if element is None:
            raise UsageError(f"unknown {a.kind} {a.element!r} in {self.xml_path}")
        if a.kind == "body":
            default = address_default(self.xml_path, f"body:{a.element}.mass")
            if not default > 0:
                raise UsageError(
                    f"cannot set body:{a.element}.mass: its compiled mass is {default:g}; "
                    "allowed: bodies with mass"
                )
            ratio = value / default
            base = {id(g): (d, m) for g, d, m, *_ in self._geoms}
            for geom in element.geoms:  # the body's own geoms, from the XML's values
                density, mass = base[id(geom)]
                geom.density, geom.mass = density * ratio, mass * ratio
            _, mass, inertia = next(b for b in self._bodies if b[0].name == element.name)
            element.mass, element.inertia = mass * ratio, inertia * ratio
        elif (
            a.kind == "geom"
            and a.attr == "size"
            and a.index == 1
            and not np.isnan(element.fromto[0])
        ):
            import mujoco

            if element.type not in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER):
                raise UsageError(
                    f"geom:{a.element}.size[1] is set by its fromto; allowed: capsules and "
                    "cylinders (adarl stretches their segment)"
                )
            fromto = np.array(element.fromto)
            centre, half = (fromto[:3] + fromto[3:]) / 2, (fromto[3:] - fromto[:3]) / 2
            stretch = value / float(np.linalg.norm(half))
            element.fromto = np.concatenate([centre - half * stretch, centre + half * stretch])
        else:
            current = np.array(getattr(element, a.attr), dtype=float)
            if current.ndim == 0:
                setattr(element, a.attr, value)
            else:
                current[a.index] = value
                setattr(element, a.attr, current)


def _bake_total_mass(spec) -> None:
    """Replace the compiler's `settotalmass` (HalfCheetah's: 14 kg) by the densities, masses and
    inertias it stands for, so that mass_scale and body masses act: the compiler would rescale
    them back to the total. The compiled masses are the XML's up to rounding (relative 1e-15)."""
    total = spec.compiler.settotalmass
    if not total > 0:
        return
    spec.compiler.settotalmass = -1
    scale = total / float(spec.compile().body_mass.sum())
    for geom in spec.geoms:
        geom.density, geom.mass = geom.density * scale, geom.mass * scale
    for body in spec.bodies:
        body.mass, body.inertia = body.mass * scale, np.array(body.inertia) * scale


def strip_textures(spec) -> None:
    """Remove all textures (visual only) so that compiling skips generating them."""
    for material in spec.materials:
        material.textures = [""] * len(material.textures)
    while spec.textures:
        spec.delete(spec.textures[0])


class GenericBuilder:
    """Compiles `MjModel`s of any MuJoCo XML at generic and addressed parameters (the builder of
    every task outside the paper's four; `adarl.envs.model.ModelBuilder` is the paper's)."""

    def __init__(self, xml_path: str, textures: bool = True):
        import mujoco

        self.spec = mujoco.MjSpec.from_file(xml_path)
        if not textures:
            strip_textures(self.spec)
        self.editor = ElementEditor(self.spec, xml_path)
        self.editor.touched = True  # the first apply writes every field

    def compile(self, params: dict[str, float]):
        """A new model at `params` (every parameter of the schedule)."""
        self.editor.apply(params)
        return self.editor.settle(self.spec.compile(), params)
