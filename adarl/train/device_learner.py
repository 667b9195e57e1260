"""The device learner of the SAC family (`--backend device`): every seed of a run vmapped into
one computation, on the MJX task (`adarl.device`), driven by the one loop (`adarl.train.loop`)
through the `Learner` protocol like any learner.

A chunk is one jitted call over all seeds: `update_every` environment steps (actions, task
steps, resets from the chunk's pool and replay inserts inside `lax.scan`), then `update_every`
gradient steps (`adarl.algos.sac_device.chunk`). An `advance` runs chunks up to the loop's next
event (at most `MAX_CHUNKS`), dispatching chunk k+1 before it reads what ended in chunk k, so
the device never waits for the host between chunks. Parameters, optimiser states, replay
buffers, task states and keys stay in device arrays; the host reads back only what ended in
each chunk (episodes for episodes.csv) and the update metrics. Ranks are masks (the bottlenecks
keep their full width), so seeds whose ranks differ share one shape and one compiled update; a
truncation is `sac.truncate` vmapped over the seeds (SVD of the masked factors, the rule,
optimiser and target resets). Every matmul runs at `adarl.device.MATMUL_PRECISION` (float32,
not a GPU's TF32), recorded in each checkpoint's meta.json.

Per-episode physics (`paper`, `ompo`, `uniform`) is a ring of ``2·update_every + 1`` rows of
model fields per seed on the device (`adarl.device.physics.PhysicsRing`): episode e runs with
slot e mod (2·update_every + 1). After reading chunk k, while chunk k+1 runs, the host refills
the slots of each seed's episodes from its current one on and copies only the rewritten rows to
the device: the ring covers both chunk k+1 and chunk k+2, which is dispatched next (each starts
at most `update_every` episodes). A restore rebuilds the ring from the checkpointed episode
counters. A checkpoint copies the replay rows to the host one seed at a time, never a second
copy of every seed's buffers.

Each evaluation also runs every seed's policy on the device task (`sac_device.evaluate`,
`eval_episodes` episodes per seed and evaluation dynamics, all vmapped into one call) while the
host evaluates as every learner does: the loop writes its rows to eval_device.csv (the device
evaluation), and eval.csv, the best policies and every report keep the host's, so that runs
of both backends are compared on the same physics.

Unlike the host learner, a seed's numbers depend on the batch it runs in: vmapping seeds into
one computation changes the kernels, and so the last bits, of every seed in it (as in every
vmapped JAX library). The same seeds on the same device give the same numbers, and a resumed
run continues exactly. Exploration is sampled on the device from each seed's key
(`sac_device.env_key`), so the numbers differ from the host backend's for the same seed.
"""

from __future__ import annotations

import functools
import weakref
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from adarl.algos import replay, sac, sac_config, sac_device, schedule
from adarl.device import MATMUL_PRECISION, matmul_precision, numerics
from adarl.errors import UsageError
from adarl.runs import codec, npz
from adarl.train.learner import Advance, Episode, Truncation, due
from adarl.train.sac_family import SACFamily, finite_parameters, truncation_rows

BACKEND = "device"
ROW_KEYS = ("obs", "act", "rew", "term", "valid")  # a buffer's rows; then its ptr and size
BUFFER_KEYS = (*ROW_KEYS, "ptr", "size")
PENDING = "pending"  # arrays.npz prefix of the update metrics not yet averaged into train.csv
#: the device evaluation's log, beside the host's eval.csv, with its columns
#: (`runs.logs.EVAL_COLUMNS`, which the loop's logs own)
DEVICE_EVAL_CSV = "eval_device.csv"
DEVICE_EVAL_COLUMNS = ["step", "seed", "dynamics", "episode", "return", "length"]
#: chunks one `advance` runs at most: a stop asked for (SIGTERM) waits for at most these
MAX_CHUNKS = 8


def read_ended(ended):
    """What ended in a chunk, on the host (it waits for that chunk; the next one is queued)."""
    return jax.device_get(ended)


