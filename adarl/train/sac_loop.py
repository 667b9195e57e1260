"""The training loop of the SAC family: several seeds in one process, vmapped.

Each seed has its own environment, replay buffer, networks and RNG streams; the jitted update
of `adarl.algos.sac` is `vmap`ped over seeds, so all seeds advance in lock-step. The host steps
the environments, collects `update_every` transitions per seed, then makes one jitted call that
appends them to the device buffers and runs `update_every` gradient steps (`lax.scan`).

Writes the run folder described in docs/run-format.md and checkpoints everything needed to
continue exactly: `train(config, run_dir, resume=True)` restores the newest complete checkpoint,
cuts the CSV logs back to it and continues with the same results as an uninterrupted run.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import time
from io import BytesIO
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from adarl import __version__
from adarl.algos import sac
from adarl.errors import UsageError
from adarl.train import buffer as replay
from adarl.train import io

BASE_COLUMNS = [
    "step",
    "seed",
    "steps_per_s",
    "loss_q",
    "loss_pi",
    "alpha",
    "entropy",
    "q_mean",
    "lr",
]
BUFFER_ROW_KEYS = ("obs", "act", "rew", "term", "valid")


@dataclasses.dataclass
class Compiled:
    """The jitted, seed-vmapped functions of one run."""

    collect: callable  # append rows only (before update_after)
    collect_and_update: callable
    act: callable
    truncate: callable
    ranks: callable
    diagnostics: callable


@functools.lru_cache(maxsize=8)
def compile_functions(spec: sac.Spec) -> Compiled:
    """Jitted functions for `spec` (cached: runs with the same spec share compilations)."""
    c = spec.config
    vmap = jax.vmap
    append = functools.partial(sac.append_and_update, spec, n_updates=0)
    update = functools.partial(sac.append_and_update, spec, n_updates=c.update_every)

    def act(actor, masks, obs, key):
        key, sub = jax.random.split(key)
        return sac.act(spec, actor, masks, obs, sub), key

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
        act=jax.jit(vmap(act)),
        truncate=jax.jit(vmap(functools.partial(sac.truncate, spec)), donate_argnums=(0,)),
        ranks=jax.jit(vmap(functools.partial(sac.rank_state, spec))),
        diagnostics=jax.jit(vmap(diagnostics)),
    )


def config_to_yaml(config, extra: dict | None = None) -> str:
    values = {
        k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(config).items()
    }
    values.update(extra or {})
    return yaml.safe_dump(values, sort_keys=False)


class Run:
    """Host-side state of a run: environments, counters, logs. Pure data plus the loop."""

    def __init__(self, config: sac.SACConfig, run_dir: Path, progress: bool = True):
        from adarl.envs import make

        self.config = config.validate()
        self.run_dir = Path(run_dir)
        self.progress = progress
        self.seeds = list(config.seeds)
        self.n = len(self.seeds)
        self.envs = [  # an unknown task or dynamics fails here, before anything is written
            make(
                config.task,
                dynamics=config.dynamics,
                seed=s,
                max_episode_steps=config.max_episode_steps,
            )
            for s in self.seeds
        ]
        space = self.envs[0].action_space
        self.spec = sac.make_spec(
            config, self.envs[0].observation_space.shape[0], space.shape[0], space.low, space.high
        )
        self.fns = compile_functions(self.spec)
        self.layer_names = sac.bottleneck_names(config)
        self.builder = replay.ChunkBuilder(
            self.n, config.update_every, self.spec.obs_dim, self.spec.act_dim
        )

    # ------------------------------------------------------------------ state
    def fresh(self) -> None:
        c = self.config
        states = [sac.init_state(self.spec, s, with_buffer=False) for s in self.seeds]
        self.state = jax.device_put(jax.tree_util.tree_map(lambda *a: np.stack(a), *states))
        self.state["buffer"] = replay.empty_buffers(
            self.n, c.buffer_size, self.spec.obs_dim, self.spec.act_dim
        )
        self.act_keys = jnp.asarray(np.stack([sac.action_key(s) for s in self.seeds]))
        self.np_rngs = [np.random.default_rng(s) for s in self.seeds]
        self.step = 0
        self.obs = np.zeros((self.n, self.spec.obs_dim), np.float32)
        self.ep_return = np.zeros(self.n)
        self.ep_length = np.zeros(self.n, np.int64)
        for i, env in enumerate(self.envs):
            o, _ = env.reset(seed=self.seeds[i])
            self.obs[i] = o

    def checkpoint_arrays(self) -> dict[str, np.ndarray]:
        state = jax.device_get(self.state)
        buf = state.pop("buffer")
        # only the rows written so far (plus the provisional one) are worth saving
        used = int(min(buf["obs"].shape[1], int(np.max(buf["size"])) + 1))
        arrays = io.flatten_tree(state, "state")
        for k in BUFFER_ROW_KEYS:
            arrays[f"buffer/{k}"] = buf[k][:, :used]
        arrays["buffer/ptr"], arrays["buffer/size"] = buf["ptr"], buf["size"]
        arrays["host/act_keys"] = np.asarray(self.act_keys)
        arrays["host/obs"] = self.obs
        arrays["host/ep_return"] = self.ep_return
        arrays["host/ep_length"] = self.ep_length
        return arrays

    def restore(self, arrays: dict, meta: dict) -> None:
        c = self.config
        if meta.get("bottleneck_widths"):
            self.use_spec(sac.with_widths(self.spec, meta["bottleneck_widths"]))
        one = sac.init_state(self.spec, 0, with_buffer=False)
        template = jax.tree_util.tree_map(
            lambda a: np.zeros((self.n, *np.shape(a)), np.asarray(a).dtype), one
        )
        state = jax.device_put(io.unflatten_tree(template, arrays, "state"))
        buf = replay.empty_buffers(self.n, c.buffer_size, self.spec.obs_dim, self.spec.act_dim)
        for k in BUFFER_ROW_KEYS:
            saved = arrays[f"buffer/{k}"]
            if saved.shape[0] != self.n or saved.shape[2:] != buf[k].shape[2:]:
                raise UsageError(
                    f"checkpoint buffer {k!r} has shape {saved.shape}; expected "
                    f"{self.n} seeds and rows of shape {buf[k].shape[2:]}"
                )
            buf[k] = buf[k].at[:, : saved.shape[1]].set(saved)
        buf["ptr"], buf["size"] = (
            jnp.asarray(arrays["buffer/ptr"]),
            jnp.asarray(arrays["buffer/size"]),
        )
        state["buffer"] = buf
        self.state = state
        self.act_keys = jnp.asarray(arrays["host/act_keys"])
        self.obs = arrays["host/obs"].astype(np.float32)
        self.ep_return = arrays["host/ep_return"].copy()
        self.ep_length = arrays["host/ep_length"].copy()
        self.step = int(meta["step"])
        self.np_rngs = []
        for s, rng_state in zip(self.seeds, meta["np_rngs"]):
            rng = np.random.default_rng(s)
            rng.bit_generator.state = rng_state
            self.np_rngs.append(rng)
        for env, env_state in zip(self.envs, meta["env_states"]):
            env.set_state(_from_json(env_state))

    # ------------------------------------------------------------------ logs
    def open_logs(self, offsets: dict | None) -> None:
        d = self.run_dir
        if offsets:
            for name, offset in offsets.items():
                io.CsvLog.truncate(d / name, offset)
        params = self.param_columns()
        extra = []
        if self.config.parseval_coef > 0:
            extra.append("parseval_penalty")
        if self.config.sparse_width:
            extra.append("active_fraction")
        self.logs = {
            "episodes.csv": io.CsvLog(
                d / "episodes.csv", ["step", "seed", "episode", "return", "length", *params]
            ),
            "train.csv": io.CsvLog(
                d / "train.csv", BASE_COLUMNS + extra + [f"rank_{n}" for n in self.layer_names]
            ),
            "eval.csv": io.CsvLog(
                d / "eval.csv", ["step", "seed", "dynamics", "episode", "return", "length"]
            ),
        }
        if self.config.adapt_rank:
            self.logs["truncations.csv"] = io.CsvLog(
                d / "truncations.csv",
                ["step", "seed", "layer", "old_rank", "proposed_rank", "new_rank"],
            )
        self.tb = io.Scalars(d / "tb", purge_step=self.step if offsets else None)

    def param_columns(self) -> list[str]:
        return [f"p_{k}" for k in (self.envs[0].dynamics_params or {})]

    def close_logs(self) -> None:
        for log in self.logs.values():
            log.close()
        self.tb.close()

    # ------------------------------------------------------------------ pieces of the loop
    def choose_actions(self) -> np.ndarray:
        if self.step < self.config.start_steps:
            low, high = np.asarray(self.spec.act_low), np.asarray(self.spec.act_high)
            return np.stack([rng.uniform(low, high).astype(np.float32) for rng in self.np_rngs])
        actions, self.act_keys = self.fns.act(
            self.state["actor"], self.state["masks"]["actor"], jnp.asarray(self.obs), self.act_keys
        )
        return np.asarray(actions)

    def env_step(self, actions: np.ndarray) -> None:
        self.step += 1
        for i, env in enumerate(self.envs):
            next_obs, reward, terminated, truncated, info = env.step(actions[i])
            self.ep_return[i] += reward
            self.ep_length[i] += 1
            done = terminated or truncated
            self.builder.add(i, self.obs[i], actions[i], reward, terminated, next_obs, done)
            if done:
                row = {
                    "step": self.step,
                    "seed": self.seeds[i],
                    "episode": int(info["episode_index"]),
                    "return": float(self.ep_return[i]),
                    "length": int(self.ep_length[i]),
                }
                row.update({f"p_{k}": v for k, v in info["dynamics"].items()})
                self.logs["episodes.csv"].write(row)
                self.tb.write(self.step, {f"episode/return/seed{self.seeds[i]}": self.ep_return[i]})
                self.recent_returns.append(float(self.ep_return[i]))
                self.ep_return[i], self.ep_length[i] = 0.0, 0
                next_obs, _ = env.reset()
            self.obs[i] = next_obs

    def end_chunk(self) -> None:
        for i in range(self.n):
            self.builder.close(i, self.obs[i])
        rows, n_rows = self.builder.rows()
        rows = {k: jnp.asarray(v) for k, v in rows.items()}
        if self.step >= self.config.update_after:
            self.state, info = self.fns.collect_and_update(self.state, rows, jnp.asarray(n_rows))
            self.pending_infos.append(info)
        else:
            self.state, _ = self.fns.collect(self.state, rows, jnp.asarray(n_rows))
        self.builder.clear()

    def maybe_truncate(self) -> None:
        c = self.config
        if not c.adapt_rank:
            return
        since = int(self.state["n_updates"][0] - self.state["iteration_start"][0])
        if since < c.truncate_every:
            return
        old = jax.device_get(self.fns.ranks(self.state))
        self.state, report = self.fns.truncate(self.state)
        report = jax.device_get(report)
        spectra = {name: np.asarray(s) for name, (s, _, _) in report.items()}
        buf = BytesIO()
        np.savez(buf, seeds=np.asarray(self.seeds), **spectra)
        io.atomic_write_bytes(
            self.run_dir / "spectra" / f"step_{self.step:012d}.npz", buf.getvalue()
        )
        rows = []
        for name, (_, proposed, new) in report.items():
            for i, seed in enumerate(self.seeds):
                rows.append(
                    {
                        "step": self.step,
                        "seed": seed,
                        "layer": name,
                        "old_rank": int(old[name][i]),
                        "proposed_rank": int(proposed[i]),
                        "new_rank": int(new[i]),
                    }
                )
        self.logs["truncations.csv"].write(rows)
        if c.compact_bottlenecks:
            self.narrow_bottlenecks(jax.device_get(self.fns.ranks(self.state)))

    def narrow_bottlenecks(self, ranks: dict) -> None:
        """Store each bottleneck only as wide as the largest rank among the seeds (and recompile
        the update for those shapes): the cut components are exactly zero."""
        widths = {}
        for key in sac.bottleneck_widths(self.spec):
            net, _, i = key.partition(":")
            names = [f"actor_{i}"] if net == "actor" else [f"q1_{i}", f"q2_{i}"]
            widths[key] = int(max(np.max(ranks[n]) for n in names))
        if widths != sac.bottleneck_widths(self.spec):
            self.use_spec(sac.with_widths(self.spec, widths))
            self.state = sac.narrow_state(self.spec, self.state)

    def use_spec(self, spec: sac.Spec) -> None:
        self.spec = spec
        self.fns = compile_functions(spec)

    def write_train_log(self, steps_per_s: float) -> None:
        infos = jax.device_get(self.pending_infos)
        self.pending_infos = []
        if not infos:
            return
        mean = {k: np.mean([i[k] for i in infos], axis=0) for k in infos[0]}
        ranks = jax.device_get(self.fns.ranks(self.state))
        diag = jax.device_get(self.fns.diagnostics(self.state))
        rows = []
        for i, seed in enumerate(self.seeds):
            row = {
                "step": self.step,
                "seed": seed,
                "steps_per_s": steps_per_s,
                "loss_q": mean["loss_q"][i],
                "loss_pi": mean["loss_pi"][i],
                "alpha": mean["alpha"][i],
                "entropy": mean["entropy"][i],
                "q_mean": mean["q_mean"][i],
                "lr": mean["lr"][i],
            }
            if self.config.parseval_coef > 0:
                row["parseval_penalty"] = mean["penalty_actor"][i] + mean["penalty_critic"][i]
            if self.config.sparse_width:
                row["active_fraction"] = diag["active_fraction"][i]
            row.update({f"rank_{n}": int(ranks[n][i]) for n in self.layer_names})
            rows.append(row)
            self.tb.write(
                self.step,
                {f"train/{k}/seed{seed}": v for k, v in row.items() if k not in ("step", "seed")},
            )
        self.logs["train.csv"].write(rows)

    def export_policies(self) -> list[dict]:
        actor = jax.device_get(self.state["actor"])
        masks = jax.device_get(self.state["masks"]["actor"])
        take = lambda tree, i: jax.tree_util.tree_map(lambda a: a[i], tree)  # noqa: E731
        return [sac.export_policy(self.spec, take(actor, i), take(masks, i)) for i in range(self.n)]

    def evaluate(self) -> None:
        from adarl.evaluation.rollout import run_episodes
        from adarl.policy import NumpyPolicy

        c = self.config
        for i, arrays in enumerate(self.export_policies()):
            policy = NumpyPolicy(arrays)
            for label in c.eval_dynamics:
                rows = run_episodes(
                    policy,
                    c.task,
                    label,
                    c.eval_episodes,
                    seed=1_000_000 + self.seeds[i],
                    max_episode_steps=c.max_episode_steps,
                )
                self.logs["eval.csv"].write(
                    [
                        {
                            "step": self.step,
                            "seed": self.seeds[i],
                            "dynamics": label,
                            "episode": r["episode"],
                            "return": r["return"],
                            "length": r["length"],
                        }
                        for r in rows
                    ]
                )
                mean_return = float(np.mean([r["return"] for r in rows]))
                self.tb.write(self.step, {f"eval/{label}/return/seed{self.seeds[i]}": mean_return})
                self.last_eval[self.seeds[i]] = mean_return

    def save(self) -> None:
        from adarl.policy import to_bytes

        meta = {
            "algo": self.config.algo,
            "seeds": self.seeds,
            "np_rngs": [rng.bit_generator.state for rng in self.np_rngs],
            "env_states": [_to_json(env.get_state()) for env in self.envs],
            "csv_offsets": {name: log.offset() for name, log in self.logs.items()},
            "bottleneck_widths": sac.bottleneck_widths(self.spec),
        }
        policies = {
            f"policy_seed_{seed}.npz": to_bytes(arrays)
            for seed, arrays in zip(self.seeds, self.export_policies())
        }
        io.save_checkpoint(
            self.run_dir,
            self.step,
            self.checkpoint_arrays(),
            meta,
            keep=self.config.keep_checkpoints,
            files=policies,
        )

    # ------------------------------------------------------------------ the loop
    def loop(self) -> None:
        c = self.config
        self.pending_infos, self.recent_returns, self.last_eval = [], [], {}
        bar = _progress(c.total_steps, self.step, self.progress)
        t_log, s_log = time.perf_counter(), self.step
        while self.step < c.total_steps:
            self.env_step(self.choose_actions())
            t = self.step
            if t % c.update_every == 0 or t == c.total_steps:
                self.end_chunk()
                self.maybe_truncate()
            if t % c.log_every == 0 or t == c.total_steps:
                now = time.perf_counter()
                rate = (t - s_log) / max(now - t_log, 1e-9)
                self.write_train_log(rate)
                t_log, s_log = now, t
            if t % c.eval_every == 0 or t == c.total_steps:
                self.evaluate()
            if t % c.checkpoint_every == 0 or t == c.total_steps:
                self.save()
            if bar is not None and (t % 100 == 0 or t == c.total_steps):
                recent = self.recent_returns[-10 * self.n :]
                bar.set_postfix_str(
                    f"return {np.mean(recent):.0f}" if recent else "return -", refresh=False
                )
                bar.update(t - bar.n)
        if bar is not None:
            bar.close()
        io.atomic_write_text(self.run_dir / "DONE", f"{self.step}\n")


def _progress(total: int, start: int, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(
        total=total, initial=start, unit="step", dynamic_ncols=True, file=sys.stderr, smoothing=0.05
    )


def _to_json(value):
    if isinstance(value, dict):
        return {k: _to_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_to_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return {"__ndarray__": value.tolist(), "dtype": str(value.dtype)}
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return value


def _from_json(value):
    if isinstance(value, dict):
        if "__ndarray__" in value:
            return np.asarray(value["__ndarray__"], dtype=value["dtype"])
        return {k: _from_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_from_json(v) for v in value]
    return value


def train(
    config: sac.SACConfig,
    run_dir: str | Path,
    resume: bool = False,
    progress: bool = True,
    command: str = "",
) -> Path:
    """Train (or resume) a SAC-family run into `run_dir`; returns the run folder."""
    run_dir = Path(run_dir)
    if resume:
        run = Run(config, run_dir, progress)
        found = io.checkpoint_dirs(run_dir)
        if (run_dir / "DONE").exists():
            print(f"run {run_dir} is already complete", file=sys.stderr)
            return run_dir
        if found:
            arrays, meta = io.load_checkpoint(found[-1])
            run.restore(arrays, meta)
            run.open_logs(meta["csv_offsets"])
        else:  # killed before its first checkpoint: start again, keeping nothing half-done
            run.fresh()
            run.open_logs(
                {name: 0 for name in ("episodes.csv", "train.csv", "eval.csv", "truncations.csv")}
            )
    else:
        if run_dir.exists() and any(run_dir.iterdir()):
            raise UsageError(
                f"run folder {run_dir} already exists and is not empty; "
                f"resume it with --resume {run_dir} or choose another --out"
            )
        run = Run(config, run_dir, progress)
        run_dir.mkdir(parents=True, exist_ok=True)
        io.atomic_write_text(
            run_dir / "config.yaml",
            config_to_yaml(
                config,
                {
                    "format_version": io.RUN_FORMAT_VERSION,
                    "adarl_version": __version__,
                    "command": command,
                },
            ),
        )
        run.fresh()
        run.open_logs(None)
    try:
        run.loop()
    finally:
        run.close_logs()
    return run_dir


def load_run_config(run_dir: str | Path) -> dict:
    """Read and check a run folder's config.yaml (one-line errors for anything wrong)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UsageError(f"run folder {run_dir} does not exist")
    path = run_dir / "config.yaml"
    if not path.exists():
        raise UsageError(f"{run_dir} is not a run folder (no config.yaml)")
    try:
        values = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise UsageError(f"{path} is not valid YAML ({exc.__class__.__name__})") from exc
    if not isinstance(values, dict):
        raise UsageError(f"{path} is not a run config")
    version = values.get("format_version")
    if version != io.RUN_FORMAT_VERSION:
        raise UsageError(
            f"{run_dir} was written with run format {version!r}; this adarl "
            f"({__version__}) reads format {io.RUN_FORMAT_VERSION}"
        )
    return values
