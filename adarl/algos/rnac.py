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

Reads top to bottom: config and presets; networks; the maths as pure functions (GAE, clipped
objective, IPM norm, worst-case selection); the jitted update (epochs × minibatches in
`lax.scan`, vmapped over seeds); running normalisers; the double-sampling simulator; the policy
export; the training loop with logs, evaluation and checkpoints (docs/run-format.md). Deviations
from the original are listed in docs/rnac.md.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from adarl.envs.tasks import PHYSICS, VERSIONS
from adarl.errors import ON_DIVERGENCE, UsageError, check_choice, check_numbers

UNCERTAINTY_SETS = ("ds", "ipm")
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


# ============================================================================ config
@dataclass
class RNACConfig:
    """Every hyperparameter of an RNAC run. Defaults: the public RNAC code's settings."""

    # --- run
    task: str = "hopper"
    dynamics: str = "paper"
    physics: str = "consistent"  # consistent (recompile: masses follow geometry) or ompo
    model_version: str = "v5"  # Gymnasium's v5 or v4 (the port of the paper's Gym v3) models
    seeds: tuple[int, ...] = (0,)
    total_steps: int = 3_000_000  # environment steps per seed
    # --- uncertainty set
    uncertainty_set: str = "ds"  # ds (double sampling) or ipm
    # ds: P(take the worst-valued candidate). The original draws one of n+1 outcomes, outcome n
    # being "the worst", i.e. δ = 1/(n+1) = 1/3 for its 2 candidates.
    delta: float = 1.0 / 3.0
    n_candidates: int = 2
    # ds: simulate and value the candidates at every step, as the original does, instead of only
    # on the steps that take the worst case (same transitions, more simulator steps)
    eager_candidates: bool = False
    action_noise: float = 5e-3  # uniform ±noise on every executed action (both sets)
    weight_reg: float = 1e-5  # ipm: TD residual −= weight_reg·‖θ_V‖₂ (ds: 0, as the original)
    # --- PPO (the original's tricks 1-10)
    hidden: tuple[int, ...] = (64, 64)
    rollout_steps: int = 2048  # "batch_size" of the original: env steps per seed per update
    minibatch_size: int = 64
    epochs: int = 10
    clip_eps: float = 0.2
    gamma: float = 0.99
    gae_lambda: float = 0.95
    lr: float = 3e-4  # actor and critic
    lr_decay: bool = True  # linear to 0 at total_steps
    adam_eps: float = 1e-5
    max_grad_norm: float = 0.5
    ent_coef: float = 0.01
    init_log_std: float = 0.0
    norm_adv: bool = True
    obs_norm: bool = True
    obs_clip: float = 10.0  # normalised observations are clipped to ±obs_clip
    reward_scaling: bool = True
    # --- evaluation, logging, checkpoints (all in environment steps per seed)
    eval_every: int = 5000
    eval_episodes: int = 3
    eval_dynamics: tuple[str, ...] = ("nominal",)
    log_every: int = 2048
    checkpoint_every: int = 100_000
    keep_checkpoints: int = 2
    # a non-finite loss, parameter or return: stop (exit code 3) or continue (docs/reliability.md)
    on_divergence: str = "stop"

    def validate(self) -> RNACConfig:
        """Raise a one-line UsageError on any bad value; return self."""
        check_numbers(self)
        check_choice("uncertainty set", self.uncertainty_set, UNCERTAINTY_SETS)
        check_choice("physics", self.physics, PHYSICS)
        check_choice("model version", self.model_version, VERSIONS)
        check_choice("on-divergence", self.on_divergence, ON_DIVERGENCE)
        if not (0.0 <= self.delta <= 1.0):
            raise UsageError(f"delta must be in [0, 1], got {self.delta}")
        if self.n_candidates < 1:
            raise UsageError(f"n-candidates must be ≥ 1, got {self.n_candidates}")
        positive = [
            "total_steps",
            "rollout_steps",
            "minibatch_size",
            "epochs",
            "eval_every",
            "log_every",
            "checkpoint_every",
            "keep_checkpoints",
            "lr",
            "clip_eps",
            "adam_eps",
            "max_grad_norm",
            "obs_clip",
        ]
        for name in positive:
            if not getattr(self, name) > 0:
                raise UsageError(f"{name.replace('_', '-')} must be > 0, got {getattr(self, name)}")
        for name in ("eval_episodes", "action_noise", "weight_reg", "ent_coef"):
            if not getattr(self, name) >= 0:
                raise UsageError(f"{name.replace('_', '-')} must be ≥ 0, got {getattr(self, name)}")
        if self.rollout_steps % self.minibatch_size:
            raise UsageError(
                f"rollout-steps ({self.rollout_steps}) must be a multiple of minibatch-size "
                f"({self.minibatch_size})"
            )
        if self.rollout_steps < 2:
            raise UsageError(f"rollout-steps must be ≥ 2, got {self.rollout_steps}")
        if not 0.0 < self.gamma <= 1.0:
            raise UsageError(f"gamma must be in (0, 1], got {self.gamma}")
        if not 0.0 <= self.gae_lambda <= 1.0:
            raise UsageError(f"gae-lambda must be in [0, 1], got {self.gae_lambda}")
        if not self.seeds:
            raise UsageError("seeds is empty; give at least one seed, e.g. --seeds 0-4")
        if len(set(self.seeds)) != len(self.seeds) or min(self.seeds) < 0:
            raise UsageError(f"seeds must be distinct and ≥ 0, got {list(self.seeds)}")
        if not self.hidden or any(h < 1 for h in self.hidden):
            raise UsageError(f"hidden sizes must be ≥ 1, got {list(self.hidden)}")
        return self


