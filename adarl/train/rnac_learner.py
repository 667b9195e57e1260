"""RNAC's learner for the training loop (`adarl.train.loop`; the maths is `adarl.algos.rnac`):
every seed steps its own environment on the host with a NumPy copy of its policy, double
sampling (`ds`) values candidate next states in a second simulator, and every `rollout_steps`
each seed is updated by the jitted update, one call per seed, so that a seed's numbers never
depend on the seeds beside it. The host state (observation and reward normalisers, the rollout
being collected) is the on-policy `Host` of NumPy arrays (`adarl.algos.onpolicy`); checkpoints
hold it with the networks, the optimisers and the key states (the loop adds the generators and
the MuJoCo states), so a resumed run continues exactly (docs/run-format.md). Reads top to
bottom: the double-sampling simulator, the learner.
"""

from __future__ import annotations

import operator

import jax
import jax.numpy as jnp
import numpy as np

from adarl.algos import schedule
from adarl.algos.onpolicy import Host, clip, critic_value, host_params, sample_action
from adarl.algos.rnac import (
    METRICS,
    TRAIN_COLUMNS,
    draw_double_sampling,
    init_states,
    make_update,
    select_candidate,
    state_bytes,
)
from adarl.algos.rnac_config import RNACConfig
from adarl.envs.env import model_sizes
from adarl.runs import checkpoints, codec
from adarl.train.guards import check_training_memory, nonfinite_seeds
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
            envs.check_dynamics(spec, config.task, **self.env_options)
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
        self.host = Host.zeros(n, self.obs_dim, self.act_dim, config.rollout_steps, len(METRICS))
        self.params = host_params(
            self.state.actor, self.state.critic
        )  # NumPy (actor, critic) per seed for the rollout

    def fresh(self) -> None:
        for i, (env, s) in enumerate(zip(self.envs, self.seeds)):
            obs, _ = env.reset(seed=s)
            self.host.obs_norm[i] = self.host.observe(i, obs, self.config)

    def restore(self, arrays: dict, meta: dict) -> None:
        self.state = codec.unflatten_tree(self.state, arrays, "state")
        self.update_keys = arrays["update_keys"]
        self.host.load(arrays)
        for rng, s in zip(self.rngs, checkpoints.rng_states(meta)):
            rng.bit_generator.state = s
        for env, s, enc in zip(self.envs, self.seeds, meta["env_states"]):
            env.reset(seed=s)
            env.set_state(codec.decode_env_state(enc, arrays))
        self.params = host_params(self.state.actor, self.state.critic)

    def checkpoint_state(self) -> tuple[dict, dict]:
        arrays = codec.flatten_tree(self.state, "state")
        arrays["update_keys"] = np.asarray(self.update_keys)
        arrays.update(self.host.arrays())
        return arrays, checkpoints.host_meta(self.rngs, self.envs, arrays)

    def param_names(self) -> list[str]:
        return list(self.envs[0].dynamics_params or {})

    def close(self) -> None:
        for env in self.envs:
            env.close()

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
                    cand = host.peek(i, self.shadows[i].candidates(a_cand), config)
                    values = critic_value(critic, cand, np)
                noise = noises[select_candidate(values, worst, ridx)]
            else:
                noise = rng.uniform(-config.action_noise, config.action_noise, self.act_dim)
            # --- step, store the transition, reset a finished episode
            executed = clip(action + noise, self.low, self.high).astype(self.act_dtype)
            obs, reward, terminated, truncated, info = env.step(executed)
            host.record(i, k, action, logp, obs, reward, terminated, truncated, config)
            if terminated or truncated:
                episodes.append(
                    Episode(i, step, info, float(host.ep_return[i]), int(host.ep_length[i]))
                )
                host.end_episode(i)
                obs, info = env.reset()
                host.obs_norm[i] = host.observe(i, obs, config)
        if step % config.rollout_steps == 0:
            self.learn(step)
        return Advance(step, episodes, due(config, step))

    def learn(self, step: int) -> None:
        """Update every seed on its full rollout; the learning rate decays linearly from the
        previous update's step, as in the original. Each seed is its own call of the update (a
        batch of one): one call over all seeds batches their matmuls, which sum in another order,
        so a seed's numbers would change in the last bits with the seeds beside it."""
        lr, batch = np.float32(schedule.rnac_learning_rate(self.config, step)), self.host.batch()
        states, metrics, keys = [], [], []
        for i in range(len(self.seeds)):
            lane = slice(i, i + 1)
            state, m, key = self.update(
                jax.tree.map(operator.itemgetter(lane), self.state),
                {name: rows[lane] for name, rows in batch.items()},
                self.update_keys[lane],
                lr,
                self.weight_reg,
            )
            states.append(state)
            metrics.append(m)
            keys.append(key)
        self.state = jax.tree.map(lambda *x: jnp.concatenate(x), *states)
        self.update_keys = jnp.concatenate(keys)
        self.host.metrics = np.concatenate([np.asarray(m) for m in metrics])
        self.params = host_params(self.state.actor, self.state.critic)

    def parameters_finite(self) -> bool:
        leaves = jax.tree.leaves(self.params)
        return all(np.all(np.isfinite(x)) for x in leaves)

    def truncate(self, step: int) -> Truncation:
        raise NotImplementedError("RNAC keeps its networks' ranks: it never truncates")

    def train_rows(self, step: int, steps_per_s: float) -> list[dict]:
        """One train.csv row per seed: the latest update's metrics (NaN before the first)."""
        return [
            {"step": step, "seed": s, "steps_per_s": steps_per_s}
            | dict(zip(METRICS, self.host.metrics[i].tolist()))
            for i, s in enumerate(self.seeds)
        ]

    def policies(self) -> list[dict]:
        """Each seed's deterministic policy, with its observation normaliser."""
        return [
            self.host.policy(i, actor, self.config, self.low, self.high)
            for i, (actor, _) in enumerate(self.params)
        ]

    def nonfinite(self, step: int) -> dict[str, list[int]]:
        """Non-finite update metrics (once there was an update), parameters, optimiser states
        or returns, by quantity."""
        seeds, n_seeds = self.seeds, len(self.seeds)
        found = {}
        if step >= self.config.rollout_steps:
            for j, name in enumerate(METRICS):
                found[name] = nonfinite_seeds(seeds, self.host.metrics[:, j])
        for m, net in enumerate(("actor", "critic")):
            flat = [
                np.concatenate([np.ravel(x) for x in jax.tree.leaves(p[m])]) for p in self.params
            ]
            found[f"{net} parameters"] = nonfinite_seeds(seeds, flat)
        for net, opt in (("actor", self.state.actor_opt), ("critic", self.state.critic_opt)):
            leaves = [np.reshape(x, (n_seeds, -1)) for x in jax.tree.leaves(jax.device_get(opt))]
            found[f"{net} optimiser state"] = nonfinite_seeds(seeds, np.concatenate(leaves, axis=1))
        found["episode return"] = nonfinite_seeds(seeds, self.host.ep_return)
        return {quantity: s for quantity, s in found.items() if s}
