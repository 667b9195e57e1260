"""The device learner of the SAC family (`--backend device`): every seed of a run vmapped into
one computation, on the MJX task (`adarl.device`), driven by the one loop (`adarl.train.loop`)
through the `Learner` protocol like any learner.

Each `advance` is one jitted call over all seeds: a chunk of `update_every` environment steps
(actions, task steps, resets and replay inserts inside `lax.scan`), then `update_every` gradient
steps (`adarl.algos.sac_device.chunk`). Parameters, optimiser states, replay buffers, task states
and keys stay in device arrays; the host reads back only what ended in the chunk (episodes for
episodes.csv) and the update metrics. Ranks are masks (the bottlenecks keep their full width), so
seeds whose ranks differ share one shape and one compiled update; a truncation is `sac.truncate`
vmapped over the seeds (SVD of the masked factors, the rule, optimiser and target resets).

Per-episode physics (`paper`, `ompo`, `uniform`) is a ring of ``update_every + 1`` rows of model
fields per seed on the device (`adarl.device.physics.PhysicsRing`): episode e runs with slot
e mod (update_every + 1); before each chunk the host refills the slots of each seed's episodes
from its current one on (at most `update_every` start in a chunk), with the host env's
parameters for that seed. A restore rebuilds the ring from the checkpointed episode counters.

Unlike the host learner, a seed's numbers depend on the batch it runs in: vmapping seeds into
one computation changes the kernels, and so the last bits, of every seed in it (as in every
vmapped JAX library). The same seeds on the same device give the same numbers, and a resumed
run continues exactly. Exploration is sampled on the device from each seed's key
(`sac_device.env_key`), so the numbers differ from the host backend's for the same seed.
"""

from __future__ import annotations

import functools
import weakref
from dataclasses import dataclass

import jax
import numpy as np

from adarl.algos import replay, sac, sac_config, sac_device, schedule
from adarl.errors import UsageError
from adarl.runs import checkpoints, codec, layout
from adarl.train.guards import check_device_memory, check_training_memory
from adarl.train.learner import Advance, Episode, Truncation, due
from adarl.train.sac_learner import (
    BASE_COLUMNS,
    LEGACY_TRUNCATION_COLUMNS,
    TRUNCATION_COLUMNS,
    finite_parameters,
    nonfinite_quantities,
    truncation_rows,
)

BACKEND = "device"
BUFFER_KEYS = ("obs", "act", "rew", "term", "valid", "ptr", "size")
PENDING = "pending"  # arrays.npz prefix of the update metrics not yet averaged into train.csv


@dataclass(frozen=True)
class SeedPhysics:
    """Physics that is one model for every episode, the device learner's view of it: `fields`,
    `mjx.Model` leaves by dotted name, arrays of shape (seeds, episodes, …) (empty: the task's
    own model); `params`, the physical parameters episodes.csv records (name -> (seeds,
    episodes)). Episode e of a seed uses row e mod (episodes). Per-episode schedules use
    `adarl.device.physics.PhysicsRing`, which has the same three members."""

    fields: dict
    params: dict

    def episode_params(self, index: int, episode: int) -> dict:
        return {k: float(v[index, episode % v.shape[1]]) for k, v in self.params.items()}

    def fill(self, current) -> bool:
        """The rows never change (`PhysicsRing.fill` refills a ring)."""
        return False


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


def seed_physics(config, task):
    """The per-episode physics of a run's seeds: `fixed_physics` for dynamics that are one model,
    else a `PhysicsRing` of ``update_every + 1`` rows per seed (a chunk starts at most
    `update_every` episodes besides the running one) in the task's floating type."""
    from adarl.device.physics import PhysicsRing
    from adarl.envs.dynamics import parse_dynamics

    if not parse_dynamics(config.dynamics, config.task).varies:
        return fixed_physics(config)
    table = schedule_table(config.task, config.dynamics)
    return PhysicsRing(table, config.seeds, config.update_every + 1, np.dtype(task.dtype))


class EnvView:
    """What the loop reads of a seed's environment (the episode's parameters, a state for
    meta.json, `close`); the task itself lives on the device."""

    def __init__(self, params: dict):
        self.dynamics_params = params

    def get_state(self) -> dict:
        return {"backend": BACKEND}

    def close(self) -> None:
        pass


@dataclass(eq=False)
class Compiled:
    """The jitted, seed-vmapped functions of one spec."""

    init_env: callable
    chunk: callable
    truncate: callable
    ranks: callable


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


def compile_functions(spec: sac.Spec) -> Compiled:
    """Jitted functions for `spec`, shared by the runs of this process that use it at the same
    time (each compile of a device chunk takes tens of seconds on a CPU)."""
    fns = _COMPILED.get(spec)
    if fns is None:
        task = device_task(spec.config.task, spec.config.dynamics, spec.config.device_solver)
        vmap = jax.vmap

        def chunk(n_steps, state, env, table, step, update):
            one = functools.partial(sac_device.chunk, spec, task, n_steps)
            return vmap(one, in_axes=(0, 0, 0, None, None))(state, env, table, step, update)

        fns = _COMPILED[spec] = Compiled(
            init_env=jax.jit(vmap(functools.partial(sac_device.init_env, task))),
            chunk=jax.jit(chunk, static_argnums=(0,), donate_argnums=(1, 2)),
            truncate=jax.jit(vmap(functools.partial(sac.truncate, spec)), donate_argnums=(0,)),
            ranks=jax.jit(vmap(functools.partial(sac.rank_state, spec))),
        )
    return fns