CONFIG_CLASS = RNACConfig

PRESETS: dict[str, dict] = {
    # the (= the public RNAC code's) settings, double sampling
    "default": {},
    # the same with the IPM uncertainty set
    "ipm": {"uncertainty_set": "ipm"},
    # the AdaRL paper's environments as its OMPO code ran them (as sac's `paper-ompo`)
    "paper-ompo": {"dynamics": "ompo", "physics": "ompo", "model_version": "v4"},
    # tiny budgets for tests and smoke runs
    "smoke": {
        "total_steps": 2048,
        "rollout_steps": 256,
        "minibatch_size": 64,
        "epochs": 2,
        "eval_every": 1024,
        "eval_episodes": 1,
        "log_every": 256,
        "checkpoint_every": 1024,
    },
}


# ============================================================================ networks
# Parameters are plain pytrees; weights are stored (in, out) so a layer is x @ w + b.
# Initialisation runs in NumPy: XLA's QR takes tens of seconds to compile on our CPUs.
def orthogonal(rng: np.random.Generator, n_in: int, n_out: int, gain: float) -> np.ndarray:
    """Orthogonal matrix (Saxe et al. 2014) as torch.nn.init.orthogonal_: Q of the QR of a
    Gaussian matrix with signs fixed by diag(R), times `gain`; shape (n_in, n_out)."""
    a = rng.standard_normal((max(n_in, n_out), min(n_in, n_out)))
    q, r = np.linalg.qr(a)
    q = q * np.sign(np.diag(r))
    return (gain * (q if n_in >= n_out else q.T)).astype(np.float32)


def init_dense(rng: np.random.Generator, n_in: int, n_out: int, gain: float) -> dict:
    """Orthogonal weights with `gain`, zero bias (the original's trick 8)."""
    return {"w": orthogonal(rng, n_in, n_out, gain), "b": np.zeros(n_out, np.float32)}


def init_actor(rng, obs_dim: int, act_dim: int, hidden: tuple[int, ...], log_std: float) -> dict:
    """Gaussian actor: tanh trunk (gain 1), mean head (gain 0.01), state-independent log-std."""
    sizes = [obs_dim, *hidden]
    return {
        "trunk": [init_dense(rng, sizes[i], sizes[i + 1], 1.0) for i in range(len(hidden))],
        "mean": init_dense(rng, sizes[-1], act_dim, 0.01),
        "log_std": np.full(act_dim, log_std, np.float32),
    }


def init_critic(rng, obs_dim: int, hidden: tuple[int, ...]) -> dict:
    """State-value critic: tanh trunk and a linear output, all orthogonal with gain 1."""
    sizes = [obs_dim, *hidden]
    return {
        "trunk": [init_dense(rng, sizes[i], sizes[i + 1], 1.0) for i in range(len(hidden))],
        "out": init_dense(rng, sizes[-1], 1, 1.0),
    }


def _trunk(layers: list[dict], x, xp=jnp):
    for layer in layers:
        x = xp.tanh(x @ layer["w"] + layer["b"])
    return x


