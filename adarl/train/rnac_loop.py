"""RNAC's training loop (the maths is `adarl.algos.rnac`): every seed steps its own environment
on the host with a NumPy copy of its policy, double sampling (`ds`) values candidate next states
in a second simulator, and every `rollout_steps` all seeds are updated at once by the jitted,
seed-vmapped update. The host state (observation and reward normalisers, the rollout being
collected) is a `Host` of NumPy arrays; checkpoints hold it with the networks, the optimisers,
the key and generator states and the MuJoCo states, so a resumed run continues exactly
(docs/run-format.md). Reads top to bottom: the double-sampling simulator, the best policies,
the host state and its normalisers, the loop.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path

import jax
import numpy as np

from adarl.algos.rnac import (
    METRICS,
    TRAIN_COLUMNS,
    clip,
    critic_value,
    draw_double_sampling,
    host_params,
    init_states,
    make_update,
    normalise_obs,
    policy_arrays,
    sample_action,
    select_candidate,
    welford,
)
from adarl.algos.rnac_config import RNACConfig
from adarl.errors import UsageError
from adarl.train import io
from adarl.train import run_folder as rf


# ============================================================================ double sampling
class ShadowSimulator:
    """The second simulator of double sampling.

    It is a second `MjData` on the real environment's current `MjModel`, so it always has the
    current episode's dynamics: adarl.envs compiles a new model at each reset whose parameters
    change; a new model is noticed here, and the MjData is remade only if the model's sizes
    changed (as adarl.envs does itself). Each candidate starts from the real simulator's full
    integration state (`mj_getState(mjSTATE_INTEGRATION)`: time, qpos, qvel, act, warm start,
    controls, applied forces), is stepped by the task's own `do_simulation` and observed by its
    own `_get_obs` (the env's `data` is swapped for the duration). The real env is untouched.
    """

    def __init__(self, env):
        import mujoco

        self._mj = mujoco
        self.SPEC = mujoco.mjtState.mjSTATE_INTEGRATION
        self.env = env
        self._model = None

    def _sync(self):
        u = self.env.unwrapped
        if u.model is not self._model:
            old, self._model = self._model, u.model
            if old is None or _sizes(old) != _sizes(u.model):
                self._data = self._mj.MjData(u.model)
                self._state = np.empty(self._mj.mj_stateSize(u.model, self.SPEC))
        return u

    def candidates(self, actions: np.ndarray) -> np.ndarray:
        """Next observations, one per row of `actions`, each from the real env's current state."""
        u = self._sync()
        self._mj.mj_getState(u.model, u.data, self._state, self.SPEC)
        real, out = u.data, []
        try:
            u.data = self._data
            for a in actions:
                self._mj.mj_setState(u.model, self._data, self._state, self.SPEC)
                u.do_simulation(a, u.frame_skip)
                out.append(np.array(u._get_obs(), dtype=np.float64))
        finally:
            u.data = real
        return np.stack(out)


def _sizes(m) -> tuple:
    return (
        m.nq,
        m.nv,
        m.nu,
        m.na,
        m.nbody,
        m.ngeom,
        m.njnt,
        m.nmocap,
        m.nuserdata,
        m.narena,
        m.nbuffer,
    )


# ============================================================================ best policies
class BestPolicies:
    """Each seed's best policy by mean nominal evaluation return, kept beside the final one as
    RNAC's original keeps its best model. Every checkpoint stores it (`best_policy_seed_<s>.npz`
    and meta.json's `best`), so a resumed run selects exactly as an uninterrupted one."""

    METRIC = "mean nominal evaluation return"

    def __init__(self, seeds):
        self.seeds = [int(s) for s in seeds]
        self.record: dict[int, dict] = {}  # seed -> {"step": …, "return": …}
        self.files: dict[int, bytes] = {}  # seed -> the policy file's bytes

    def offer(self, seed: int, step: int, mean_return: float, policy: dict) -> None:
        """Keep `policy` if its finite `mean_return` beats the seed's best so far (ties: the
        earlier one)."""
        from adarl.policy import to_bytes

        best = self.record.get(seed)
        if math.isfinite(mean_return) and (best is None or mean_return > best["return"]):
            self.record[seed] = {"step": int(step), "return": float(mean_return)}
            self.files[seed] = to_bytes(policy)

    def meta(self) -> dict:
        seeds = {str(s): self.record[s] for s in self.seeds if s in self.record}
        return {"metric": self.METRIC, "dynamics": "nominal", "seeds": seeds}

    def checkpoint_files(self) -> dict[str, bytes]:
        return {f"best_policy_seed_{s}.npz": self.files[s] for s in self.seeds if s in self.files}

    def restore(self, meta: dict, checkpoint: Path) -> None:
        """Read the best back from a checkpoint (none recorded: start empty)."""
        for key, record in ((meta.get("best") or {}).get("seeds") or {}).items():
            path = Path(checkpoint) / f"best_policy_seed_{int(key)}.npz"
            try:
                self.files[int(key)] = path.read_bytes()
            except OSError:
                raise UsageError(
                    f"checkpoint {checkpoint} has no {path.name}, which its meta.json lists"
                ) from None
            self.record[int(key)] = {"step": int(record["step"]), "return": float(record["return"])}


# ============================================================================ training
@dataclass
class Host:
    """Everything outside JAX that a checkpoint holds, stacked over seeds (axis 0)."""

    obs_norm: np.ndarray  # (S, D) the current observation as the policy sees it
    obs_count: np.ndarray  # (S,) running state normaliser
    obs_mean: np.ndarray  # (S, D)
    obs_m2: np.ndarray  # (S, D)
    ret_count: np.ndarray  # (S,) reward scaling: running std of the discounted return
    ret_mean: np.ndarray
    ret_m2: np.ndarray
    ret_acc: np.ndarray  # (S,) the discounted return R of the current episode
    ep_return: np.ndarray  # (S,) raw return and length of the current episode
    ep_length: np.ndarray
    metrics: np.ndarray  # (S, len(METRICS)) of the latest update (NaN before the first)
    buf_obs: np.ndarray  # (S, T, D) the rollout so far
    buf_actions: np.ndarray
    buf_logp: np.ndarray
    buf_rewards: np.ndarray
    buf_next_obs: np.ndarray
    buf_terminated: np.ndarray
    buf_done: np.ndarray

    @classmethod
    def zeros(cls, n_seeds: int, obs_dim: int, act_dim: int, t: int) -> Host:
        f32 = np.float32
        return cls(
            obs_norm=np.zeros((n_seeds, obs_dim), f32),
            obs_count=np.zeros(n_seeds),
            obs_mean=np.zeros((n_seeds, obs_dim)),
            obs_m2=np.zeros((n_seeds, obs_dim)),
            ret_count=np.zeros(n_seeds),
            ret_mean=np.zeros(n_seeds),
            ret_m2=np.zeros(n_seeds),
            ret_acc=np.zeros(n_seeds),
            ep_return=np.zeros(n_seeds),
            ep_length=np.zeros(n_seeds, np.int64),
            metrics=np.full((n_seeds, len(METRICS)), np.nan, f32),
            buf_obs=np.zeros((n_seeds, t, obs_dim), f32),
            buf_actions=np.zeros((n_seeds, t, act_dim), f32),
            buf_logp=np.zeros((n_seeds, t), f32),
            buf_rewards=np.zeros((n_seeds, t), f32),
            buf_next_obs=np.zeros((n_seeds, t, obs_dim), f32),
            buf_terminated=np.zeros((n_seeds, t), f32),
            buf_done=np.zeros((n_seeds, t), f32),
        )

    def obs_var(self, i: int) -> np.ndarray:
        return self.obs_m2[i] / self.obs_count[i] if self.obs_count[i] > 0 else self.obs_m2[i] * 0


def _observe(host: Host, i: int, obs: np.ndarray, config: RNACConfig) -> np.ndarray:
    """Update seed i's state normaliser with a new observation and return it normalised."""
    if not config.obs_norm:
        return np.asarray(obs, np.float32)
    host.obs_count[i], host.obs_mean[i], host.obs_m2[i] = welford(
        host.obs_count[i], host.obs_mean[i], host.obs_m2[i], np.asarray(obs, np.float64)
    )
    return normalise_obs(obs, host.obs_mean[i], host.obs_var(i), config.obs_clip)


def _peek(host: Host, i: int, obs: np.ndarray, config: RNACConfig) -> np.ndarray:
    """Normalise without updating (double-sampling candidates)."""
    if not config.obs_norm:
        return np.asarray(obs, np.float32)
    return normalise_obs(obs, host.obs_mean[i], host.obs_var(i), config.obs_clip)


def _scale_reward(host: Host, i: int, r: float, config: RNACConfig) -> float:
    """The original's RewardScaling: R ← γR + r, r / (std(R) + 1e-8); the first reward of the
    run (std undefined) is passed unscaled."""
    if not config.reward_scaling:
        return r
    host.ret_acc[i] = config.gamma * host.ret_acc[i] + r
    host.ret_count[i], host.ret_mean[i], host.ret_m2[i] = welford(
        host.ret_count[i], host.ret_mean[i], host.ret_m2[i], host.ret_acc[i]
    )
    if host.ret_count[i] < 2:
        return r
    return r / (math.sqrt(host.ret_m2[i] / host.ret_count[i]) + 1e-8)


def train(
    config: RNACConfig,
    run_dir: Path,
    resume: bool = False,
    progress: bool = True,
    command: str = "",
) -> None:
    """Train RNAC for every seed of `config` together, writing the run folder `run_dir`
    (docs/run-format.md). With `resume`, continue from its newest intact checkpoint (or start
    again if it was killed before the first one). `command` is recorded in config.yaml. The run
    folder's lock is held from the first write to the end (docs/reliability.md)."""
    with io.RunLock(run_dir) as lock:
        _train(config, Path(run_dir), resume, progress, command, lock)


def _train(config: RNACConfig, run_dir: Path, resume: bool, progress: bool, command: str, lock):
    from tqdm import tqdm

    from adarl import envs
    from adarl.envs.rollout import run_episodes
    from adarl.policy import NumpyPolicy
    from adarl.policy import to_bytes as policy_bytes

    config.validate()
    run_dir = Path(run_dir)
    envs.get_task(config.task)
    envs.parse_dynamics(config.dynamics, config.task)
    for spec in config.eval_dynamics:
        envs.parse_dynamics(spec, config.task)
    csv_names = (rf.EPISODES_CSV, rf.TRAIN_CSV, rf.EVAL_CSV)
    if resume:
        opened = rf.open_to_resume(run_dir, lock, config)
        if opened is None:  # complete
            return
        ckpt_path, ckpt_arrays, meta = opened
        resume = meta is not None  # killed before its first checkpoint: start again
        if not resume:
            for name in csv_names:
                io.CsvLog.truncate(run_dir / name, 0)
    else:
        rf.start_new(run_dir, lock, config, "rnac", command)

    # --- environments, one per seed, and the double-sampling simulators
    seeds = [int(s) for s in config.seeds]
    n_seeds, t_roll = len(seeds), config.rollout_steps
    options = config.env_options()
    env_list = [envs.make(config.task, config.dynamics, s, **options) for s in seeds]
    low = np.asarray(env_list[0].action_space.low, np.float64)
    high = np.asarray(env_list[0].action_space.high, np.float64)
    act_dtype = env_list[0].action_space.dtype
    obs_dim, act_dim = env_list[0].observation_space.shape[0], low.shape[0]
    shadows = [ShadowSimulator(e) for e in env_list] if config.uncertainty_set == "ds" else []
    rngs = [np.random.default_rng([s, 0x52AC]) for s in seeds]  # action noise and ds draws

    # --- JAX state: parameters and optimisers, and a key stream for the updates, per seed
    state, update_keys = init_states(seeds, config, obs_dim, act_dim)
    update = make_update(config, low, high)
    host = Host.zeros(n_seeds, obs_dim, act_dim, t_roll)
    best = BestPolicies(seeds)

    if resume:
        state = io.unflatten_tree(state, ckpt_arrays, "state")
        update_keys = ckpt_arrays["update_keys"]
        for f in dataclasses.fields(Host):
            if ckpt_arrays[f"host/{f.name}"].shape != getattr(host, f.name).shape:
                raise UsageError(f"checkpoint array host/{f.name} does not match this config")
            setattr(host, f.name, ckpt_arrays[f"host/{f.name}"].copy())
        step = int(meta["step"])
        for rng, s in zip(rngs, rf.rng_states(meta)):
            rng.bit_generator.state = s
        for env, s, enc in zip(env_list, seeds, meta["env_states"]):
            env.reset(seed=s)
            env.set_state(rf.decode_env_state(enc, ckpt_arrays))
        offsets = rf.csv_offsets(meta)
        for name in csv_names:
            io.CsvLog.truncate(run_dir / name, offsets[name])
        best.restore(meta, ckpt_path)
        param_names = list(env_list[0].dynamics_params)
    else:
        step = 0
        for i, (env, s) in enumerate(zip(env_list, seeds)):
            obs, info = env.reset(seed=s)
            host.obs_norm[i] = _observe(host, i, obs, config)
        param_names = list(info["dynamics"])
    if step >= config.total_steps:
        for env in env_list:
            env.close()
        rf.finish(run_dir, step)
        return
    params = host_params(state)  # NumPy (actor, critic) per seed for the rollout

    logs = {
        rf.EPISODES_CSV: io.CsvLog(run_dir / rf.EPISODES_CSV, rf.episode_columns(param_names)),
        rf.TRAIN_CSV: io.CsvLog(run_dir / rf.TRAIN_CSV, TRAIN_COLUMNS),
        rf.EVAL_CSV: io.CsvLog(run_dir / rf.EVAL_CSV, rf.EVAL_COLUMNS),
    }
    tb = io.Scalars(run_dir / "tb", purge_step=step if (run_dir / "tb").exists() else None)
    bar = tqdm(
        total=config.total_steps,
        initial=step,
        unit="step",
        dynamic_ncols=True,
        disable=None if progress else True,
        desc=f"rnac-{config.uncertainty_set} {config.task}",
    )
    recent_return = np.full(n_seeds, np.nan)
    last_log = (step, time.perf_counter())
    ds = config.uncertainty_set == "ds"
    weight_reg = np.float32(0.0 if ds else config.weight_reg)  # the original: 0 for ds
    low32, high32 = low.astype(np.float32), high.astype(np.float32)

    def seed_policy(i: int) -> dict:
        actor = params[i][0]
        if config.obs_norm:
            return policy_arrays(
                actor, host.obs_mean[i], host.obs_var(i), config.obs_clip, low, high
            )
        return policy_arrays(actor, None, None, config.obs_clip, low, high)

    def evaluate():
        for i, s in enumerate(seeds):
            policy = NumpyPolicy(seed_policy(i))
            for spec in config.eval_dynamics:
                rows = run_episodes(
                    policy, config.task, spec, config.eval_episodes, 1_000_000 + s, **options
                )
                logs[rf.EVAL_CSV].write(rf.eval_rows(step, s, spec, rows))
                mean_return = float(np.mean([r["return"] for r in rows]))
                tb.write(step, {rf.tb_eval_return(spec, s): mean_return})
                if spec == "nominal":
                    best.offer(s, step, mean_return, policy.arrays)

    def checkpoint():
        arrays = io.flatten_tree(state, "state")
        arrays["update_keys"] = np.asarray(update_keys)
        arrays.update({f"host/{f.name}": getattr(host, f.name) for f in dataclasses.fields(Host)})
        meta = rf.checkpoint_meta(
            "rnac",
            config,
            seeds,
            rngs,
            rf.encode_env_states(env_list, arrays),
            {name: logs[name].offset() for name in csv_names},
        )
        meta["best"] = best.meta()
        policies = {
            f"policy_seed_{s}.npz": policy_bytes(seed_policy(i)) for i, s in enumerate(seeds)
        }
        policies.update(best.checkpoint_files())
        rf.save_checkpoint(
            run_dir, step, arrays, meta, keep=config.keep_checkpoints, files=policies
        )

    watch = io.DivergenceWatch(run_dir, config.on_divergence)

    def check_divergence():
        """Non-finite update metrics (once there was an update), parameters, optimiser states
        or returns."""
        if step >= t_roll:
            for j, name in enumerate(METRICS):
                watch.note_values(name, seeds, host.metrics[:, j])
        for m, net in enumerate(("actor", "critic")):
            flat = [np.concatenate([np.ravel(x) for x in jax.tree.leaves(p[m])]) for p in params]
            watch.note_values(f"{net} parameters", seeds, flat)
        for net, opt in (("actor", state.actor_opt), ("critic", state.critic_opt)):  # Adam's
            leaves = [np.reshape(x, (n_seeds, -1)) for x in jax.tree.leaves(jax.device_get(opt))]
            watch.note_values(f"{net} optimiser state", seeds, np.concatenate(leaves, axis=1))
        watch.note_values("episode return", seeds, host.ep_return)
        watch.check(step)

    try:
        while step < config.total_steps:
            k = step % t_roll
            step += 1
            for i, (env, rng) in enumerate(zip(env_list, rngs)):
                # --- act (NumPy copy of this rollout's parameters)
                actor, critic = params[i]
                action, logp = sample_action(actor, host.obs_norm[i], rng, low32, high32)
                # --- the noise of the transition that happens: a random or (ds) the worst candidate
                if ds:
                    noises, worst, ridx = draw_double_sampling(
                        rng, config.n_candidates, act_dim, config.action_noise, config.delta
                    )
                    values = None
                    if worst or config.eager_candidates:  # only then are they simulated
                        a_cand = clip(action + noises, low, high).astype(act_dtype)
                        cand = _peek(host, i, shadows[i].candidates(a_cand), config)
                        values = critic_value(critic, cand, np)
                    noise = noises[select_candidate(values, worst, ridx)]
                else:
                    noise = rng.uniform(-config.action_noise, config.action_noise, act_dim)
                # --- step, store the transition, reset a finished episode
                executed = clip(action + noise, low, high).astype(act_dtype)
                obs, reward, terminated, truncated, info = env.step(executed)
                host.ep_return[i] += reward
                host.ep_length[i] += 1
                next_norm = _observe(host, i, obs, config)
                host.buf_obs[i, k], host.buf_next_obs[i, k] = host.obs_norm[i], next_norm
                host.buf_actions[i, k], host.buf_logp[i, k] = action, logp
                host.buf_rewards[i, k] = _scale_reward(host, i, float(reward), config)
                host.buf_terminated[i, k], host.buf_done[i, k] = terminated, terminated or truncated
                host.obs_norm[i] = next_norm
                if terminated or truncated:
                    row = {
                        "step": step,
                        "seed": seeds[i],
                        "episode": info["episode_index"],
                        "return": host.ep_return[i],
                        "length": host.ep_length[i],
                    }
                    row.update({f"p_{p}": info["dynamics"][p] for p in param_names})
                    logs[rf.EPISODES_CSV].write(row)
                    tb.write(step, {rf.tb_episode_return(seeds[i]): host.ep_return[i]})
                    recent_return[i] = host.ep_return[i]
                    if not math.isfinite(host.ep_return[i]):
                        watch.note("episode return", [seeds[i]])
                    host.ep_return[i], host.ep_length[i], host.ret_acc[i] = 0.0, 0, 0.0
                    obs, info = env.reset()
                    host.obs_norm[i] = _observe(host, i, obs, config)
            # --- update every seed on its full rollout, vmapped; lr decays linearly from the
            # previous update's step, as in the original
            if step % t_roll == 0:
                lr = (
                    config.lr * (1.0 - (step - t_roll) / config.total_steps)
                    if config.lr_decay
                    else config.lr
                )
                batch = {
                    "obs": host.buf_obs,
                    "actions": host.buf_actions,
                    "logp": host.buf_logp,
                    "rewards": host.buf_rewards,
                    "next_obs": host.buf_next_obs,
                    "terminated": host.buf_terminated,
                    "done": host.buf_done,
                }
                state, metrics, update_keys = update(
                    state, batch, update_keys, np.float32(lr), weight_reg
                )
                host.metrics = np.asarray(metrics)
                params = host_params(state)
            if step % config.log_every == 0:
                now = time.perf_counter()
                sps = (step - last_log[0]) / max(now - last_log[1], 1e-9)
                last_log = (step, now)
                for i, s in enumerate(seeds):
                    scalars = dict(zip(METRICS, host.metrics[i].tolist()))
                    logs[rf.TRAIN_CSV].write(
                        {"step": step, "seed": s, "steps_per_s": sps, **scalars}
                    )
                    tb.write(
                        step,
                        {rf.tb_train(n, s): v for n, v in scalars.items() if not math.isnan(v)}
                        | {rf.tb_train("steps_per_s", s): sps},
                    )
                check_divergence()
            if config.eval_episodes and step % config.eval_every == 0:
                evaluate()
            if step % config.checkpoint_every == 0 or step == config.total_steps:
                check_divergence()  # never checkpoint non-finite parameters
                checkpoint()
            if step % 256 == 0 or step == config.total_steps:
                bar.update(step - bar.n)
                if not np.isnan(recent_return).all():
                    bar.set_postfix(ret=f"{np.nanmean(recent_return):.0f}", refresh=False)
        rf.finish(run_dir, step)
    finally:
        bar.close()
        tb.close()
        for log in logs.values():
            log.close()
        for env in env_list:
            env.close()
