"""RNAC: robust natural actor-critic (Zhou et al., NeurIPS 2023) in JAX.

Follows the public PPO-based trainer (github.com/tliu1997/RNAC, `train_rnac.py`,
`ppo_continuous.py`, `normalization.py`) with its two uncertainty sets:

* ``ds`` (double sampling): at each step the current MuJoCo state is copied into a second
  simulator that shares the current episode's compiled model, `n_candidates` candidate next
  states are drawn with uniform action noise in ±`action_noise`, the critic values them, and with
  probability δ the lowest-valued candidate is the transition that happens, otherwise a uniformly
  random one. The real environment then replays the chosen noise (MuJoCo is deterministic, so it
  lands exactly on the chosen candidate).
* ``ipm`` (integral probability metric): every TD residual subtracts `weight_reg`·‖θ_V‖₂, the
  norm of all critic weights and all biases but the last.

Its networks, GAE, PPO's clipped objective, normalisers and host state are the on-policy
parts every such algorithm shares (`adarl.algos.onpolicy`). Reads top to bottom: RNAC's maths
as pure functions (IPM norm, worst-case selection); the jitted update (epochs × minibatches in
`lax.scan`, vmapped over seeds). The config and presets are `adarl.algos.rnac_config`; its
learner (the double-sampling simulator) is `adarl.train.rnac_learner`, trained by the one loop
`adarl.train.loop` (logs, evaluation, checkpoints).
Deviations from the original are listed in docs/rnac.md.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from adarl.algos.onpolicy import (
    actor_mean,
    critic_value,
    gae,
    init_actor,
    init_critic,
    ppo_clip_objective,
)
from adarl.algos.rnac_config import RNACConfig
from adarl.nets.gaussian import gaussian_entropy, gaussian_log_prob
from adarl.nets.mlp import make_layout, n_params

TRAIN_COLUMNS = [
    "step",
    "seed",
    "steps_per_s",
    "loss_pi",
    "loss_v",
    "entropy",
    "lr",
    "approx_kl",
    "clip_frac",
]
METRICS = TRAIN_COLUMNS[3:]  # what an update reports, in this order


# ============================================================================ the maths
def ipm_norm(critic: dict):
    """‖θ_V‖₂ of RNAC's IPM uncertainty set (`reg_norm` in the original's update): the
    Euclidean norm of all critic weights and of all biases except the output layer's."""
    squares = [jnp.sum(layer["w"] ** 2) + jnp.sum(layer["b"] ** 2) for layer in critic["trunk"]]
    return jnp.sqrt(sum(squares) + jnp.sum(critic["out"]["w"] ** 2))


def select_candidate(values: np.ndarray, worst: bool, random_index: int) -> int:
    """RNAC's double-sampling uncertainty set: the lowest-valued candidate argmin_k V(s'_k) when
    `worst` (drawn with probability δ), else the uniformly drawn `random_index`."""
    return int(np.argmin(values)) if worst else int(random_index)


def draw_double_sampling(
    rng: np.random.Generator, n: int, act_dim: int, noise: float, delta: float
) -> tuple[np.ndarray, bool, int]:
    """The random draws of one double-sampling step, always in this order (so a resumed run
    consumes the generator identically): the candidates' action noises U(−noise, noise), whether
    this step takes the worst candidate (probability δ), and the random candidate otherwise."""
    noises = rng.uniform(-noise, noise, size=(n, act_dim))
    worst = bool(rng.random() < delta)
    return noises, worst, int(rng.integers(n))


# ============================================================================ the update
class TrainState(NamedTuple):
    actor: dict
    critic: dict
    actor_opt: optax.OptState
    critic_opt: optax.OptState


def make_optimizer(config: RNACConfig) -> optax.GradientTransformation:
    """Gradient-norm clip then Adam(ε); the (decaying) learning rate is applied by the update."""
    return optax.chain(
        optax.clip_by_global_norm(config.max_grad_norm), optax.scale_by_adam(eps=config.adam_eps)
    )


def state_bytes(config: RNACConfig, obs_dim: int, act_dim: int) -> int:
    """Bytes of one seed's networks in `init_states` (float32): the actor (trunk, mean head,
    log-std) and the critic, each with Adam's two moments. Counted, not built."""
    actor = n_params(make_layout([obs_dim, *config.hidden, act_dim])) + act_dim
    critic = n_params(make_layout([obs_dim, *config.hidden, 1]))
    return 4 * 3 * (actor + critic)


def init_states(seeds: list[int], config: RNACConfig, obs_dim: int, act_dim: int):
    """Every seed's networks and optimiser states, stacked over seeds, and the raw (uint32)
    threefry keys of their updates; all drawn from NumPy generators seeded by the seed."""
    params, keys = [], []
    for seed in seeds:
        rng = np.random.default_rng([seed, 0x1717])
        actor = init_actor(rng, obs_dim, act_dim, tuple(config.hidden), config.init_log_std)
        params.append((actor, init_critic(rng, obs_dim, tuple(config.hidden))))
        keys.append(rng.integers(0, 2**32, size=2, dtype=np.uint32))
    actor, critic = jax.tree.map(lambda *x: np.stack(x), *params)
    key = (tuple(config.hidden), obs_dim, act_dim, len(seeds))
    if key not in _OPT_INITS:
        _OPT_INITS[key] = jax.jit(jax.vmap(make_optimizer(config).init))
    opt_init = _OPT_INITS[key]
    return TrainState(actor, critic, opt_init(actor), opt_init(critic)), np.stack(keys)