# The forward functions take `xp` (jax.numpy or numpy): the update runs them in JAX, the rollout
# in NumPy on a host copy of the parameters (they are constant during a rollout, and a NumPy
# forward of a 64-64 net costs ~10 µs where a jitted call costs ~200 µs on our CPUs).
def actor_mean(actor: dict, obs, low, high, xp=jnp):
    """Mean action c + h·tanh(z): the original's max_action·tanh(mean_layer(h)), for any bounds."""
    z = _trunk(actor["trunk"], obs, xp) @ actor["mean"]["w"] + actor["mean"]["b"]
    return (high + low) / 2 + (high - low) / 2 * xp.tanh(z)


def critic_value(critic: dict, obs, xp=jnp):
    """V(s), shape obs.shape[:-1]."""
    return (_trunk(critic["trunk"], obs, xp) @ critic["out"]["w"] + critic["out"]["b"])[..., 0]


def gaussian_log_prob(action, mean, log_std, xp=jnp):
    """log N(a; μ, diag σ²) summed over action dimensions."""
    z = (action - mean) * xp.exp(-log_std)
    return xp.sum(-0.5 * z**2 - log_std - 0.5 * math.log(2 * math.pi), axis=-1)


def gaussian_entropy(log_std):
    """Entropy of N(μ, diag σ²): Σ_i ½ + ½ log 2π + log σ_i."""
    return jnp.sum(0.5 + 0.5 * math.log(2 * math.pi) + log_std, axis=-1)


def sample_action(actor: dict, obs: np.ndarray, rng: np.random.Generator, low, high):
    """One rollout action (NumPy): a ~ N(μ(s), σ²) clipped to the bounds, and the log-probability
    of the clipped action, as the original (float32 throughout, like the networks)."""
    mean = actor_mean(actor, obs, low, high, np)
    eps = rng.standard_normal(mean.shape).astype(np.float32)
    a = clip(mean + np.exp(actor["log_std"]) * eps, low, high).astype(np.float32)
    return a, float(gaussian_log_prob(a, mean, actor["log_std"], np))


# ============================================================================ the maths
def gae(rewards, values, next_values, terminated, done, gamma: float, lam: float, penalty=0.0):
    """Generalised advantage estimation (Schulman et al. 2016, eq. 16) with the IPM residual.

    δ_t = r_t + γ(1 − term_t)·V(s'_t) − V(s_t) − penalty            (RNAC, IPM TD residual)
    A_t = δ_t + γλ(1 − done_t)·A_{t+1},   A after the last step = 0
    Returns (A, A + V(s)), the advantages and the critic's regression targets. `terminated` marks
    a true end (no bootstrap), `done` any episode end (terminated or truncated), as in the
    original's `dw` and `done`. All arguments are 1-D over time except the scalars.
    """
    deltas = rewards + gamma * (1.0 - terminated) * next_values - values - penalty

    def backward(carry, x):
        delta, d = x
        carry = delta + gamma * lam * (1.0 - d) * carry
        return carry, carry

    _, adv = jax.lax.scan(backward, jnp.zeros((), deltas.dtype), (deltas, done), reverse=True)
    return adv, adv + values


def ppo_clip_objective(logp_new, logp_old, adv, clip_eps: float):
    """PPO's clipped surrogate (Schulman et al. 2017, eq. 7), per sample, to be maximised:
    min(ρ·A, clip(ρ, 1 − ε, 1 + ε)·A) with ρ = exp(log π_new − log π_old)."""
    ratio = jnp.exp(logp_new - logp_old)
    return jnp.minimum(ratio * adv, jnp.clip(ratio, 1.0 - clip_eps, 1.0 + clip_eps) * adv)


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
    """The PPO/RNAC update of one seed on one rollout, jitted and vmapped over seeds:
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


def host_params(state: TrainState) -> list[tuple[dict, dict]]:
    """Per-seed NumPy copies of (actor, critic) for the rollout."""
    actor, critic = jax.device_get((state.actor, state.critic))
    n = len(actor["log_std"])
    return [jax.tree.map(lambda x, i=i: np.asarray(x[i]), (actor, critic)) for i in range(n)]


# ============================================================================ normalisers
def welford(count, mean, m2, x):
    """One step of Welford's running mean/variance (the original's RunningMeanStd);
    the variance is m2 / count."""
    count = count + 1
    delta = x - mean
    mean = mean + delta / count
    return count, mean, m2 + delta * (x - mean)


def normalise_obs(obs, mean, var, obs_clip: float) -> np.ndarray:
    """clip((o − m)/√(v + 1e-8), ±clip): the adarl policy-file formula, used in training too."""
    return clip((obs - mean) / np.sqrt(var + 1e-8), -obs_clip, obs_clip).astype(np.float32)


def clip(x, low, high):
    """np.clip without its dispatch overhead (a few µs per call, several calls per step)."""
    return np.minimum(np.maximum(x, low), high)


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


# ============================================================================ policy export
def policy_arrays(actor: dict, obs_mean, obs_var, obs_clip: float, low, high) -> dict:
    """One seed's deterministic policy in the adarl.policy format (tanh trunk, c + h·tanh mean)."""
    arrays = {
        "format": np.asarray("adarl-policy-1"),
        "activation": np.asarray("tanh"),
        "n_layers": np.asarray(len(actor["trunk"])),
        "squash": np.asarray("tanh"),
        "mean_w": np.asarray(actor["mean"]["w"]),
        "mean_b": np.asarray(actor["mean"]["b"]),
        "action_low": np.asarray(low, np.float32),
        "action_high": np.asarray(high, np.float32),
    }
    for i, layer in enumerate(actor["trunk"]):
        arrays.update(
            {
                f"l{i}_kind": np.asarray("dense"),
                f"l{i}_w": np.asarray(layer["w"]),
                f"l{i}_b": np.asarray(layer["b"]),
            }
        )
    if obs_mean is not None:
        arrays.update(
            {
                "obs_mean": np.asarray(obs_mean),
                "obs_var": np.asarray(obs_var),
                "obs_clip": np.asarray(obs_clip),
            }
        )
    return arrays


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


