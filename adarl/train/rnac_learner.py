"""RNAC's learner for the training loop (`adarl.train.loop`; the maths is `adarl.algos.rnac`):
every seed steps its own environment on the host with a NumPy copy of its policy, double
sampling (`ds`) values candidate next states in a second simulator, and every `rollout_steps`
all seeds are updated at once by the jitted, seed-vmapped update. The host state (observation
and reward normalisers, the rollout being collected) is a `Host` of NumPy arrays; checkpoints
hold it with the networks, the optimisers and the key states (the loop adds the generators and
the MuJoCo states), so a resumed run continues exactly (docs/run-format.md). Reads top to
bottom: the double-sampling simulator, the host state and its normalisers, the learner.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import numpy as np

from adarl.algos import schedule
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
    state_bytes,
    welford,
)
from adarl.algos.rnac_config import RNACConfig
from adarl.envs.env import model_sizes
from adarl.errors import UsageError
from adarl.runs import checkpoints, codec
from adarl.train.guards import check_training_memory
from adarl.train.learner import Advance, Episode, Truncation, due


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
            if old is None or model_sizes(old) != model_sizes(u.model):
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

    @staticmethod
    def rollout_bytes(obs_dim: int, act_dim: int, t: int) -> int:
        """Bytes of one seed's rollout in `zeros` (float32 `buf_*`: two observations, the action
        and four scalars per step)."""
        return 4 * t * (2 * obs_dim + act_dim + 4)

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


class RNACLearner:
    """Environments, double-sampling simulators, networks and host state of an RNAC run."""

    algo = "rnac"
    train_columns = TRAIN_COLUMNS
    extra_logs: dict = {}

    def __init__(self, config: RNACConfig):
        from adarl import envs

        self.config = config
        self.seeds = [int(s) for s in config.seeds]
        self.env_options = config.env_options()
        for spec in config.eval_dynamics:  # checked now, not at the first evaluation
            envs.parse_dynamics(spec, config.task)
        # the first seed's environment gives the sizes the memory check needs; the others
        # are made after it
        self.envs = [envs.make(config.task, config.dynamics, self.seeds[0], **self.env_options)]
        env = self.envs[0]
        self.low = np.asarray(env.action_space.low, np.float64)
        self.high = np.asarray(env.action_space.high, np.float64)
        self.low32, self.high32 = self.low.astype(np.float32), self.high.astype(np.float32)
        self.act_dtype = env.action_space.dtype
        self.obs_dim, self.act_dim = env.observation_space.shape[0], self.low.shape[0]
        n = len(self.seeds)
        check_training_memory(
            n,
            n * Host.rollout_bytes(self.obs_dim, self.act_dim, config.rollout_steps),
            n * state_bytes(config, self.obs_dim, self.act_dim),
            f"lower --hidden ({','.join(map(str, config.hidden))}) or --rollout-steps "
            f"({config.rollout_steps}), or train fewer seeds per run",
        )
        self.envs += [
            envs.make(config.task, config.dynamics, s, **self.env_options) for s in self.seeds[1:]
        ]
        self.ds = config.uncertainty_set == "ds"
        self.shadows = [ShadowSimulator(e) for e in self.envs] if self.ds else []
        self.weight_reg = np.float32(
            0.0 if self.ds else config.weight_reg
        )  # the original: 0 for ds
        self.rngs = [np.random.default_rng([s, 0x52AC]) for s in self.seeds]  # noise, ds draws
        # parameters and optimisers, and a key stream for the updates, per seed
        self.state, self.update_keys = init_states(self.seeds, config, self.obs_dim, self.act_dim)
        self.update = make_update(config, self.low, self.high)
        self.host = Host.zeros(len(self.seeds), self.obs_dim, self.act_dim, config.rollout_steps)
        self.params = host_params(self.state)  # NumPy (actor, critic) per seed for the rollout

    def fresh(self) -> None:
        for i, (env, s) in enumerate(zip(self.envs, self.seeds)):
            obs, _ = env.reset(seed=s)
            self.host.obs_norm[i] = _observe(self.host, i, obs, self.config)

    def restore(self, arrays: dict, meta: dict) -> None:
        self.state = codec.unflatten_tree(self.state, arrays, "state")
        self.update_keys = arrays["update_keys"]
        for f in dataclasses.fields(Host):
            if arrays[f"host/{f.name}"].shape != getattr(self.host, f.name).shape:
                raise UsageError(f"checkpoint array host/{f.name} does not match this config")
            setattr(self.host, f.name, arrays[f"host/{f.name}"].copy())
        for rng, s in zip(self.rngs, checkpoints.rng_states(meta)):
            rng.bit_generator.state = s
        for env, s, enc in zip(self.envs, self.seeds, meta["env_states"]):
            env.reset(seed=s)
            env.set_state(codec.decode_env_state(enc, arrays))
        self.params = host_params(self.state)

    def checkpoint_state(self) -> tuple[dict, dict]:
        arrays = codec.flatten_tree(self.state, "state")
        arrays["update_keys"] = np.asarray(self.update_keys)
        host = self.host
        arrays.update({f"host/{f.name}": getattr(host, f.name) for f in dataclasses.fields(Host)})
        return arrays, {}

    def advance(self, step: int) -> Advance:
        """One environment step of every seed, and at the end of a rollout the update of every
        seed on its rollout (vmapped)."""
        config, host = self.config, self.host
        k = step % config.rollout_steps
        step, episodes = step + 1, []
        for i, (env, rng) in enumerate(zip(self.envs, self.rngs)):
            # --- act (NumPy copy of this rollout's parameters)
            actor, critic = self.params[i]
            action, logp = sample_action(actor, host.obs_norm[i], rng, self.low32, self.high32)
            # --- the noise of the transition that happens: a random or (ds) the worst candidate
            if self.ds:
                noises, worst, ridx = draw_double_sampling(
                    rng, config.n_candidates, self.act_dim, config.action_noise, config.delta
                )
                values = None
                if worst or config.eager_candidates:  # only then are they simulated
                    a_cand = clip(action + noises, self.low, self.high).astype(self.act_dtype)
                    cand = _peek(host, i, self.shadows[i].candidates(a_cand), config)
                    values = critic_value(critic, cand, np)
                noise = noises[select_candidate(values, worst, ridx)]
            else:
                noise = rng.uniform(-config.action_noise, config.action_noise, self.act_dim)
            # --- step, store the transition, reset a finished episode
            executed = clip(action + noise, self.low, self.high).astype(self.act_dtype)
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
                episodes.append(
                    Episode(i, step, info, float(host.ep_return[i]), int(host.ep_length[i]))
                )
                host.ep_return[i], host.ep_length[i], host.ret_acc[i] = 0.0, 0, 0.0
                obs, info = env.reset()
                host.obs_norm[i] = _observe(host, i, obs, config)
        if step % config.rollout_steps == 0:
            self.learn(step)
        return Advance(step, episodes, due(config, step))

    def learn(self, step: int) -> None:
        """Update every seed on its full rollout, vmapped; the learning rate decays linearly
        from the previous update's step, as in the original."""
        config, host = self.config, self.host
        lr = schedule.rnac_learning_rate(config, step)
        batch = {
            "obs": host.buf_obs,
            "actions": host.buf_actions,
            "logp": host.buf_logp,
            "rewards": host.buf_rewards,
            "next_obs": host.buf_next_obs,
            "terminated": host.buf_terminated,
            "done": host.buf_done,
        }
        self.state, metrics, self.update_keys = self.update(
            self.state, batch, self.update_keys, np.float32(lr), self.weight_reg
        )
        host.metrics = np.asarray(metrics)
        self.params = host_params(self.state)

    def parameters_finite(self) -> bool:
        leaves = jax.tree.leaves(self.params)
        return all(np.all(np.isfinite(x)) for x in leaves)

    def truncate(self, step: int) -> Truncation:
        raise NotImplementedError("RNAC keeps its networks' ranks: it never truncates")

    def train_rows(self, step: int, steps_per_s: float, watch) -> list[dict]:
        """One train.csv row per seed: the latest update's metrics (NaN before the first)."""
        return [
            {"step": step, "seed": s, "steps_per_s": steps_per_s}
            | dict(zip(METRICS, self.host.metrics[i].tolist()))
            for i, s in enumerate(self.seeds)
        ]

    def policies(self) -> list[dict]:
        """Each seed's deterministic policy, with its observation normaliser."""
        host, c = self.host, self.config
        return [
            policy_arrays(
                actor,
                host.obs_mean[i] if c.obs_norm else None,
                host.obs_var(i) if c.obs_norm else None,
                c.obs_clip,
                self.low,
                self.high,
            )
            for i, (actor, _) in enumerate(self.params)
        ]

    def note_divergence(self, watch, step: int) -> None:
        """Non-finite update metrics (once there was an update), parameters, optimiser states
        or returns."""
        seeds, n_seeds = self.seeds, len(self.seeds)
        if step >= self.config.rollout_steps:
            for j, name in enumerate(METRICS):
                watch.note_values(name, seeds, self.host.metrics[:, j])
        for m, net in enumerate(("actor", "critic")):
            flat = [
                np.concatenate([np.ravel(x) for x in jax.tree.leaves(p[m])]) for p in self.params
            ]
            watch.note_values(f"{net} parameters", seeds, flat)
        for net, opt in (("actor", self.state.actor_opt), ("critic", self.state.critic_opt)):
            leaves = [np.reshape(x, (n_seeds, -1)) for x in jax.tree.leaves(jax.device_get(opt))]
            watch.note_values(f"{net} optimiser state", seeds, np.concatenate(leaves, axis=1))
        watch.note_values("episode return", seeds, self.host.ep_return)