@dataclass(frozen=True)
class SeedPhysics:
    """Physics that is one model for every episode, the device learner's view of it: `fields`,
    `mjx.Model` leaves by dotted name, arrays of shape (seeds, episodes, …) (empty: the task's
    own model); `params`, the physical parameters episodes.csv records (name -> (seeds,
    episodes)). Episode e of a seed uses row e mod (episodes). Per-episode schedules use
    `adarl.device.physics.PhysicsRing`, which has the same members."""

    fields: dict
    params: dict

    def episode_params(self, index: int, episode: int) -> dict:
        return {k: float(v[index, episode % v.shape[1]]) for k, v in self.params.items()}

    def refill(self, current) -> np.ndarray:
        """The rows never change (`PhysicsRing.refill` refills a ring): none rewritten."""
        return np.zeros((0, 2), np.int64)


def fixed_physics(config) -> SeedPhysics:
    """Dynamics that are one model for every episode (`default`: Gymnasium's own; `nominal`,
    `fixed:…`: the schedule's one compiled model): no fields replaced, and the parameters the
    host task reports for it."""
    from adarl.envs import make

    env = make(config.task, dynamics=config.dynamics, seed=0, **config.env_options())
    env.reset()
    params = dict(env.dynamics_params)
    env.close()
    n = len(config.seeds)
    return SeedPhysics({}, {k: np.full((n, 1), v) for k, v in params.items()})


def ring_slots(config) -> int:
    """Rows per seed of the physics ring: the running chunk's episodes and the next chunk's
    (each starts at most `update_every` besides the one running at its start)."""
    return 2 * config.update_every + 1


def seed_physics(config, task):
    """The per-episode physics of a run's seeds: `fixed_physics` for dynamics that are one model,
    else a `PhysicsRing` of `ring_slots` rows per seed in the task's floating type."""
    from adarl.device.physics import PhysicsRing
    from adarl.envs.dynamics import parse_dynamics

    if not parse_dynamics(config.dynamics, config.task).varies:
        return fixed_physics(config)
    table = schedule_table(config.task, config.dynamics)
    return PhysicsRing(table, config.seeds, ring_slots(config), np.dtype(task.dtype))


def eval_fields(config, label: str, dtype) -> dict:
    """The model fields of every seed's device evaluation episodes under `label` (name ->
    (seeds, eval_episodes, …)): none for dynamics that are one model (the label's device task
    is that model), else episode k of seed s has the host evaluation's parameters (its env's
    schedule seed is 1,000,000 + s, `physics.episode_params`)."""
    from adarl.device.physics import episode_params
    from adarl.envs.dynamics import parse_dynamics

    if not parse_dynamics(label, config.task).varies:
        return {}
    table = schedule_table(config.task, label)
    rows = {}
    per_seed = []
    for seed in config.seeds:
        episodes = []
        for k in range(config.eval_episodes):
            params = episode_params(table.schedule, 1_000_000 + seed, k)
            key = (seed, k) if table.schedule.needs_rng else k
            if key not in rows:
                rows[key] = table.fields_at(params)
            episodes.append(rows[key])
        per_seed.append({n: np.stack([e[n] for e in episodes]) for n in table.names})
    return {n: np.stack([s[n] for s in per_seed]).astype(dtype) for n in table.names}


class SeedRows:
    """One seed's first `used` rows of a device buffer array as a part of `adarl.runs.npz.Stacked`,
    copied to the host only when the checkpoint writes it: a checkpoint holds one seed's rows at
    a time, on the device and on the host, never a second copy of every seed's."""

    def __init__(self, take, array, index: int, used: int):
        self.take, self.array, self.index, self.used = take, array, index, used
        self.shape = (1, used, *array.shape[2:])
        self.dtype = np.dtype(array.dtype)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        rows = np.asarray(jax.device_get(self.take(self.array, np.int32(self.index))))
        rows = rows[: self.used][None]
        return rows if dtype is None else rows.astype(dtype)


def precise(fn):
    """`fn` with every matmul it traces at `adarl.device.MATMUL_PRECISION` (float32: on a GPU,
    JAX's default for float32 matmuls is TF32)."""

    def run(*args):
        with matmul_precision():
            return fn(*args)

    inner = getattr(fn, "func", fn)  # a partial: the function's own name in compile logs
    run.__name__ = getattr(inner, "__name__", "device_function")
    return run