def _encode(obj, arrays: dict, key: str):
    """Make an env state JSON-able: arrays go to `arrays` (the checkpoint's npz) by key."""
    if isinstance(obj, np.ndarray):
        arrays[key] = obj
        return {"__array__": key}
    if isinstance(obj, dict):
        return {"__dict__": [[k, _encode(v, arrays, f"{key}/{k}")] for k, v in obj.items()]}
    if isinstance(obj, list | tuple):
        items = [_encode(v, arrays, f"{key}/{j}") for j, v in enumerate(obj)]
        return {"__tuple__": items} if isinstance(obj, tuple) else items
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _decode(obj, arrays: dict):
    if isinstance(obj, dict):
        if "__array__" in obj:
            return arrays[obj["__array__"]]
        if "__dict__" in obj:
            return {k: _decode(v, arrays) for k, v in obj["__dict__"]}
        if "__tuple__" in obj:
            return tuple(_decode(v, arrays) for v in obj["__tuple__"])
        return {k: _decode(v, arrays) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_decode(v, arrays) for v in obj]
    return obj


def _write_config(run_dir: Path, config: RNACConfig, command: str) -> None:
    import yaml

    from adarl import __version__
    from adarl.train.io import RUN_FORMAT_VERSION, atomic_write_text

    def plain(v):
        return [plain(x) for x in v] if isinstance(v, list | tuple) else v

    doc = {
        "algo": "rnac",
        **{k: plain(v) for k, v in dataclasses.asdict(config).items()},
        "format_version": RUN_FORMAT_VERSION,
        "adarl_version": __version__,
        "command": command or " ".join(sys.argv),
    }
    atomic_write_text(run_dir / "config.yaml", yaml.safe_dump(doc, sort_keys=False))


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
    from adarl.train import io

    with io.RunLock(run_dir) as lock:
        _train(config, Path(run_dir), resume, progress, command, lock)


