"""Compile a task's MuJoCo model at given physical parameters, by editing an `mujoco.MjSpec`.

Recompiling (rather than editing a compiled model's `geom_size`) makes masses, inertias and the
contact bounding radii `geom_rbound` follow the geometry. One `ModelBuilder` keeps one spec of
Gymnasium's XML and writes every edited field absolutely from a snapshot of the original values,
so the same spec serves every episode. A parameter at its Gymnasium default leaves its fields at
the XML's own values, so the defaults compile to Gymnasium's model bit for bit.

Geometry (Hopper, Walker2d; OMPO's construction, lengths are capsule half-lengths):
  torso half-length L: torso centre at hip + L (hip height 1.05 stays), torso capsule half-length L,
      every thigh body (both legs on Walker2d) at -L below the torso centre; the root slide joints
      stay at the world origin and rootz keeps ref 1.25, so qpos[1] = 1.25 means "as at reset".
  foot half-length F: every foot capsule's half-length is F about its unchanged centre.
Physics: gravity g -> opt.gravity = (0, 0, -g); wind W -> opt.wind = (-W, 0, 0); Ant/Humanoid get
air (density 1.2, viscosity 2e-5); mass_scale multiplies every geom density (hence body masses and
inertias); friction_scale every geom friction; damping_scale every joint damping; stiffness sets the
task's stiffened joints' stiffness with the task's spring reference.
Optional parameters (the M2TD3 / RRLS uncertainty sets, Tanabe et al. 2022; Zouitine et al. 2024):
floor_friction sets the floor geom's sliding friction (after friction_scale); a body mass
(torso_mass, thigh_mass, front_left_leg_mass, ...) is written into the compiled model's
`body_mass`, its inertia kept, as both codes do (M2TD3 utils/make_env.py, RRLS rrls/envs/*.py).
At its default an optional parameter leaves the model as the other parameters make it.

`ompo` physics (`ModelEditor`) instead writes the same parameters into the compiled default model,
as OMPO's `*_random.py` envs do: lengths only move `body_pos` and resize `geom_size`, so masses,
inertias and the bounding radii `geom_rbound` stay those of Gymnasium's robot; `geom_aabb`, which
MuJoCo 2.x (OMPO's) did not have, is set so that MuJoCo's broadphase boxes are 2.x's (see
`ModelEditor`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from gymnasium.envs.mujoco.mujoco_env import expand_model_path

from adarl.envs.elements import ElementEditor, strip_textures
from adarl.envs.params import is_addressed
from adarl.envs.tasks import PHYSICS, TaskSpec, get_task
from adarl.errors import check_choice

#: Gymnasium's XML file of each task (its v5 env class default).
XML_FILES = {
    "hopper": "hopper.xml",
    "walker2d": "walker2d_v5.xml",
    "ant": "ant.xml",
    "humanoid": "humanoid.xml",
}
#: The body each optional mass parameter sets (M2TD3's and RRLS's `body_mass[i]` by name).
BODY_MASSES = {
    "torso_mass": "torso",
    "thigh_mass": "thigh",
    "front_left_leg_mass": "front_left_leg",
    "front_right_leg_mass": "front_right_leg",
}
#: The geom `floor_friction` sets (geom 0 in every task, RRLS's `geom_friction[0, 0]`).
FLOOR_GEOM = "floor"

#: The -v4 env classes' XML files: only Walker2d's differs (right foot friction 0.9, not 1.9).
XML_FILES_V4 = XML_FILES | {"walker2d": "walker2d.xml"}


def _xml_path(task: TaskSpec) -> str:
    """Full path of Gymnasium's XML for `task` at its model version."""
    files = XML_FILES_V4 if task.version == "v4" else XML_FILES
    return expand_model_path(files[task.name])