_OPT_INITS: dict = {}


# config fields the update depends on: equal values reuse the compiled update (tests, resumes)
UPDATE_FIELDS = (
    "hidden",
    "rollout_steps",
    "minibatch_size",
    "epochs",
    "clip_eps",
    "gamma",
    "gae_lambda",
    "adam_eps",
    "max_grad_norm",
    "ent_coef",
    "norm_adv",
)
_UPDATES: dict = {}


def make_update(config: RNACConfig, low: np.ndarray, high: np.ndarray):
    """Cached `_make_update`: one compiled update per distinct setting."""
    key = (
        *(getattr(config, f) for f in UPDATE_FIELDS),
        tuple(np.ravel(low)),
        tuple(np.ravel(high)),
    )
    if key not in _UPDATES:
        _UPDATES[key] = _make_update(config, low, high)
    return _UPDATES[key]


def _make_update(config: RNACConfig, low: np.ndarray, high: np.ndarray):
    """The PPO/RNAC update of one seed on one rollout, jitted and vmapped over seeds (the
    learner passes one seed at a time, so that a seed's numbers do not depend on the others):
    `update(states, batches, keys, lr, weight_reg) -> (states, metrics, keys)`; `weight_reg` is
    the IPM coefficient (0 for ds).

    A batch holds `obs, actions, logp, rewards, next_obs, terminated, done`, time-major. GAE runs
    once with the pre-update critic (IPM penalty included), advantages are normalised over the
    rollout, then `epochs` passes over shuffled minibatches update actor and critic, each with its
    own Adam and gradient clip, as in the original.
    """
    opt = make_optimizer(config)
    n, mb = config.rollout_steps, config.minibatch_size
    n_mb = n // mb
    low, high = jnp.asarray(low, jnp.float32), jnp.asarray(high, jnp.float32)

    def actor_loss(actor, obs, actions, logp_old, adv):
        mean = actor_mean(actor, obs, low, high)
        logp = gaussian_log_prob(actions, mean, actor["log_std"])
        entropy = jnp.broadcast_to(gaussian_entropy(actor["log_std"]), logp.shape)
        loss = jnp.mean(
            -ppo_clip_objective(logp, logp_old, adv, config.clip_eps) - config.ent_coef * entropy
        )
        log_ratio = logp - logp_old
        ratio = jnp.exp(log_ratio)
        aux = {
            "entropy": jnp.mean(entropy),
            "approx_kl": jnp.mean((ratio - 1.0) - log_ratio),
            "clip_frac": jnp.mean((jnp.abs(ratio - 1.0) > config.clip_eps).astype(jnp.float32)),
        }
        return loss, aux

    def critic_loss(critic, obs, targets):
        return jnp.mean((critic_value(critic, obs) - targets) ** 2)

    def apply(params, grads, opt_state, lr):
        updates, opt_state = opt.update(grads, opt_state, params)
        return jax.tree.map(lambda p, u: p - lr * u, params, updates), opt_state

    def update(state: TrainState, batch: dict, key, lr, weight_reg):
        key, key_epochs = jax.random.split(key)
        values = critic_value(state.critic, batch["obs"])
        next_values = critic_value(state.critic, batch["next_obs"])
        penalty = weight_reg * ipm_norm(state.critic)
        adv, targets = gae(
            batch["rewards"],
            values,
            next_values,
            batch["terminated"],
            batch["done"],
            config.gamma,
            config.gae_lambda,
            penalty,
        )
        if config.norm_adv:
            adv = (adv - adv.mean()) / (adv.std(ddof=1) + 1e-5)
        data = (batch["obs"], batch["actions"], batch["logp"], adv, targets)

        def minibatch(state: TrainState, idx):
            obs, actions, logp_old, a, t = (x[idx] for x in data)
            (loss_pi, aux), g_actor = jax.value_and_grad(actor_loss, has_aux=True)(
                state.actor, obs, actions, logp_old, a
            )
            loss_v, g_critic = jax.value_and_grad(critic_loss)(state.critic, obs, t)
            actor, actor_opt = apply(state.actor, g_actor, state.actor_opt, lr)
            critic, critic_opt = apply(state.critic, g_critic, state.critic_opt, lr)
            return TrainState(actor, critic, actor_opt, critic_opt), dict(
                aux, loss_pi=loss_pi, loss_v=loss_v
            )

        def epoch(state: TrainState, key):
            return jax.lax.scan(minibatch, state, jax.random.permutation(key, n).reshape(n_mb, mb))

        state, metrics = jax.lax.scan(epoch, state, jax.random.split(key_epochs, config.epochs))
        metrics = {k: jnp.mean(v) for k, v in metrics.items()}
        metrics["lr"] = jnp.asarray(lr, jnp.float32)
        return state, jnp.stack([metrics[k] for k in METRICS]), key

    return jax.jit(jax.vmap(update, in_axes=(0, 0, 0, None, None)))