def _train(config: RNACConfig, run_dir: Path, resume: bool, progress: bool, command: str, lock):
    from tqdm import tqdm

    from adarl import envs
    from adarl.evaluation.rollout import run_episodes
    from adarl.policy import NumpyPolicy
    from adarl.policy import to_bytes as policy_bytes
    from adarl.train import io

    config.validate()
    run_dir = Path(run_dir)
    envs.get_task(config.task)
    envs.parse_dynamics(config.dynamics, config.task)
    for spec in config.eval_dynamics:
        envs.parse_dynamics(spec, config.task)
    if resume:
        io.check_resume_dir(run_dir)
        lock.acquire(new=False)
        if (run_dir / "DONE").exists():
            print(f"run {run_dir} is already complete", file=sys.stderr)
            return
        loaded = io.load_latest_intact(run_dir)
        resume = loaded is not None  # killed before its first checkpoint: start again
        if loaded:
            ckpt_path, ckpt_arrays, meta = loaded
            io.check_resume_config(run_dir, meta, config)
        else:
            for name in ("episodes", "train", "eval"):
                io.CsvLog.truncate(run_dir / f"{name}.csv", 0)
    else:
        io.check_new_run_dir(run_dir)
        lock.acquire(new=True)
        _write_config(run_dir, config, command)
        io.write_environment(run_dir)

    # --- environments, one per seed, and the double-sampling simulators
    seeds = [int(s) for s in config.seeds]
    n_seeds, t_roll = len(seeds), config.rollout_steps
    options = envs.env_options(config)  # physics and model version
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

    csv_names = ("episodes", "train", "eval")
    if resume:
        state = io.unflatten_tree(state, ckpt_arrays, "state")
        update_keys = ckpt_arrays["update_keys"]
        for f in dataclasses.fields(Host):
            if ckpt_arrays[f"host/{f.name}"].shape != getattr(host, f.name).shape:
                raise UsageError(f"checkpoint array host/{f.name} does not match this config")
            setattr(host, f.name, ckpt_arrays[f"host/{f.name}"].copy())
        step = int(meta["step"])
        for rng, s in zip(rngs, meta["rng_states"]):
            rng.bit_generator.state = s
        for env, s, enc in zip(env_list, seeds, meta["env_states"]):
            env.reset(seed=s)
            env.set_state(_decode(enc, ckpt_arrays))
        for name in csv_names:
            io.CsvLog.truncate(run_dir / f"{name}.csv", meta["csv_offsets"][name])
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
        io.atomic_write_text(run_dir / "DONE", f"{step}\n")
        return
    params = host_params(state)  # NumPy (actor, critic) per seed for the rollout

    logs = {
        "episodes": io.CsvLog(
            run_dir / "episodes.csv",
            ["step", "seed", "episode", "return", "length", *(f"p_{p}" for p in param_names)],
        ),
        "train": io.CsvLog(run_dir / "train.csv", TRAIN_COLUMNS),
        "eval": io.CsvLog(
            run_dir / "eval.csv", ["step", "seed", "dynamics", "episode", "return", "length"]
        ),
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
                logs["eval"].write(
                    [
                        {
                            "step": step,
                            "seed": s,
                            "dynamics": spec,
                            "episode": r["episode"],
                            "return": r["return"],
                            "length": r["length"],
                        }
                        for r in rows
                    ]
                )
                mean_return = float(np.mean([r["return"] for r in rows]))
                tb.write(step, {f"seed_{s}/eval_return/{spec}": mean_return})
                if spec == "nominal":
                    best.offer(s, step, mean_return, policy.arrays)

    def checkpoint():
        arrays = io.flatten_tree(state, "state")
        arrays["update_keys"] = np.asarray(update_keys)
        arrays.update({f"host/{f.name}": getattr(host, f.name) for f in dataclasses.fields(Host)})
        env_states = [
            _encode(env.get_state(), arrays, f"env/{i}") for i, env in enumerate(env_list)
        ]
        meta = {
            "algo": "rnac",
            "config": io.config_record(config),
            "rng_states": [rng.bit_generator.state for rng in rngs],
            "env_states": env_states,
            "csv_offsets": {name: logs[name].offset() for name in csv_names},
            "best": best.meta(),
        }
        policies = {
            f"policy_seed_{s}.npz": policy_bytes(seed_policy(i)) for i, s in enumerate(seeds)
        }
        policies.update(best.checkpoint_files())
        io.save_checkpoint(
            run_dir, step, arrays, meta, keep=config.keep_checkpoints, files=policies
        )

    watch = io.DivergenceWatch(run_dir, config.on_divergence)

    def check_divergence():
        """Non-finite update metrics (once there was an update), parameters or returns."""
        if step >= t_roll:
            for j, name in enumerate(METRICS):
                watch.note_values(name, seeds, host.metrics[:, j])
        for m, net in enumerate(("actor", "critic")):
            flat = [np.concatenate([np.ravel(x) for x in jax.tree.leaves(p[m])]) for p in params]
            watch.note_values(f"{net} parameters", seeds, flat)
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
                    logs["episodes"].write(row)
                    tb.write(step, {f"seed_{seeds[i]}/episode_return": host.ep_return[i]})
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
                    logs["train"].write({"step": step, "seed": s, "steps_per_s": sps, **scalars})
                    tb.write(
                        step,
                        {f"seed_{s}/{n}": v for n, v in scalars.items() if not math.isnan(v)}
                        | {f"seed_{s}/steps_per_s": sps},
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
        io.atomic_write_text(run_dir / "DONE", f"{step}\n")
    finally:
        bar.close()
        tb.close()
        for log in logs.values():
            log.close()
        for env in env_list:
            env.close()