@dataclass(frozen=True)
class Layout:
    """Named elements of a planar legged robot whose torso and feet change length."""

    torso_body: str
    torso_geom: str
    hip_bodies: tuple[str, ...]  # bodies hanging from the torso's lower end
    root_slides: tuple[str, ...]  # slide joints anchored at the world origin
    foot_geoms: tuple[str, ...]


LAYOUTS = {
    "hopper": Layout("torso", "torso_geom", ("thigh",), ("rootx", "rootz"), ("foot_geom",)),
    "walker2d": Layout(
        "torso",
        "torso_geom",
        ("thigh", "thigh_left"),
        ("rootx", "rootz"),
        ("foot_geom", "foot_left_geom"),
    ),
}


class ModelBuilder:
    """Compiles `MjModel`s of one task at any parameters (about 0.5 ms each without textures)."""

    def __init__(self, task: str | TaskSpec, xml_path: str | None = None, textures: bool = True):
        """`textures=False` drops the (visual-only, slow to generate) textures: use it when the
        model is never rendered."""
        self.task = task if isinstance(task, TaskSpec) else get_task(task)
        self.spec = mujoco.MjSpec.from_file(xml_path or _xml_path(self.task))
        if not textures:
            strip_textures(self.spec)
        self._base = _Snapshot(self.spec, self.task)
        self._elements = ElementEditor(self.spec, xml_path or _xml_path(self.task))
        self._applied: dict[str, float] | None = None  # what self.spec holds now

    def compile(self, params: dict[str, float]) -> mujoco.MjModel:
        """A new model at `params` (the task's full parameter dict, addressed parameters
        `KIND:NAME.ATTR` included: adarl.envs.elements)."""
        previous, self._applied = self._applied, None  # unknown if anything below fails
        addressed = any(is_addressed(name) for name in params)
        if addressed or self._elements.touched:  # back to the XML's values, then all of params
            self._elements.restore()
            previous = None
        apply_params(self.spec, self.task, params, self._base, previous)
        if addressed:
            self._elements.apply_addressed(params)
        model = self.spec.compile()
        if addressed:
            model = self._elements.settle(model, params)
        set_body_masses(model, self.task, params)
        self._applied = dict(params)
        return model


def compile_model(
    task: str,
    params: dict[str, float] | None = None,
    textures: bool = False,
    *,
    physics: str = "consistent",
    version: str = "v5",
) -> mujoco.MjModel:
    """One-off model of `task` at defaults | `params`: `ModelBuilder(task).compile(...)`, or under
    `ompo` physics Gymnasium's compiled model edited by `ModelEditor`."""
    check_choice("physics", physics, PHYSICS)
    spec = get_task(task, version)
    params = dict(spec.params) | dict(params or {})
    if physics == "ompo":
        return ModelEditor(spec, mujoco.MjModel.from_xml_path(_xml_path(spec))).compile(params)
    return ModelBuilder(spec, textures=textures).compile(params)


def nominal_masses(task: str, physics: str, version: str = "v5") -> dict[str, float]:
    """Body masses (kg, by body name, world left out) at the task's nominal point, the centroid of
    its `paper` schedule, under `physics`."""
    spec = get_task(task, version)
    nominal = {p: s.center for p, s in spec.schedules["paper"].items()}
    model = compile_model(task, nominal, physics=physics, version=version)
    return {
        model.body(i).name or f"body{i}": float(model.body_mass[i]) for i in range(1, model.nbody)
    }


#: Compiled fields `ModelEditor` writes (all restored from the default model first).
_EDITED = (
    "body_pos",
    "geom_size",
    "geom_aabb",
    "body_mass",
    "body_inertia",
    "geom_friction",
    "dof_damping",
    "dof_dampingpoly",
    "jnt_stiffness",
    "qpos_spring",
)


