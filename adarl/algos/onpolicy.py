"""What every on-policy algorithm of adarl shares (RNAC's, and a PPO's): the tanh actor and
state-value critic, GAE and PPO's clipped surrogate, the running normalisers, the host state of
a learner collecting rollouts (`Host`), and the policy file with the normaliser folded in.

Follows the public PPO-based RNAC trainer (github.com/tliu1997/RNAC, `ppo_continuous.py`,
`normalization.py`), which is CleanRL's continuous PPO with its ten tricks. Reads top to bottom:
networks; the maths as pure functions; the normalisers; the host state; the policy file. An
algorithm adds its losses and jitted update (`adarl.algos.rnac`) and a learner that steps its
environments (`adarl.train.rnac_learner`; a new one: docs/algorithms.md).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from adarl.errors import UsageError
from adarl.nets.gaussian import gaussian_log_prob
from adarl.nets.mlp import orthogonal
from adarl.policy import file_arrays


# ============================================================================ networks
# Parameters are plain pytrees; weights are stored (in, out) so a layer is x @ w + b.
# Initialisation runs in NumPy: XLA's QR takes tens of seconds to compile on our CPUs.
def init_dense(rng: np.random.Generator, n_in: int, n_out: int, gain: float) -> dict:
    """Orthogonal weights with `gain`, zero bias (the original's trick 8)."""
    return {"w": orthogonal(rng, (n_in, n_out), gain), "b": np.zeros(n_out, np.float32)}


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


def sample_action(actor: dict, obs: np.ndarray, rng: np.random.Generator, low, high):
    """One rollout action (NumPy): a ~ N(μ(s), σ²) clipped to the bounds, and the log-probability
    of the clipped action, as the original (float32 throughout, like the networks)."""
    mean = actor_mean(actor, obs, low, high, np)
    eps = rng.standard_normal(mean.shape).astype(np.float32)
    a = clip(mean + np.exp(actor["log_std"]) * eps, low, high).astype(np.float32)
    return a, float(gaussian_log_prob(a, mean, actor["log_std"], np))


def host_params(actor: dict, critic: dict) -> list[tuple[dict, dict]]:
    """Per-seed NumPy copies of (actor, critic), stacked over seeds on the device, for the
    rollout."""
    actor, critic = jax.device_get((actor, critic))
    n = len(actor["log_std"])
    return [jax.tree.map(lambda x, i=i: np.asarray(x[i]), (actor, critic)) for i in range(n)]


# ============================================================================ the maths
def gae(rewards, values, next_values, terminated, done, gamma: float, lam: float, penalty=0.0):
    """Generalised advantage estimation (Schulman et al. 2016, eq. 16), with a penalty on every
    TD residual (RNAC's IPM set; 0 for PPO).

    δ_t = r_t + γ(1 − term_t)·V(s'_t) − V(s_t) − penalty
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


# ============================================================================ the host state
@dataclass
class Host:
    """Everything of an on-policy learner outside JAX that a checkpoint holds (as
    `host/<field>`), stacked over seeds (axis 0): the normalisers, the current episodes, the
    latest update's metrics and the rollout being collected. The normalising methods read the
    config's `obs_norm`, `obs_clip`, `reward_scaling` and `gamma`."""

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
    metrics: np.ndarray  # (S, M) of the latest update (NaN before the first)
    buf_obs: np.ndarray  # (S, T, D) the rollout so far
    buf_actions: np.ndarray
    buf_logp: np.ndarray
    buf_rewards: np.ndarray
    buf_next_obs: np.ndarray
    buf_terminated: np.ndarray
    buf_done: np.ndarray

    @classmethod
    def zeros(cls, n_seeds: int, obs_dim: int, act_dim: int, t: int, n_metrics: int) -> Host:
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
            metrics=np.full((n_seeds, n_metrics), np.nan, f32),
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

    def observe(self, i: int, obs: np.ndarray, config) -> np.ndarray:
        """Update seed i's state normaliser with a new observation and return it normalised."""
        if not config.obs_norm:
            return np.asarray(obs, np.float32)
        self.obs_count[i], self.obs_mean[i], self.obs_m2[i] = welford(
            self.obs_count[i], self.obs_mean[i], self.obs_m2[i], np.asarray(obs, np.float64)
        )
        return normalise_obs(obs, self.obs_mean[i], self.obs_var(i), config.obs_clip)

    def peek(self, i: int, obs: np.ndarray, config) -> np.ndarray:
        """Normalise without updating (RNAC's double-sampling candidates)."""
        if not config.obs_norm:
            return np.asarray(obs, np.float32)
        return normalise_obs(obs, self.obs_mean[i], self.obs_var(i), config.obs_clip)

    def scale_reward(self, i: int, r: float, config) -> float:
        """The original's RewardScaling: R ← γR + r, r / (std(R) + 1e-8); the first reward of
        the run (std undefined) is passed unscaled."""
        if not config.reward_scaling:
            return r
        self.ret_acc[i] = config.gamma * self.ret_acc[i] + r
        self.ret_count[i], self.ret_mean[i], self.ret_m2[i] = welford(
            self.ret_count[i], self.ret_mean[i], self.ret_m2[i], self.ret_acc[i]
        )
        if self.ret_count[i] < 2:
            return r
        return r / (math.sqrt(self.ret_m2[i] / self.ret_count[i]) + 1e-8)

    def record(self, i: int, k: int, action, logp, obs, reward, terminated, truncated, config):
        """Seed i's environment step k of the rollout (`obs`: the next observation, raw):
        normalise it, store the transition, scale the reward; returns the next observation
        normalised. The episode's return and length count the raw reward."""
        self.ep_return[i] += reward
        self.ep_length[i] += 1
        next_norm = self.observe(i, obs, config)
        self.buf_obs[i, k], self.buf_next_obs[i, k] = self.obs_norm[i], next_norm
        self.buf_actions[i, k], self.buf_logp[i, k] = action, logp
        self.buf_rewards[i, k] = self.scale_reward(i, float(reward), config)
        self.buf_terminated[i, k], self.buf_done[i, k] = terminated, terminated or truncated
        self.obs_norm[i] = next_norm
        return next_norm

    def end_episode(self, i: int) -> None:
        """Seed i's episode ended: its return, length and discounted return start again."""
        self.ep_return[i], self.ep_length[i], self.ret_acc[i] = 0.0, 0, 0.0

    def batch(self) -> dict[str, np.ndarray]:
        """The rollouts of all seeds as the update reads them, time-major per seed."""
        return {
            "obs": self.buf_obs,
            "actions": self.buf_actions,
            "logp": self.buf_logp,
            "rewards": self.buf_rewards,
            "next_obs": self.buf_next_obs,
            "terminated": self.buf_terminated,
            "done": self.buf_done,
        }

    def arrays(self) -> dict[str, np.ndarray]:
        """The checkpoint's arrays (`host/<field>`)."""
        return {f"host/{f.name}": getattr(self, f.name) for f in dataclasses.fields(self)}

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        """A checkpoint's `arrays` back (one-line UsageError if a shape does not match)."""
        for f in dataclasses.fields(self):
            if arrays[f"host/{f.name}"].shape != getattr(self, f.name).shape:
                raise UsageError(f"checkpoint array host/{f.name} does not match this config")
            setattr(self, f.name, arrays[f"host/{f.name}"].copy())

    def policy(self, i: int, actor: dict, config, low, high) -> dict[str, np.ndarray]:
        """Seed i's deterministic policy with its observation normaliser folded in."""
        norm = (self.obs_mean[i], self.obs_var(i), config.obs_clip) if config.obs_norm else None
        return policy_arrays(actor, low, high, norm)


# ============================================================================ the policy file
def policy_arrays(actor: dict, low, high, obs_norm: tuple | None = None) -> dict:
    """One seed's deterministic policy in the adarl.policy format (tanh trunk, c + h·tanh mean);
    `obs_norm`: (mean, var, clip) of the observation normaliser, or None."""
    layers = [("dense", layer["w"], layer["b"]) for layer in actor["trunk"]]
    mean = (actor["mean"]["w"], actor["mean"]["b"])
    return file_arrays(layers, mean, low, high, "tanh", obs_norm=obs_norm)