class DeviceSACLearner:
    """A SAC-family run on the device backend: all seeds in one vmapped state."""

    def __init__(self, config: sac_config.SACConfig, physics=None):
        from adarl.device import missing_reason
        from adarl.envs import make

        config.check_device()
        reason = missing_reason()
        if reason is not None:
            raise UsageError(f"--backend device needs MJX: {reason}")
        self.config = config
        self.algo = config.algo
        self.seeds = list(config.seeds)
        self.n = len(self.seeds)
        self.env_options = config.env_options()
        task = device_task(config.task, config.dynamics, config.device_solver)
        # SeedPhysics or PhysicsRing: fields, episode_params, fill
        self.physics = seed_physics(config, task) if physics is None else physics
        self.envs = [EnvView(self.physics.episode_params(i, 0)) for i in range(self.n)]
        low, high = np.asarray(task.mj_model.actuator_ctrlrange, np.float32).T
        self.spec = sac.make_spec(config, task.observation_size, task.action_size, low, high)
        self.layer_names = sac.bottleneck_names(config)
        self.truncation_steps = set(schedule.truncation_steps(config))
        memory = (
            self.n,
            self.n * config.buffer_size * replay.row_bytes(self.spec.obs_dim, self.spec.act_dim),
            self.n * sac.state_bytes(self.spec)
            + sum(v.nbytes for v in self.physics.fields.values()),
            f"lower --buffer-size ({config.buffer_size}) or --hidden "
            f"({','.join(map(str, config.hidden))}), or train fewer seeds per run",
        )
        check_training_memory(*memory)
        check_device_memory(*memory)
        for label in config.eval_dynamics:  # evaluation runs on the host tasks; checked now
            make(
                config.task, dynamics=label, seed=0, **self.env_options | {"max_episode_steps": 1}
            ).close()
        extra = ["parseval_penalty"] if config.parseval_coef > 0 else []
        self.train_columns = BASE_COLUMNS + extra + [f"rank_{n}" for n in self.layer_names]
        self.extra_logs = (
            {layout.TRUNCATIONS_CSV: (TRUNCATION_COLUMNS, LEGACY_TRUNCATION_COLUMNS)}
            if config.adapt_rank
            else {}
        )
        self.fns = compile_functions(self.spec)
        self.table = jax.device_put(self.physics.fields)  # refilled before each chunk
        self.episodes = np.zeros(self.n, np.int64)  # each seed's current episode index
        self.infos: list = []  # update metrics of each chunk since the last train.csv rows
        self.metric_means: dict | None = None  # of the latest train.csv rows, per seed

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
        self.rngs = [np.random.default_rng(s) for s in self.seeds]  # meta.json; unused
        self.infos = []

    def initial_state(self) -> dict:
        """Every seed's SAC state without its buffer, stacked (NumPy; the host's parameters)."""
        states = [sac.init_state(self.spec, s, with_buffer=False) for s in self.seeds]
        return jax.tree_util.tree_map(lambda *a: np.stack(a), *states)

    def load_physics(self) -> None:
        """Put on the device the rows of each seed's episodes from its current one (`episodes`)
        to the last a chunk can start (refilled on the host where they changed)."""
        if self.physics.fill(self.episodes):  # copies: fill writes the host rows in place
            self.table = jax.device_put({k: v.copy() for k, v in self.physics.fields.items()})

    def env_keys(self) -> np.ndarray:
        return np.stack([sac_device.env_key(s) for s in self.seeds])

    def checkpoint_state(self) -> tuple[dict[str, np.ndarray], dict]:
        """Everything to continue exactly: the SAC state, the replay rows written so far (and
        the provisional one), the environment side (task states, observations, returns, keys)
        and the update metrics not yet in train.csv."""
        buffer = self.state["buffer"]
        arrays = codec.flatten_tree(
            jax.device_get({k: v for k, v in self.state.items() if k != "buffer"}), "state"
        )
        used = int(min(buffer["obs"].shape[1], int(np.max(jax.device_get(buffer["size"]))) + 1))
        for k in BUFFER_KEYS:  # only the rows written so far leave the device
            rows = buffer[k] if k in ("ptr", "size") else buffer[k][:, :used]
            arrays[f"buffer/{k}"] = np.asarray(jax.device_get(rows))
        arrays.update(codec.flatten_tree(jax.device_get(self.env), "env_device"))
        for name in self.infos[0] if self.infos else ():
            arrays[f"{PENDING}/{name}"] = np.stack([np.asarray(i[name]) for i in self.infos])
        return arrays, {"backend": BACKEND}

    def restore(self, arrays: dict, meta: dict) -> None:
        if meta.get("backend") != BACKEND:
            raise UsageError(
                f"this checkpoint was written by the {meta.get('backend', 'host')} backend; "
                "--backend device resumes only device checkpoints"
            )
        c = self.config
        state = codec.unflatten_tree(self.initial_state(), arrays, "state")
        buffer = replay.init_buffer(c.buffer_size, self.spec.obs_dim, self.spec.act_dim)
        for k in BUFFER_KEYS:
            saved = arrays[f"buffer/{k}"]
            if saved.shape[0] != self.n or saved.shape[2:] != buffer[k].shape[1:]:
                raise UsageError(
                    f"checkpoint buffer {k!r} has shape {saved.shape}; expected {self.n} seeds "
                    f"and rows of shape {buffer[k].shape[1:]}"
                )
            if k in ("ptr", "size"):
                buffer[k] = saved
            else:  # the rows past those written are zeros, as they were
                full = np.zeros((self.n, *buffer[k].shape), buffer[k].dtype)
                full[:, : saved.shape[1]] = saved
                buffer[k] = full
        state["buffer"] = buffer
        self.state = jax.device_put(state)
        env = jax.eval_shape(self.fns.init_env, self.env_keys(), self.table)
        self.env = jax.device_put(codec.unflatten_tree(env, arrays, "env_device"))
        self.episodes = np.asarray(jax.device_get(self.env["episode"]), np.int64)
        self.load_physics()  # the ring from the episode counters (its rows depend on them only)
        names = [k.split("/", 1)[1] for k in arrays if k.startswith(f"{PENDING}/")]
        n = arrays[f"{PENDING}/{names[0]}"].shape[0] if names else 0
        self.infos = [{name: arrays[f"{PENDING}/{name}"][j] for name in names} for j in range(n)]
        self.rngs = checkpoints.restore_rngs(meta, self.seeds)

    # ------------------------------------------------------------------ acting and learning
    def advance(self, step: int) -> Advance:
        """One chunk of every seed from `step` (one jitted call); the episodes that ended in it,
        ordered by step, then by seed."""
        c = self.config
        end = schedule.chunk_end(c, step)
        update = schedule.chunk_updates(c, end)
        self.load_physics()
        self.state, self.env, ended, info = self.fns.chunk(
            end - step, self.state, self.env, self.table, np.int32(step), np.bool_(update)
        )
        if update:
            self.infos.append(info)
        done, ret, length, index = jax.device_get(ended)  # (seeds, steps)
        self.episodes = index[:, -1].astype(np.int64) + done[:, -1]  # the episode running now
        episodes = []
        for k, i in zip(*np.nonzero(done.T)):
            info = {
                "episode_index": int(index[i, k]),
                "dynamics": self.physics.episode_params(i, int(index[i, k])),
            }
            episodes.append(
                Episode(int(i), step + int(k) + 1, info, float(ret[i, k]), int(length[i, k]))
            )
        return Advance(end, episodes, due(c, end, truncate=end in self.truncation_steps))

    def parameters_finite(self) -> bool:
        finite = jax.device_get(finite_parameters(self.state))
        return all(np.all(ok) for ok in finite.values())

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
    def train_rows(self, step: int, steps_per_s: float) -> list[dict]:
        """One train.csv row per seed: the update metrics averaged since the last rows, and the
        ranks (none before the first update)."""
        if not self.infos:
            return []
        infos = jax.device_get(self.infos)
        self.infos = []
        mean = self.metric_means = {k: np.mean([i[k] for i in infos], axis=0) for k in infos[0]}
        ranks = jax.device_get(self.fns.ranks(self.state))
        rows = []
        for i, seed in enumerate(self.seeds):
            row = {"step": step, "seed": seed, "steps_per_s": steps_per_s}
            row.update({k: mean[k][i] for k in ("loss_q", "loss_pi", "alpha", "entropy")})
            row.update({"q_mean": mean["q_mean"][i], "lr": mean["lr"][i]})
            if self.config.parseval_coef > 0:
                row["parseval_penalty"] = mean["penalty_actor"][i] + mean["penalty_critic"][i]
            row.update({f"rank_{n}": int(ranks[n][i]) for n in self.layer_names})
            rows.append(row)
        return rows

    def policies(self) -> list[dict]:
        """Each seed's deterministic policy (its actor's arrays, bottlenecks compacted)."""
        actor = jax.device_get(self.state["actor"])
        masks = jax.device_get(self.state["masks"]["actor"])
        return [
            sac.export_policy(self.spec, _take(actor, i), _take(masks, i)) for i in range(self.n)
        ]

    def nonfinite(self, step: int) -> dict[str, list[int]]:
        """Non-finite update metrics of the latest train.csv rows, parameters, optimiser states
        or returns, by quantity."""
        finite = jax.device_get(finite_parameters(self.state))
        returns = jax.device_get(self.env["ep_return"])
        return nonfinite_quantities(self.seeds, self.metric_means, finite, returns)


def _take(tree, i: int):
    return jax.tree_util.tree_map(lambda a: a[i], tree)
