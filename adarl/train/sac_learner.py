"""The learner of the SAC family for the training loop (`adarl.train.loop`): several seeds in
one process.

Each seed has its own environment, replay buffer, networks and RNG streams: it is its own
lane, with its own state, its own XLA computations (the jitted update of `adarl.algos.sac`,
`vmap`ped over a seed axis of length 1) and, once AdaRL has cut its rank, its own bottleneck
widths, so a seed's numbers are a function of (code, config, seed) alone, whichever seeds train
beside it (vmapping several seeds into one computation changes the matmul kernels, and so the
last bits, of every seed in it; the layout that did, `lanes: K`, is retired). The lanes advance
in lock-step: the host steps a lane's environment for `update_every` steps, then makes one
jitted call that appends the transitions to its device buffer and runs `update_every` gradient
steps (`lax.scan`). JAX runs a lane's update asynchronously while the host steps the next
lane's environment, so on a 2-core machine the simulator and the learner overlap. Exploration
actions are sampled on the host (`NumpyPolicy.sample`, noise from the seed's NumPy generator)
from a copy of the lane's actor taken after its update, so stepping a lane never waits behind
another lane's update. Every seed sees exactly Spinning Up's schedule: `update_every` steps with
the current policy, then `update_every` updates.

AdaRL truncates after the chunks `schedule.truncation_steps` lists (the one place that says when):
`advance` returns the `TRUNCATE` event there, the loop keeps a pre-truncation checkpoint (a fork
point), and `truncate` decomposes every bottleneck, narrows each lane's bottlenecks to its ranks
and returns the spectra and truncations.csv rows for the loop to write.
`checkpoint_state` holds everything needed to continue exactly (docs/run-format.md).
"""

from __future__ import annotations

import dataclasses
import functools
import weakref

import jax
import jax.numpy as jnp
import numpy as np

from adarl.algos import replay, sac, sac_config, schedule
from adarl.errors import UsageError
from adarl.runs import checkpoints, codec, npz
from adarl.train.learner import Advance, Episode, Truncation, due
from adarl.train.sac_family import SACFamily, finite_parameters, truncation_rows

BUFFER_ROW_KEYS = ("obs", "act", "rew", "term", "valid")
PENDING = "pending"  # arrays.npz prefix of the update metrics not yet averaged into train.csv


@dataclasses.dataclass
class Compiled:
    """The jitted, seed-vmapped functions of one lane (each lane size and width compiles its own)."""

    collect: callable  # append rows only (before update_after)
    collect_and_update: callable
    truncate: callable
    ranks: callable
    diagnostics: callable


# Compiled functions by spec, kept only while a lane uses them: every XLA:CPU executable holds
# its own memory maps, and a process that keeps the functions of every width it ever used runs
# into the kernel's limit on maps (vm.max_map_count, 65,530 by default) and crashes in XLA.
_COMPILED: weakref.WeakValueDictionary = weakref.WeakValueDictionary()


def compile_functions(spec: sac.Spec) -> Compiled:
    """Jitted functions for `spec`, shared by the lanes (and runs) using that spec at the same
    time and freed, with their executables, once no lane does."""
    fns = _COMPILED.get(spec)
    if fns is None:
        fns = _COMPILED[spec] = _compile_functions(spec)
    return fns


def _compile_functions(spec: sac.Spec) -> Compiled:
    c = spec.config
    vmap = jax.vmap
    append = functools.partial(sac.append_and_update, spec, n_updates=0)
    update = functools.partial(sac.append_and_update, spec, n_updates=c.update_every)

    def diagnostics(state):
        out = {}
        if c.sparse_width:
            obs = replay.sample(state["buffer"], jax.random.PRNGKey(0), c.batch_size)["obs"]
            h = sac.actor_features(spec, state["actor"], state["masks"]["actor"], obs)
            out["active_fraction"] = jnp.mean(h > 0)
        return out

    return Compiled(
        collect=jax.jit(vmap(append), donate_argnums=(0,)),
        collect_and_update=jax.jit(vmap(update), donate_argnums=(0,)),
        truncate=jax.jit(vmap(functools.partial(sac.truncate, spec)), donate_argnums=(0,)),
        ranks=jax.jit(vmap(functools.partial(sac.rank_state, spec))),
        diagnostics=jax.jit(vmap(diagnostics)),
    )