@dataclass(eq=False)
class Compiled:
    """The jitted, seed-vmapped functions of one spec."""

    init_env: callable
    chunk: callable
    truncate: callable
    ranks: callable
    diagnostics: callable
    put_rows: callable  # (table, seeds, slots, rows): the ring's rewritten rows in place
    seed_rows: callable  # (array, i): seed i's rows
    put_seed_rows: callable  # (array, i, rows): seed i's rows in place (donated)
    evaluations: dict = field(default_factory=dict)  # eval dynamics label -> jitted evaluate


_COMPILED: weakref.WeakValueDictionary = weakref.WeakValueDictionary()


@functools.cache
def schedule_table(name: str, dynamics: str):
    """`adarl.device.physics.physics_table` of `name` under `dynamics`, one per process (finding
    the changed fields compiles a few dozen models)."""
    from adarl.device.physics import physics_table

    return physics_table(name, dynamics)


@functools.cache
def device_task(name: str, dynamics: str, solver: str = "xml"):
    """The device task `name` on the model of `dynamics` (Gymnasium's own for `default`, else
    the schedule's centroid, which is its one model for `nominal` and `fixed:…` and the base
    whose leaves per-episode rows replace for the others), with `solver` (`--device-solver`);
    one object per process, so compiled functions are shared."""
    from adarl.device import tasks

    caps = tasks.solver_caps(solver)
    if dynamics == "default":
        return tasks.make(name, solver=caps)
    return tasks.make(name, mj_model=schedule_table(name, dynamics).mj_model, solver=caps)


def _diagnostics(spec: sac.Spec, state):
    """sac-sparse's `active_fraction` (the host learner's: the actor's code on a replay batch
    drawn with key 0)."""
    c = spec.config
    out = {}
    if c.sparse_width:
        obs = replay.sample(state["buffer"], jax.random.PRNGKey(0), c.batch_size)["obs"]
        h = sac.actor_features(spec, state["actor"], state["masks"]["actor"], obs)
        out["active_fraction"] = jnp.mean(h > 0)
    return out


def compile_functions(spec: sac.Spec) -> Compiled:
    """Jitted functions for `spec`, shared by the runs of this process that use it at the same
    time (each compile of a device chunk takes tens of seconds on a CPU); every one traced at
    `MATMUL_PRECISION` (`precise`)."""
    fns = _COMPILED.get(spec)
    if fns is None:
        c = spec.config
        task = device_task(c.task, c.dynamics, c.device_solver)
        vmap = jax.vmap

        def put_rows(table, seeds, slots, rows):
            return {k: table[k].at[seeds, slots].set(rows[k]) for k in table}

        evaluations = {
            label: jax.jit(
                precise(
                    functools.partial(
                        sac_device.evaluate,
                        spec,
                        device_task(c.task, label, c.device_solver),
                        c.max_episode_steps,
                        c.eval_episodes,
                    )
                )
            )
            for label in c.eval_dynamics
        }
        fns = _COMPILED[spec] = Compiled(
            init_env=jax.jit(precise(vmap(functools.partial(sac_device.init_env, task)))),
            chunk=jax.jit(
                precise(functools.partial(sac_device.chunk, spec, task)),
                static_argnums=(0,),
                donate_argnums=(1, 2),
            ),
            truncate=jax.jit(
                precise(vmap(functools.partial(sac.truncate, spec))), donate_argnums=(0,)
            ),
            ranks=jax.jit(vmap(functools.partial(sac.rank_state, spec))),
            diagnostics=jax.jit(precise(vmap(functools.partial(_diagnostics, spec)))),
            put_rows=jax.jit(put_rows),
            seed_rows=jax.jit(lambda a, i: jax.lax.dynamic_index_in_dim(a, i, keepdims=False)),
            put_seed_rows=jax.jit(
                lambda a, i, rows: jax.lax.dynamic_update_index_in_dim(a, rows, i, 0),
                donate_argnums=(0,),
            ),
            evaluations=evaluations,
        )
    return fns


