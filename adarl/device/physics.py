"""Per-episode physics for the device tasks: the `mjx.Model` leaves a dynamics schedule changes,
one row per episode, built on the host by the host tasks' own `ModelBuilder` and schedules.

Episode i's parameters are `DynamicsEnv`'s (``schedule.params_for_episode(i, rng)`` with
``rng = default_rng([seed, i])`` in uniform mode, `seed` the env's schedule seed), so both backends
draw the same sequence. Which leaves change is found by compiling models across the schedule's
ranges and comparing every leaf of their MJX models with the centroid's (a length change reaches
derived fields too: ``body_invweight0``, ``body_subtreemass``, ``geom_rbound``, ``geom_aabb``,
``actuator_acc0``, ``stat``); a row is then read from each episode's compiled `MjModel` directly
(no `mjx.put_model` per episode). The device task runs on the centroid's model
(`PhysicsTable.mj_model`) with a row's fields in place of its leaves: ``task.reset(key, row)``.
In training, `PhysicsRing` keeps each seed's next episodes' rows (the device learner's ring).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adarl.device.common import Rules, device_model
from adarl.device.tasks import RULES
from adarl.envs.dynamics import DynamicsSchedule, parse_dynamics
from adarl.envs.model import ModelBuilder
from adarl.envs.tasks import get_task
from adarl.errors import UsageError

#: Random parameter points (besides the range corners and the schedule's first episodes) at which
#: `changed_fields` compares compiled models.
SAMPLES = 8


def episode_params(schedule: DynamicsSchedule, seed: int, index: int) -> dict[str, float]:
    """Episode `index`'s parameters as `adarl.envs.DynamicsEnv` draws them with schedule seed
    `seed` (uniform mode: one ``default_rng([seed, index])`` per episode)."""
    rng = np.random.default_rng([int(seed), int(index)]) if schedule.needs_rng else None
    return schedule.params_for_episode(int(index), rng)


def mjx_model(mj_model, rules: Rules):
    """``mjx.put_model`` of `mj_model` as `rules`' task runs it (`device_model`) in float64 on the
    CPU (`host_device`): (leaves, static), the array leaves by dotted
    name (``opt.gravity``, ``body_mass``) and the non-array part (sizes, solver, flags such as
    ``has_fluid_params``). A model whose static part differs from the base's cannot be expressed
    by replacing leaves; ``_impl.geom_rbound_hfield`` (a static copy of ``geom_rbound`` that MJX
    reads only for height-field collisions) is left out of it in a model without height fields."""
    import jax
    from mujoco import mjx

    with jax.enable_x64(True):
        model = mjx.put_model(device_model(rules, mj_model), impl="jax", device=host_device())
        if mj_model.nhfield == 0:
            model = model.tree_replace({"_impl.geom_rbound_hfield": np.zeros(0)})
        pairs, static = jax.tree_util.tree_flatten_with_path(model)
        return {_dotted(path): np.asarray(leaf) for path, leaf in pairs}, static


def host_device():
    """The CPU device where the process has one, else None (JAX's default device): under
    ``JAX_PLATFORMS=cuda`` there is no CPU backend and ``jax.devices("cpu")`` raises."""
    import jax

    try:
        return jax.devices("cpu")[0]
    except RuntimeError:
        return None


def _dotted(path) -> str:
    return ".".join(str(getattr(k, "name", getattr(k, "idx", k))) for k in path)


def host_value(mj_model, name: str, shape: tuple) -> np.ndarray:
    """The value of MJX leaf `name` (``opt.gravity``, ``body_mass``) read from the compiled
    `mj_model` (no `put_model`), as a float64 array of `shape`."""
    value = mj_model
    for part in name.split("."):
        value = getattr(value, part)
    return np.asarray(value, dtype=np.float64).reshape(shape)


def sample_params(schedule: DynamicsSchedule, seed: int = 0) -> list[dict[str, float]]:
    """Parameter points spanning `schedule`: its ranges' low and high corners, each varying
    parameter alone at its low and high end, `SAMPLES` uniform draws and its first episodes."""
    ranges = schedule.ranges()
    varying = [p for p, (lo, hi) in ranges.items() if lo != hi]
    centre = schedule.centroid()
    points = [{p: ranges[p][0] for p in ranges}, {p: ranges[p][1] for p in ranges}]
    for p in varying:
        points += [centre | {p: ranges[p][0]}, centre | {p: ranges[p][1]}]
    rng = np.random.default_rng(seed)
    points += [
        centre | {p: float(rng.uniform(*ranges[p])) for p in varying} for _ in range(SAMPLES)
    ]
    points += [episode_params(schedule, seed, i) for i in range(4)]
    return points


def changed_fields(
    builder: ModelBuilder, schedule: DynamicsSchedule, rules: Rules, seed: int = 0
) -> tuple:
    """The dotted names of the MJX leaves (of `rules`' device model) that differ between the
    centroid's model and any model of `sample_params` (compiled by `builder`); raises if a
    sample's static part differs."""
    base_leaves, base_static = mjx_model(builder.compile(schedule.centroid()), rules)
    changed = set()
    for params in sample_params(schedule, seed):
        model = builder.compile(params)
        leaves, static = mjx_model(model, rules)
        if static != base_static:
            raise UsageError(
                f"dynamics {schedule.name!r} changes a static MJX field at {params}; allowed: "
                "schedules that change array fields only"
            )
        changed |= {n for n, v in leaves.items() if not np.array_equal(v, base_leaves[n])}
        for name in changed:  # the host reading must be what put_model makes
            if not np.array_equal(host_value(model, name, leaves[name].shape), leaves[name]):
                raise UsageError(f"MJX field {name!r} differs from its MjModel source")
    return tuple(sorted(changed))


@dataclass
class PhysicsTable:
    """Per-episode model fields of one task under one schedule (host arrays, float64).

    `mj_model` is the centroid's compiled model (the device task's base model); `names` the MJX
    leaves the schedule changes; `rows(episodes)` their values for those episodes, each stacked
    along a leading axis, ready for a vmapped ``task.reset(keys, fields)``.
    """

    task: str
    schedule: DynamicsSchedule
    seed: int
    mj_model: object  # mujoco.MjModel
    names: tuple
    shapes: dict
    builder: ModelBuilder

    def params(self, episode: int) -> dict[str, float]:
        """Episode `episode`'s parameters (the host env's)."""
        return episode_params(self.schedule, self.seed, episode)

    def fields_at(self, params: dict[str, float]) -> dict[str, np.ndarray]:
        """The fields (dotted name -> array) of the model at `params` (the task's full dict)."""
        model = self.builder.compile(params)
        return {n: host_value(model, n, self.shapes[n]) for n in self.names}

    def row(self, episode: int) -> dict[str, np.ndarray]:
        """Episode `episode`'s fields (dotted name -> array)."""
        return self.fields_at(self.params(episode))

    def rows(self, episodes) -> dict[str, np.ndarray]:
        """The fields of `episodes` (an iterable of indices), stacked: name -> (len, *shape)."""
        return stack([self.row(i) for i in episodes])


def stack(rows: list[dict]) -> dict[str, np.ndarray]:
    """Field dicts stacked along a new leading axis (one row per lane or episode)."""
    return {n: np.stack([r[n] for r in rows]) for n in rows[0]} if rows else {}


def physics_table(task: str, dynamics: str | DynamicsSchedule, seed: int = 0) -> PhysicsTable:
    """The `PhysicsTable` of `task` under `dynamics` (a schedule name such as ``paper``, ``ompo``,
    ``nominal``, ``uniform``, ``fixed:...``, or a `DynamicsSchedule`) with schedule seed `seed`,
    under `consistent` physics on Gymnasium's v5 models (the host default)."""
    spec = get_task(task)
    schedule = parse_dynamics(dynamics, spec.name)
    if schedule.mode == "default":
        raise UsageError(
            "bad dynamics 'default' for a physics table; allowed: paper, ompo, nominal, uniform, "
            "fixed:... (Gymnasium's own model needs no table: omit the fields)"
        )
    builder = ModelBuilder(spec, textures=False)
    rules = RULES[spec.name]
    names = changed_fields(builder, schedule, rules, seed) if schedule.varies else ()
    base = builder.compile(schedule.centroid())
    leaves, _ = mjx_model(base, rules)
    shapes = {n: leaves[n].shape for n in names}
    return PhysicsTable(spec.name, schedule, int(seed), base, names, shapes, builder)


def ring_episodes(current, slots: int) -> np.ndarray:
    """The episode each ring slot holds when the seeds' current episodes are `current`
    ((seeds,)): slot k holds the one episode of ``current … current + slots - 1`` that is k mod
    `slots`, so episode e is always read from slot e mod `slots`. Returns (seeds, slots)."""
    current = np.asarray(current, np.int64)[:, None]
    return current + (np.arange(slots)[None] - current) % slots


class PhysicsRing:
    """Every seed's model fields for its next episodes, as the device learner reads them: a ring
    of `slots` rows per seed (`fields`, name -> (seeds, slots, *shape) host arrays in `dtype`),
    episode e of a seed in slot e mod `slots`.

    `fill(current)` makes each seed's ring hold its episodes ``current … current + slots - 1``
    (a chunk of n env steps starts at most n episodes, one per step, so ``slots = n + 1``
    covers a chunk, and the device learner's ``2n + 1`` two chunks: the one running and the
    next, dispatched before the first one's episodes are known), compiling only the rows it
    lacks; `refill` says which rows those were. Seed i's episode e has the host env's
    parameters for schedule seed ``seeds[i]`` (`episode_params`), so both backends run the same
    sequence; rows of schedules without random draws (`paper`, `ompo`) depend on the episode
    index only and are compiled once per index for all seeds (kept while some seed may still
    need them: from the lowest current episode on).
    """

    def __init__(self, table: PhysicsTable, seeds, slots: int, dtype=np.float32):
        self.table = table
        self.seeds = [int(s) for s in seeds]
        self.slots = int(slots)
        n = len(self.seeds)
        self.fields = {
            name: np.zeros((n, self.slots, *shape), dtype) for name, shape in table.shapes.items()
        }
        self.held = np.full((n, self.slots), -1, np.int64)  # episode in each slot (-1: none)
        self._by_index: dict[int, dict] = {}

    def episode_params(self, index: int, episode: int) -> dict[str, float]:
        """Seed `index`'s episode `episode`'s parameters (the host env's for that seed)."""
        return episode_params(self.table.schedule, self.seeds[index], episode)

    def row(self, index: int, episode: int) -> dict[str, np.ndarray]:
        """The fields of seed `index`'s episode `episode`."""
        if self.table.schedule.needs_rng:
            return self.table.fields_at(self.episode_params(index, episode))
        if episode not in self._by_index:
            self._by_index[episode] = self.table.fields_at(self.episode_params(index, episode))
        return self._by_index[episode]

    def fill(self, current) -> bool:
        """Hold episodes ``current … current + slots - 1`` of every seed (`current`: (seeds,)
        episode indices); returns whether any slot changed."""
        return len(self.refill(current)) > 0

    def refill(self, current) -> np.ndarray:
        """`fill`, returning the (seed, slot) pairs it rewrote ((k, 2) integers, seed-major):
        the only rows a device copy of `fields` needs anew."""
        want = ring_episodes(current, self.slots)
        stale = np.argwhere(want != self.held)
        for i, k in stale:
            for name, value in self.row(int(i), int(want[i, k])).items():
                self.fields[name][i, k] = value
        self.held = want
        lowest = int(np.min(current))
        self._by_index = {e: r for e, r in self._by_index.items() if e >= lowest}
        return stale