@dataclasses.dataclass
class Lane:
    """One seed and its vmapped update. Lanes take turns: while one lane's update runs (JAX
    dispatches it asynchronously), the host steps the next lane's environment, so the update and
    the simulator use both cores."""

    index: int  # the seed's position in SACLearner.seeds
    device: jax.Device
    state: dict  # device state, leading axis (length 1) = the seed
    builder: replay.ChunkBuilder
    spec: sac.Spec  # the lane's bottleneck widths
    fns: Compiled
    infos: list = dataclasses.field(default_factory=list)  # update metrics not yet logged
    actor: object = None  # host copy of the current policy (NumpyPolicy); None = stale


class SACLearner(SACFamily):
    """Environments, lanes of seeds and the host state of a SAC-family run."""

    def __init__(self, config: sac_config.SACConfig):
        from adarl.envs import make

        options = config.env_options()
        # the first seed's environment (an unknown task or dynamics fails here, before anything
        # is written) gives the sizes the memory check needs; the others are made after it
        first = make(config.task, dynamics=config.dynamics, seed=config.seeds[0], **options)
        space = first.action_space
        self.setup(config, first.observation_space.shape[0], space.shape[0], space.low, space.high)
        self.envs = [first]
        self.check_memory()
        self.envs += [
            make(config.task, dynamics=config.dynamics, seed=s, **options) for s in self.seeds[1:]
        ]
        self.check_eval_dynamics()

    # ------------------------------------------------------------------ state
    def fresh(self) -> None:
        states = [sac.init_state(self.spec, s, with_buffer=False) for s in self.seeds]
        self.set_lanes(jax.tree_util.tree_map(lambda *a: np.stack(a), *states))
        self.rngs = [np.random.default_rng(s) for s in self.seeds]
        self.obs = np.zeros((self.n, self.spec.obs_dim), np.float32)
        self.ep_return = np.zeros(self.n)
        self.ep_length = np.zeros(self.n, np.int64)
        for i, env in enumerate(self.envs):
            o, _ = env.reset(seed=self.seeds[i])
            self.obs[i] = o

    def set_lanes(
        self, state: dict, buffers: dict | None = None, lane_widths: list | None = None
    ) -> None:
        """Split a host state of all seeds (without buffers, bottlenecks `self.spec` wide) into
        one lane per seed, lane k on local device k mod (number of devices); `buffers`: saved
        buffer rows of all seeds, or None (empty); `lane_widths`: each lane's bottleneck widths
        (default `self.spec`'s)."""
        c = self.config
        devices = jax.local_devices()
        self.lanes = []
        for k in range(self.n):
            device = devices[k % len(devices)]
            spec = self.spec if lane_widths is None else sac.with_widths(self.spec, lane_widths[k])
            part = _take(state, slice(k, k + 1))
            if spec != self.spec:
                part = sac.resize_bottlenecks(spec, part)
            part = jax.device_put(part, device)
            buf = replay.empty_buffers(1, c.buffer_size, self.spec.obs_dim, self.spec.act_dim)
            if buffers is not None:
                for key in BUFFER_ROW_KEYS:
                    saved = buffers[key][k : k + 1]
                    buf[key] = buf[key].at[:, : saved.shape[1]].set(saved)
                buf["ptr"] = jnp.asarray(buffers["ptr"][k : k + 1])
                buf["size"] = jnp.asarray(buffers["size"][k : k + 1])
            part["buffer"] = jax.device_put(buf, device)
            builder = replay.ChunkBuilder(1, c.update_every, self.spec.obs_dim, self.spec.act_dim)
            self.lanes.append(
                Lane(
                    index=k,
                    device=device,
                    state=part,
                    builder=builder,
                    spec=spec,
                    fns=compile_functions(spec),
                )
            )

    def gather(self, fn):
        """`fn(lane)` of every lane on the host, concatenated along the seed axis in seed order
        (per-seed values: ranks, metrics, flags)."""
        return _concat_lanes([jax.device_get(fn(lane)) for lane in self.lanes])

    def checkpoint_state(self) -> tuple[dict[str, np.ndarray], dict]:
        """Everything to continue exactly, and meta.json's bottleneck widths; every lane's
        bottlenecks stored `self.spec` wide (the configured width), so a seed's arrays do not
        depend on the widths of the other seeds."""

        def stored(lane):
            state = {k: v for k, v in lane.state.items() if k != "buffer"}
            return state if lane.spec == self.spec else sac.resize_bottlenecks(self.spec, state)

        state = self.gather(stored)
        arrays = codec.flatten_tree(state, "state")
        bufs = [jax.device_get(lane.state["buffer"]) for lane in self.lanes]
        # only the rows written so far (plus the provisional one) are worth saving
        used = int(min(bufs[0]["obs"].shape[1], max(int(np.max(b["size"])) for b in bufs) + 1))
        for k in BUFFER_ROW_KEYS:  # joined in the file, not in memory
            arrays[f"buffer/{k}"] = npz.Stacked([b[k][:, :used] for b in bufs])
        for k in ("ptr", "size"):
            arrays[f"buffer/{k}"] = np.concatenate([b[k] for b in bufs])
        arrays["host/obs"] = self.obs
        arrays["host/ep_return"] = self.ep_return
        arrays["host/ep_length"] = self.ep_length
        for k, lane in enumerate(self.lanes):  # only between train.csv rows (no key otherwise)
            infos = jax.device_get(lane.infos)
            for name in infos[0] if infos else ():
                arrays[f"{PENDING}/{k}/{name}"] = np.stack([info[name] for info in infos])
        meta = {
            "bottleneck_widths": sac.bottleneck_widths(self.spec),
            "lane_bottleneck_widths": [sac.bottleneck_widths(lane.spec) for lane in self.lanes],
        }
        return arrays, meta | checkpoints.host_meta(self.rngs, self.envs, arrays)

    def restore(self, arrays: dict, meta: dict) -> None:
        if "host/act_keys" in arrays:
            raise UsageError(
                "this checkpoint was written by an adarl that sampled exploration actions with "
                "JAX keys; it cannot be continued exactly here: train a new run"
            )
        one = sac.init_state(self.spec, 0, with_buffer=False)
        template = jax.tree_util.tree_map(
            lambda a: np.zeros((self.n, *np.shape(a)), np.asarray(a).dtype), one
        )
        state = codec.unflatten_tree(template, arrays, "state")
        expected = {"obs": (self.spec.obs_dim,), "act": (self.spec.act_dim,)}
        buffers = {}
        for k in BUFFER_ROW_KEYS:
            saved = arrays[f"buffer/{k}"]
            if saved.shape[0] != self.n or saved.shape[2:] != expected.get(k, ()):
                raise UsageError(
                    f"checkpoint buffer {k!r} has shape {saved.shape}; expected "
                    f"{self.n} seeds and rows of shape {expected.get(k, ())}"
                )
            buffers[k] = saved
        buffers["ptr"], buffers["size"] = arrays["buffer/ptr"], arrays["buffer/size"]
        self.set_lanes(state, buffers, meta.get("lane_bottleneck_widths"))
        for k, lane in enumerate(self.lanes):  # metrics of updates since the last train.csv row
            names = [key.split("/")[-1] for key in arrays if key.startswith(f"{PENDING}/{k}/")]
            n = arrays[f"{PENDING}/{k}/{names[0]}"].shape[0] if names else 0
            lane.infos = [
                {name: arrays[f"{PENDING}/{k}/{name}"][j] for name in names} for j in range(n)
            ]
        self.obs = arrays["host/obs"].astype(np.float32)
        self.ep_return = arrays["host/ep_return"].copy()
        self.ep_length = arrays["host/ep_length"].copy()
        self.rngs = checkpoints.restore_rngs(meta, self.seeds)
        for env, env_state in zip(self.envs, meta["env_states"]):
            env.set_state(codec.decode_env_state(env_state, arrays))

    # ------------------------------------------------------------------ acting and learning
    def host_actor(self, lane: Lane):
        """The lane's current policy as a NumPy sampler (refreshed after each update): acting
        on the host needs no device call, so it never waits behind another lane's update."""
        from adarl.policy import NumpyPolicy

        if lane.actor is None:
            actor = _take(jax.device_get(lane.state["actor"]), 0)
            masks = _take(jax.device_get(lane.state["masks"]["actor"]), 0)
            lane.actor = NumpyPolicy(sac.export_policy(lane.spec, actor, masks, True))
        return lane.actor

    def choose_action(self, lane: Lane, t: int) -> np.ndarray:
        """The lane's action for environment step `t` (1-based): uniform before `start_steps`,
        then a = c + h·tanh(μ + σε) with ε from the seed's NumPy generator."""
        rng = self.rngs[lane.index]
        if t - 1 < self.config.start_steps:
            low, high = np.asarray(self.spec.act_low), np.asarray(self.spec.act_high)
            return rng.uniform(low, high).astype(np.float32)
        noise = rng.standard_normal(self.spec.act_dim, np.float32)
        return self.host_actor(lane).sample(self.obs[lane.index], noise)

    def env_step(self, lane: Lane, t: int, action: np.ndarray, episodes: list) -> None:
        """Environment step `t` of the lane's seed; its row goes to the lane's chunk builder, a
        finished episode to `episodes`."""
        i, env = lane.index, self.envs[lane.index]
        next_obs, reward, terminated, truncated, info = env.step(action)
        self.ep_return[i] += reward
        self.ep_length[i] += 1
        done = terminated or truncated
        lane.builder.add(0, self.obs[i], action, reward, terminated, next_obs, done)
        if done:
            episodes.append(Episode(i, t, info, float(self.ep_return[i]), int(self.ep_length[i])))
            self.ep_return[i], self.ep_length[i] = 0.0, 0
            next_obs, _ = env.reset()
        self.obs[i] = next_obs

    def end_chunk(self, lane: Lane, update: bool) -> None:
        """Send the lane's chunk of rows to its buffer and, if `update`, start its
        `update_every` gradient steps (asynchronous)."""
        lane.builder.close(0, self.obs[lane.index])
        rows, n_rows = jax.device_put(lane.builder.rows(), lane.device)
        if update:
            lane.state, info = lane.fns.collect_and_update(lane.state, rows, n_rows)
            lane.infos.append(info)
            lane.actor = None
        else:
            lane.state, _ = lane.fns.collect(lane.state, rows, n_rows)
        lane.builder.clear()

    def advance(self, step: int) -> Advance:
        """Advance every lane from `step` to the end of the current chunk of `update_every`
        steps: step a lane's environments, start its update, go on to the next lane."""
        c = self.config
        end = schedule.chunk_end(c, step)
        update = schedule.chunk_updates(c, end)
        episodes = []
        for lane in self.lanes:
            for t in range(step + 1, end + 1):
                self.env_step(lane, t, self.choose_action(lane, t), episodes)
            self.end_chunk(lane, update)
        return Advance(end, episodes, due(c, end, truncate=end in self.truncation_steps))

    def truncate(self, step: int) -> Truncation:
        """AdaRL's truncation, at the steps `schedule.truncation_steps` gives: every bottleneck
        decomposed and cut (Eq. 5 and the retain clause, `sac.truncate`) and each lane narrowed
        to its ranks; returns the spectra and truncations.csv rows."""
        c = self.config
        old = self.gather(_ranks)
        reports = []
        full = _layer_widths(self.spec)
        for lane in self.lanes:
            lane.state, report = lane.fns.truncate(lane.state)
            lane.actor = None
            report = jax.device_get(report)
            for name, (s, *rest) in report.items():  # spectra of narrow lanes: zero-padded
                report[name] = (_pad_last(s, full[name]), *rest)
            reports.append(report)
        report = _concat_lanes(reports)
        spectra, rows = truncation_rows(step, self.seeds, old, report, c.apply_cuts)
        if c.compact_bottlenecks:
            self.narrow_bottlenecks(self.gather(_ranks))
        return Truncation(spectra, rows)

    def narrow_bottlenecks(self, ranks: dict) -> None:
        """Store each lane's bottlenecks only as wide as their ranks (the largest of the layers
        that share a width) and recompile its update for those shapes: the cut components are
        exactly zero."""
        for lane in self.lanes:
            widths = {
                key: int(max(ranks[n][lane.index] for n in sac.layers_of_width(key)))
                for key in sac.bottleneck_widths(lane.spec)
            }
            if widths != sac.bottleneck_widths(lane.spec):
                lane.spec = sac.with_widths(lane.spec, widths)
                lane.fns = compile_functions(lane.spec)
                lane.state = sac.resize_bottlenecks(lane.spec, lane.state)

    # ------------------------------------------------------------------ what the loop reads
    def param_names(self) -> list[str]:
        return list(self.envs[0].dynamics_params or {})

    def close(self) -> None:
        for env in self.envs:
            env.close()

    # ------------------------------------------------------------------ per-seed values (SACFamily)
    def take_metric_means(self) -> dict | None:
        if not self.lanes[0].infos:
            return None
        per_lane = []
        for lane in self.lanes:
            infos = jax.device_get(lane.infos)
            lane.infos = []
            per_lane.append({k: np.mean([i[k] for i in infos], axis=0) for k in infos[0]})
        return _concat_lanes(per_lane)

    def seed_ranks(self) -> dict:
        return self.gather(_ranks)

    def seed_diagnostics(self) -> dict:
        return self.gather(lambda lane: lane.fns.diagnostics(lane.state))

    def seed_finite(self) -> dict:
        return self.gather(lambda lane: finite_parameters(lane.state))

    def seed_actors(self) -> list[tuple[sac.Spec, dict, dict]]:
        actors = []
        for lane in self.lanes:
            actor = jax.device_get(lane.state["actor"])
            masks = jax.device_get(lane.state["masks"]["actor"])
            actors.append((lane.spec, _take(actor, 0), _take(masks, 0)))
        return actors

    def episode_returns(self) -> np.ndarray:
        return self.ep_return


def _ranks(lane: Lane) -> dict:
    return lane.fns.ranks(lane.state)


def _layer_widths(spec: sac.Spec) -> dict[str, int]:
    """Stored width of every bottleneck, keyed like `sac.bottleneck_names` (actor_1, q1_1, …)."""
    return {
        name: w
        for key, w in sac.bottleneck_widths(spec).items()
        for name in sac.layers_of_width(key)
    }


def _pad_last(a: np.ndarray, n: int) -> np.ndarray:
    """`a` zero-padded along its last axis to length n."""
    return np.pad(a, [(0, 0)] * (a.ndim - 1) + [(0, n - a.shape[-1])])


def _concat_lanes(parts: list):
    """Per-lane host trees (leading axis: the lane's seeds) joined into one over all seeds."""
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a), *parts)


def _take(tree, i: int | slice):
    """Seed `i` (or a slice of seeds) of a tree of seed-stacked arrays."""
    return jax.tree_util.tree_map(lambda a: a[i], tree)