class ModelEditor:
    """Writes parameters into one compiled `MjModel` in place, the way OMPO does (`ompo` physics).

    OMPO (Non_stationary_env/hopper_random.py, walker2d_random.py) sets, at each reset,
    ``body_pos[torso].z = 1.05 + L``, ``body_pos[thigh].z = -L`` (both thighs on Walker2d),
    ``geom_size[torso_geom][1] = L`` and ``geom_size[foot][1] = F`` (both feet), and
    (ant_random.py, humanoid_random.py) ``opt.gravity = (0, 0, -g)``, ``opt.wind = (-W, 0, 0)``
    with air (density 1.2, viscosity 2e-5). Nothing is recompiled: masses, inertias, `geom_rbound`
    and the other derived constants stay the default model's. The generic parameters scale the
    compiled fields they act on (`body_mass` and `body_inertia`, `geom_friction`, `dof_damping`);
    `stiffness` writes `jnt_stiffness` and `qpos_spring`. Every field is written absolutely from a
    snapshot of the default model, so a parameter at its default leaves its fields at Gymnasium's
    values.

    Contacts are those OMPO's MuJoCo 2.1 (mujoco-py) computed on the edited robot. 2.x selected
    geom pairs with `geom_rbound` alone: a body's broadphase box was its geoms' bounding-sphere
    boxes, and a pair was dropped when the spheres (a plane: the plane and the sphere) were apart;
    OMPO's edit left `geom_rbound` stale there too, so it stays stale here. MuJoCo >= 3.8 (4.0
    here) boxes each geom by the intersection of its sphere box and its `geom_aabb` box, so the
    stale aabb of a grown geom drops pairs 2.x kept, and a refreshed one drops others (a tight box
    around one geom no longer meets the stale sphere box of the other). While the torso or a foot
    is resized, every robot geom's aabb is therefore the box of its bounding sphere
    (`sphere_boxes`), which makes MuJoCo's broadphase box exactly 2.x's. Measured with
    bench/ompo_refresh.py (docs/envs.md): a random-action Hopper at torso 0.6 / foot 0.59 leaves
    2.x's contacts after 603 env steps with the stale aabb, 919 with the refreshed aabb, 220 with
    both bounds refreshed; Walker2d's robot geoms do not collide with each other (conaffinity 0),
    and the floor's pairs skip the broadphase, so its trajectories do not change.
    """

    def __init__(self, task: str | TaskSpec, model: mujoco.MjModel):
        self.task = task if isinstance(task, TaskSpec) else get_task(task)
        self.model = model
        self._base = {name: np.array(getattr(model, name)) for name in _EDITED}
        opt = model.opt
        self._option = (np.array(opt.gravity), np.array(opt.wind), opt.density, opt.viscosity)
        layout = LAYOUTS.get(self.task.name)
        self._layout = layout
        if layout:
            self._torso = model.body(layout.torso_body).id
            self._torso_geom = model.geom(layout.torso_geom).id
            self._hips = [model.body(n).id for n in layout.hip_bodies]
            self._feet = [model.geom(n).id for n in layout.foot_geoms]
            # 1.25 - 0.2 = 1.05: OMPO's hip height, the torso's lower end
            self._hip_z = float(model.body_pos[self._torso][2] + model.body_pos[self._hips[0]][2])
            self._robot = np.flatnonzero(model.geom_bodyid != 0)  # geoms the broadphase boxes
        self._stiff = [
            (model.joint(n).id, model.jnt_qposadr[model.joint(n).id])
            for n in self.task.stiffness_joints
        ]

    def compile(self, params: dict[str, float]) -> mujoco.MjModel:
        """Write `params` (the task's full parameter dict) into the model; returns the same model."""
        m, base, defaults = self.model, self._base, self.task.params
        for name, value in base.items():
            getattr(m, name)[...] = value
        if self._layout:
            length = params["torso_length"]
            if length != defaults["torso_length"]:
                m.body_pos[self._torso, 2] = self._hip_z + length
                m.body_pos[self._hips, 2] = -length
                m.geom_size[self._torso_geom, 1] = length
            if params["foot_length"] != defaults["foot_length"]:
                m.geom_size[self._feet, 1] = params["foot_length"]
            if not np.array_equal(m.geom_size, base["geom_size"]):
                m.geom_aabb[self._robot] = sphere_boxes(m.geom_rbound[self._robot])
        m.body_mass[:] = base["body_mass"] * params["mass_scale"]
        m.body_inertia[:] = base["body_inertia"] * params["mass_scale"]
        m.geom_friction[:] = base["geom_friction"] * params["friction_scale"]
        floor = params.get("floor_friction", self.task.all_params.get("floor_friction"))
        if floor is not None and floor != self.task.all_params["floor_friction"]:
            m.geom_friction[m.geom(FLOOR_GEOM).id, 0] = floor
        m.dof_damping[:] = base["dof_damping"] * params["damping_scale"]
        m.dof_dampingpoly[:] = base["dof_dampingpoly"] * params["damping_scale"]
        k = params.get("stiffness", 0.0)
        if k != 0.0:
            for joint, qpos_adr in self._stiff:
                m.jnt_stiffness[joint] = k
                m.qpos_spring[qpos_adr] = self.task.spring_ref
        gravity, wind, density, viscosity = self._option
        opt = m.opt
        opt.gravity = gravity if "gravity" not in params else [0.0, 0.0, -params["gravity"]]
        opt.wind = wind if "wind" not in params else [0.0 - params["wind"], 0.0, 0.0]
        opt.density, opt.viscosity = self.task.medium or (density, viscosity)
        set_body_masses(m, self.task, params)
        return m


