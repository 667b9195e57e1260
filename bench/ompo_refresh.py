"""What `ompo` physics must refresh after OMPO's in-place edit: `geom_rbound`, `geom_aabb`, both?

OMPO (mujoco-py, MuJoCo 2.1) writes the new lengths into the compiled model's `body_pos` and
`geom_size`; the compiler-derived bounds stay those of Gymnasium's robot. MuJoCo 2.x had only
`geom_rbound`: its broadphase boxed every body by its geoms' bounding spheres and its geom-pair
filter was the bounding-sphere (plane: plane-sphere) test. MuJoCo >= 2.3.3 also has `geom_aabb`
(first for the midphase of bodies with several geoms), and since 3.8 (4.0 here) the broadphase
boxes a body by the intersection of each geom's sphere box and its aabb box (`makeAAMM`), so a
stale aabb of a grown geom prunes body pairs MuJoCo 2.x kept. Pairs with the
world body (the floor) skip the broadphase, so the aabb only matters for self-collisions (Hopper;
Walker2d's robot geoms have conaffinity 0, so Walker2d has floor contacts only).

For each task and parameter point the same random actions (seed 0, from the default pose
`qpos0`, no resets, Gymnasium's frame_skip) drive one model per variant:

  stale      OMPO's edit as is (rbound and aabb of Gymnasium's robot): adarl's `ompo` until now
  rbound     the edit + `geom_rbound` of the edited geometry
  aabb       the edit + `geom_aabb` of the edited geometry (rbound stale)
  both       the edit + both refreshed: the reference the table compares against
  mujoco2    rbound stale, every robot geom's aabb = the cube of half-size rbound about its
             centre, so that 4.0's broadphase box is the bounding-sphere box MuJoCo 2.x used
             (`makeAAMM` takes the tighter of the two): the contacts OMPO's MuJoCo 2.1 computed.
             Cubes on the edited geoms alone are not enough: a true aabb box of an unedited
             geom can miss the stale sphere box of an edited one that 2.x's sphere box met
  recompiled the edited geometry compiled from an MjSpec with every body's inertial set
             explicitly to Gymnasium's: masses and inertias default, every other derived
             constant (bounds, invweight0, meaninertia, ...) recomputed
  ompo       what adarl's `ModelEditor` (`physics="ompo"`) simulates: since this measurement,
             `mujoco2`'s bounds (before it, `stale`'s)

"Refreshed" bounds are read from `recompiled` (MuJoCo's compiler), not from adarl's code. Per
variant: the first env step whose state (qpos, qvel) differs bit-wise from `both`'s and from
`mujoco2`'s, the max |state difference| to `both`, and contacts summed over the steps (all; robot
with robot). Runs in about 30 s (7 models x 3000 steps x 8 points):

    python bench/ompo_refresh.py [--steps 3000] [--seed 0]
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

from adarl.envs.model import LAYOUTS, ModelEditor, _xml_path
from adarl.envs.tasks import get_task

FRAME_SKIP = {"hopper": 4, "walker2d": 4}  # Gymnasium's Hopper-v5, Walker2d-v5
VARIANTS = ("stale", "rbound", "aabb", "both", "mujoco2", "recompiled", "ompo")


def points(task: str) -> list[tuple[str, dict[str, float]]]:
    """(label, {torso_length, foot_length}) to measure: nominal, the `paper` schedule's extremes
    (Hopper's high end is torso 0.6 / foot 0.59), and the `ompo` schedule's if it differs."""
    spec = get_task(task)
    out = []
    for kind in ("paper", "ompo"):
        sched = spec.schedules[kind]
        for label, pick in (("low", "low"), ("nominal", "center"), ("high", "high")):
            values = {
                p: (s.center if pick == "center" else getattr(s, pick)) for p, s in sched.items()
            }
            if values not in [v for _, v in out]:
                out.append((f"{kind} {label}", values))
    return out


def recompiled(task: str, edited: mujoco.MjModel, default: mujoco.MjModel) -> mujoco.MjModel:
    """Gymnasium's XML with `edited`'s torso, hip and foot positions and sizes written into an
    MjSpec (the same floats, bit for bit) and every body's inertial fixed to `default`'s,
    compiled: the edited robot with default masses, every other constant derived."""
    spec = mujoco.MjSpec.from_file(_xml_path(get_task(task)))
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_AUTO
    for body in spec.bodies[1:]:
        i = default.body(body.name).id
        body.explicitinertial = True
        body.mass = default.body_mass[i]
        body.ipos = default.body_ipos[i]
        body.iquat = default.body_iquat[i]
        body.inertia = default.body_inertia[i]
    layout = LAYOUTS[task]
    for name in (layout.torso_body, *layout.hip_bodies):
        spec.body(name).pos = edited.body(name).pos
    for name in (layout.torso_geom, *layout.foot_geoms):
        spec.geom(name).size = edited.geom(name).size
    model = spec.compile()
    assert np.array_equal(model.body_mass, default.body_mass)
    assert np.array_equal(model.geom_size, edited.geom_size)
    assert np.array_equal(model.body_pos, edited.body_pos)
    return model


def variants(task: str, lengths: dict[str, float]) -> dict[str, mujoco.MjModel]:
    """One model per variant (see the module docstring)."""
    spec = get_task(task)
    params = dict(spec.params) | lengths
    default = mujoco.MjModel.from_xml_path(_xml_path(spec))

    def edited() -> mujoco.MjModel:
        return ModelEditor(spec, mujoco.MjModel.from_xml_path(_xml_path(spec))).compile(params)

    fresh = recompiled(task, edited(), default)
    models = {"recompiled": fresh, "ompo": edited()}
    for name in ("stale", "rbound", "aabb", "both", "mujoco2"):
        m = edited()
        m.geom_rbound[:] = fresh.geom_rbound if name in ("rbound", "both") else default.geom_rbound
        m.geom_aabb[:] = fresh.geom_aabb if name in ("aabb", "both") else default.geom_aabb
        if name == "mujoco2" and not np.array_equal(m.geom_size, default.geom_size):
            robot = m.geom_bodyid != 0
            m.geom_aabb[robot, :3] = 0.0
            m.geom_aabb[robot, 3:] = m.geom_rbound[robot, None]
        models[name] = m
    return {name: models[name] for name in VARIANTS}


def rollout(model: mujoco.MjModel, actions: np.ndarray, frame_skip: int):
    """States (steps x (nq+nv)) and contact counts (all, robot-robot) of `actions` from qpos0."""
    data = mujoco.MjData(model)
    states = np.empty((len(actions), model.nq + model.nv))
    contacts = np.zeros(2, dtype=int)
    for t, action in enumerate(actions):
        data.ctrl[:] = action
        for _ in range(frame_skip):
            mujoco.mj_step(model, data)
            robot = np.minimum(data.contact.geom1, data.contact.geom2) > 0  # floor is geom 0
            contacts += (data.ncon, int(np.count_nonzero(robot)))
        states[t, : model.nq], states[t, model.nq :] = data.qpos, data.qvel
    return states, contacts


def first_departure(a: np.ndarray, b: np.ndarray) -> str:
    """1-based env step of the first bit-wise difference, or '-' if none."""
    differs = np.flatnonzero(np.any(a != b, axis=1))
    return str(differs[0] + 1) if len(differs) else "-"


def table(title: str, rows: list[tuple[str, dict[str, str]]]) -> str:
    """A Markdown table: one row per (task, point), one column per variant."""
    names = list(rows[0][1])
    lines = [f"{title}\n", "| task, point (torso, foot) | " + " | ".join(names) + " |"]
    lines.append("|---|" + "---|" * len(names))
    lines += [f"| {label} | " + " | ".join(cells.values()) + " |" for label, cells in rows]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    start = time.perf_counter()
    to_both, to_mj2, contacts = [], [], []
    for task in ("hopper", "walker2d"):
        for label, lengths in points(task):
            models = variants(task, lengths)
            m = models["both"]
            low, high = m.actuator_ctrlrange.T
            actions = np.random.default_rng(args.seed).uniform(low, high, (args.steps, m.nu))
            runs = {n: rollout(models[n], actions, FRAME_SKIP[task]) for n in VARIANTS}
            ref, mj2 = runs["both"][0], runs["mujoco2"][0]
            row = f"{task} {label} ({lengths['torso_length']:g}, {lengths['foot_length']:g})"
            to_both.append(
                (
                    row,
                    {
                        n: f"{first_departure(x, ref)} ({np.abs(x - ref).max():.2g})"
                        for n, (x, _) in runs.items()
                        if n != "both"
                    },
                )
            )
            to_mj2.append(
                (row, {n: first_departure(x, mj2) for n, (x, _) in runs.items() if n != "mujoco2"})
            )
            contacts.append((row, {n: f"{c[0]} ({c[1]})" for n, (_, c) in runs.items()}))
    print(table("First env step departing from `both` (max |Δ qpos, qvel| over the run)", to_both))
    print(table("First env step departing from `mujoco2` (MuJoCo 2.x's pair selection)", to_mj2))
    print(table("Contacts summed over the steps (robot with robot)", contacts))
    print(f"{args.steps} steps per rollout, seed {args.seed}: {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