class DeviceSACLearner(SACFamily):
    """A SAC-family run on the device backend: all seeds in one vmapped state."""

    def __init__(self, config: sac_config.SACConfig, physics=None):
        from adarl.device import missing_reason

        config.check_device()
        reason = missing_reason()
        if reason is not None:
            raise UsageError(f"--backend device needs MJX: {reason}")
        task = device_task(config.task, config.dynamics, config.device_solver)
        low, high = np.asarray(task.mj_model.actuator_ctrlrange, np.float32).T
        self.setup(config, task.observation_size, task.action_size, low, high)
        # SeedPhysics or PhysicsRing: fields, episode_params, refill
        self.physics = seed_physics(config, task) if physics is None else physics
        self.check_memory(sum(v.nbytes for v in self.physics.fields.values()), device=True)
        self.check_eval_dynamics()  # the host evaluation's tasks
        # the device evaluation's tasks and per-episode fields, on the device from here on
        self.eval_fields = {
            label: jax.device_put(eval_fields(config, label, np.dtype(task.dtype)))
            for label in config.eval_dynamics
        }
        self.eval_keys = np.stack([sac_device.eval_key(s) for s in self.seeds])
        self.extra_logs = {DEVICE_EVAL_CSV: (list(DEVICE_EVAL_COLUMNS),), **self.extra_logs}
        self.fns = compile_functions(self.spec)
        self.table = jax.device_put({k: v.copy() for k, v in self.physics.fields.items()})
        self.episodes = np.zeros(self.n, np.int64)  # each seed's current episode index
        self.infos: list = []  # update metrics of each chunk since the last train.csv rows

    # ------------------------------------------------------------------ state
    def fresh(self) -> None:
        c = self.config
        state = self.initial_state()
        state["buffer"] = replay.empty_buffers(
            self.n, c.buffer_size, self.spec.obs_dim, self.spec.act_dim
        )
        self.state = jax.device_put(state)
        self.episodes = np.zeros(self.n, np.int64)
        self.load_physics()
        self.env = self.fns.init_env(self.env_keys(), self.table)
        self.infos = []

    def initial_state(self) -> dict:
        """Every seed's SAC state without its buffer, stacked (NumPy; the host's parameters)."""
        states = [sac.init_state(self.spec, s, with_buffer=False) for s in self.seeds]
        return jax.tree_util.tree_map(lambda *a: np.stack(a), *states)

    def load_physics(self) -> None:
        """Make the device's ring hold the rows of each seed's episodes from its current one
        (`episodes`) on: the host refills the slots whose episodes changed and copies only those
        rows (`upload_rows`), or the whole ring where every slot changed (a fresh start)."""
        stale = self.physics.refill(self.episodes)
        if not len(stale):
            return
        if len(stale) == self.n * self.physics.slots:  # copies: refill writes the rows in place
            self.table = jax.device_put({k: v.copy() for k, v in self.physics.fields.items()})
        else:
            self.upload_rows(stale)

    def upload_rows(self, stale: np.ndarray) -> None:
        """Copy the ring's rewritten (seed, slot) rows `stale` into the device's table, padded
        to a power of two by repeating the first (so a few shapes compile)."""
        pad = (1 << (len(stale) - 1).bit_length()) - len(stale)
        index = np.concatenate([stale, np.repeat(stale[:1], pad, axis=0)]).astype(np.int32)
        seeds, slots = index[:, 0], index[:, 1]
        rows = {k: v[seeds, slots] for k, v in self.physics.fields.items()}
        self.table = self.fns.put_rows(self.table, seeds, slots, rows)

    def env_keys(self) -> np.ndarray:
        return np.stack([sac_device.env_key(s) for s in self.seeds])

    def checkpoint_state(self) -> tuple[dict[str, np.ndarray], dict]:
        """Everything to continue exactly: the SAC state, the replay rows written so far (and
        the provisional one), copied seed by seed as the checkpoint is written (`SeedRows`), the
        environment side (task states, observations, returns, keys) and the update metrics not
        yet in train.csv; meta.json records the matmul precision."""
        buffer = self.state["buffer"]
        arrays = codec.flatten_tree(
            jax.device_get({k: v for k, v in self.state.items() if k != "buffer"}), "state"
        )
        used = int(min(buffer["obs"].shape[1], int(np.max(jax.device_get(buffer["size"]))) + 1))
        for k in ROW_KEYS:  # only the rows written so far leave the device, a seed at a time
            parts = [SeedRows(self.fns.seed_rows, buffer[k], i, used) for i in range(self.n)]
            arrays[f"buffer/{k}"] = npz.Stacked(parts)
        for k in ("ptr", "size"):
            arrays[f"buffer/{k}"] = np.asarray(jax.device_get(buffer[k]))
        arrays.update(codec.flatten_tree(jax.device_get(self.env), "env_device"))
        for name in self.infos[0] if self.infos else ():
            arrays[f"{PENDING}/{name}"] = np.stack([np.asarray(i[name]) for i in self.infos])
        return arrays, {"backend": BACKEND, **numerics()}

    def restore(self, arrays: dict, meta: dict) -> None:
        if meta.get("backend") != BACKEND:
            raise UsageError(
                f"this checkpoint was written by the {meta.get('backend', 'host')} backend; "
                "--backend device resumes only device checkpoints"
            )
        recorded = meta.get("matmul_precision", MATMUL_PRECISION)  # older: CPU runs, the same
        if recorded != MATMUL_PRECISION:
            raise UsageError(
                f"this checkpoint was written with matmul precision {recorded!r}; this adarl's "
                f"device backend runs {MATMUL_PRECISION!r} and resumes only that"
            )
        c = self.config
        state = codec.unflatten_tree(self.initial_state(), arrays, "state")
        template = replay.init_buffer(1, self.spec.obs_dim, self.spec.act_dim)
        buffer = {}
        for k in BUFFER_KEYS:
            saved = arrays[f"buffer/{k}"]
            if saved.shape[0] != self.n or saved.shape[2:] != template[k].shape[1:]:
                raise UsageError(
                    f"checkpoint buffer {k!r} has shape {saved.shape}; expected {self.n} seeds "
                    f"and rows of shape {template[k].shape[1:]}"
                )
            if k in ("ptr", "size"):
                buffer[k] = jax.device_put(np.asarray(saved))
                continue
            rows = (c.buffer_size, *template[k].shape[1:])
            device = jnp.zeros((self.n, *rows), template[k].dtype)
            for i in range(self.n):  # a seed at a time; the rows past those written are zeros
                seed_rows = np.zeros(rows, template[k].dtype)
                seed_rows[: saved.shape[1]] = saved[i]
                device = self.fns.put_seed_rows(device, np.int32(i), seed_rows)
            buffer[k] = device
        self.state = jax.device_put(state)
        self.state["buffer"] = buffer
        env = jax.eval_shape(self.fns.init_env, self.env_keys(), self.table)
        self.env = jax.device_put(codec.unflatten_tree(env, arrays, "env_device"))
        self.episodes = np.asarray(jax.device_get(self.env["episode"]), np.int64)
        self.load_physics()  # the ring from the episode counters (its rows depend on them only)
        names = [k.split("/", 1)[1] for k in arrays if k.startswith(f"{PENDING}/")]
        n = arrays[f"{PENDING}/{names[0]}"].shape[0] if names else 0
        self.infos = [{name: arrays[f"{PENDING}/{name}"][j] for name in names} for j in range(n)]

    # ------------------------------------------------------------------ acting and learning
    def advance(self, step: int) -> Advance:
        """Every seed's chunks from `step` up to the loop's next event (at most `MAX_CHUNKS`),
        each one jitted call, chunk k+1 dispatched before chunk k's episodes are read; the
        episodes that ended, ordered by step, then by seed."""
        c = self.config
        self.load_physics()
        episodes, pending = [], None
        for _ in range(MAX_CHUNKS):
            end = schedule.chunk_end(c, step)
            update = schedule.chunk_updates(c, end)
            self.state, self.env, ended, info = self.fns.chunk(
                end - step, self.state, self.env, self.table, np.int32(step), np.bool_(update)
            )
            if update:
                self.infos.append(info)
            if pending is not None:
                episodes += self.collect(*pending)
            pending, step = (step, ended), end
            events = due(c, end, truncate=end in self.truncation_steps)
            if events:
                break
        episodes += self.collect(*pending)
        return Advance(step, episodes, events)

    def collect(self, step: int, ended) -> list[Episode]:
        """The episodes that ended in the chunk from `step` (`ended`, its device output); moves
        the episode counters on and refills the ring from them (for the chunk after the next)."""
        done, ret, length, index = read_ended(ended)  # (seeds, steps)
        self.episodes = index[:, -1].astype(np.int64) + done[:, -1]  # the episode running now
        self.load_physics()
        episodes = []
        for k, i in zip(*np.nonzero(done.T)):
            info = {
                "episode_index": int(index[i, k]),
                "dynamics": self.physics.episode_params(i, int(index[i, k])),
            }
            episodes.append(
                Episode(int(i), step + int(k) + 1, info, float(ret[i, k]), int(length[i, k]))
            )
        return episodes

    def truncate(self, step: int) -> Truncation:
        """AdaRL's truncation of every seed at once (`sac.truncate` vmapped: the masks keep
        every seed's width); returns the spectra and truncations.csv rows."""
        c = self.config
        old = jax.device_get(self.fns.ranks(self.state))
        self.state, report = self.fns.truncate(self.state)
        report = jax.device_get(report)
        spectra, rows = truncation_rows(step, self.seeds, old, report, c.apply_cuts)
        return Truncation(spectra, rows)

    # ------------------------------------------------------------------ what the loop reads
    def start_evaluation(self, step: int):
        """The device evaluation at `step`: every seed's `eval_episodes` deterministic episodes
        under each evaluation dynamics, dispatched now (`sac_device.evaluate`, one call per
        dynamics) so that it runs while the host evaluates; returns a function that waits for
        it and gives the rows for `DEVICE_EVAL_CSV` (log name -> rows, seed by seed)."""
        actor, masks = self.state["actor"], self.state["masks"]["actor"]
        keys = self.eval_keys
        results = {
            label: self.fns.evaluations[label](actor, masks, keys, self.eval_fields[label])
            for label in self.config.eval_dynamics
        }

        def rows() -> dict[str, list[dict]]:
            out = {label: jax.device_get(r) for label, r in results.items()}
            written = []
            for i, seed in enumerate(self.seeds):
                for label, (returns, lengths) in out.items():
                    values = [
                        (step, seed, label, k, float(returns[i, k]), int(lengths[i, k]))
                        for k in range(returns.shape[1])
                    ]
                    written += [dict(zip(DEVICE_EVAL_COLUMNS, v, strict=True)) for v in values]
            return {DEVICE_EVAL_CSV: written}

        return rows

    def param_names(self) -> list[str]:
        return list(self.physics.episode_params(0, 0))

    def close(self) -> None:
        pass  # the tasks live on the device

    # ------------------------------------------------------------------ per-seed values (SACFamily)
    def take_metric_means(self) -> dict | None:
        if not self.infos:
            return None
        infos = jax.device_get(self.infos)
        self.infos = []
        return {k: np.mean([i[k] for i in infos], axis=0) for k in infos[0]}

    def seed_ranks(self) -> dict:
        return jax.device_get(self.fns.ranks(self.state))

    def seed_diagnostics(self) -> dict:
        return jax.device_get(self.fns.diagnostics(self.state))

    def seed_finite(self) -> dict:
        return jax.device_get(finite_parameters(self.state))

    def seed_actors(self) -> list[tuple[sac.Spec, dict, dict]]:
        actor = jax.device_get(self.state["actor"])
        masks = jax.device_get(self.state["masks"]["actor"])
        return [(self.spec, _take(actor, i), _take(masks, i)) for i in range(self.n)]

    def episode_returns(self) -> np.ndarray:
        return jax.device_get(self.env["ep_return"])


def _take(tree, i: int):
    return jax.tree_util.tree_map(lambda a: a[i], tree)