def sphere_boxes(rbound: np.ndarray) -> np.ndarray:
    """`geom_aabb` rows (centre, half-sizes in the geom frame) that make MuJoCo's broadphase box
    of each geom the box of its bounding sphere, as in MuJoCo 2.x: cubes of half-size `rbound`
    about the geom centre. MuJoCo takes, per axis, the tighter of the sphere box and the rotated
    aabb box, and a cube's rotated box is never tighter than the sphere's (a unit vector's L1
    norm is >= 1), so the sphere box is what remains."""
    rbound = np.asarray(rbound, dtype=float)
    return np.concatenate([np.zeros((len(rbound), 3)), np.repeat(rbound[:, None], 3, 1)], 1)


def set_body_masses(model: mujoco.MjModel, task: TaskSpec, params: dict[str, float]) -> None:
    """Write each mass parameter of `params` that differs from its default into `body_mass`
    (inertia kept, as M2TD3 and RRLS do)."""
    for name, body in BODY_MASSES.items():
        if name in params and params[name] != task.all_params[name]:
            model.body_mass[model.body(body).id] = params[name]


class _Snapshot:
    """The XML's values of every field `apply_params` writes."""

    def __init__(self, spec: mujoco.MjSpec, task: TaskSpec):
        self.geoms = [(g, g.density, g.mass, np.array(g.friction)) for g in spec.geoms]
        self.joints = [(j, np.array(j.damping)) for j in spec.joints]
        floor = spec.geom(FLOOR_GEOM)
        self.floor = None if floor is None else (floor, np.array(floor.friction))
        self.stiff = [
            (spec.joint(n), np.array(spec.joint(n).stiffness), spec.joint(n).springref)
            for n in task.stiffness_joints
        ]
        opt = spec.option
        self.option = (np.array(opt.gravity), np.array(opt.wind), opt.density, opt.viscosity)
        layout = LAYOUTS.get(task.name)
        if layout:
            torso = spec.body(layout.torso_body)
            hips = [spec.body(n) for n in layout.hip_bodies]
            self.torso = (torso, np.array(torso.pos))
            self.torso_geom = (
                spec.geom(layout.torso_geom),
                np.array(spec.geom(layout.torso_geom).size),
            )
            self.hips = [(h, np.array(h.pos)) for h in hips]
            self.slides = [(spec.joint(n), np.array(spec.joint(n).pos)) for n in layout.root_slides]
            self.feet = [(spec.geom(n), np.array(spec.geom(n).size)) for n in layout.foot_geoms]
            self.hip_z = float(torso.pos[2] + hips[0].pos[2])  # 1.25 - 0.2 = 1.05


#: Parameters written together; `apply_params` skips a group whose values did not change.
_GROUPS = {
    "torso": ("torso_length",),
    "feet": ("foot_length",),
    "mass": ("mass_scale",),
    "friction": ("friction_scale", "floor_friction"),
    "damping": ("damping_scale",),
    "stiffness": ("stiffness",),
    "option": ("gravity", "wind"),
}


def apply_params(
    spec: mujoco.MjSpec,
    task: TaskSpec,
    params: dict[str, float],
    base: _Snapshot,
    previous: dict[str, float] | None = None,
) -> None:
    """Write `params` into `spec` (absolute values from `base`; see the module docstring).
    Groups whose values equal `previous` (what `spec` already holds) are skipped."""
    defaults = task.params

    def changed(group: str) -> bool:
        names = [n for n in _GROUPS[group] if n in task.all_params]
        return previous is None or any(params.get(n) != previous.get(n) for n in names)

    if task.name in LAYOUTS:
        if changed("torso"):
            _set_torso(
                base, params["torso_length"], params["torso_length"] == defaults["torso_length"]
            )
        if changed("feet"):
            _set_feet(base, params["foot_length"], params["foot_length"] == defaults["foot_length"])
    if changed("mass"):
        for geom, density, geom_mass, _ in base.geoms:
            geom.density = density * params["mass_scale"]
            geom.mass = geom_mass * params["mass_scale"]  # NaN (mass from density) stays NaN
    if changed("friction"):
        for geom, _, _, friction in base.geoms:
            geom.friction = friction * params["friction_scale"]
        floor = params.get("floor_friction", task.all_params.get("floor_friction"))
        if floor is not None and floor != task.all_params["floor_friction"]:
            geom, friction = base.floor
            geom.friction = np.concatenate([[floor], friction[1:] * params["friction_scale"]])
    if changed("damping"):
        for joint, damping in base.joints:
            joint.damping = damping * params["damping_scale"]
    if base.stiff and changed("stiffness"):
        k = params["stiffness"]
        # springref is an angle in the compiler's unit (degrees in Gymnasium's XMLs); stiffness per rad
        spring_ref = math.degrees(task.spring_ref) if spec.compiler.degree else task.spring_ref
        for joint, stiffness, springref in base.stiff:
            joint.stiffness = stiffness if k == 0.0 else np.concatenate([[k], stiffness[1:]])
            joint.springref = springref if k == 0.0 else spring_ref
    if changed("option"):
        gravity, wind, density, viscosity = base.option
        opt = spec.option
        opt.gravity = gravity if "gravity" not in params else [0.0, 0.0, -params["gravity"]]
        opt.wind = wind if "wind" not in params else [0.0 - params["wind"], 0.0, 0.0]
        opt.density, opt.viscosity = task.medium or (density, viscosity)


def _set_torso(base: _Snapshot, length: float, untouched: bool) -> None:
    """Torso centre at hip + L, capsule half-length L, hips at -L, root slides at the origin."""
    torso, pos = base.torso
    geom, size = base.torso_geom
    torso.pos = pos if untouched else [pos[0], pos[1], base.hip_z + length]
    geom.size = size if untouched else [size[0], length, size[2]]
    for hip, hip_pos in base.hips:
        hip.pos = hip_pos if untouched else [hip_pos[0], hip_pos[1], -length]
    for slide, slide_pos in base.slides:
        slide.pos = slide_pos if untouched else [slide_pos[0], slide_pos[1], -(base.hip_z + length)]


def _set_feet(base: _Snapshot, length: float, untouched: bool) -> None:
    """Every foot capsule gets half-length F about its unchanged centre (as OMPO)."""
    for geom, size in base.feet:
        geom.size = size if untouched else [size[0], length, size[2]]
