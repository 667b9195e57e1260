"""Soft actor-critic in JAX, with AdaRL's rank-adaptive bottlenecks and the SAC-family baselines.

Reads top to bottom: the networks, the losses, the jitted update (and the rank truncation), the
policy export. Acting and the lanes of seeds are `adarl.train.sac_learner`; the timeline (chunks,
truncation steps, the learning rate) `adarl.algos.schedule`; logging and checkpoints the one
loop, `adarl.train.loop`. Every algorithm of the SAC family is a configuration of this file
(`SACConfig` and `SAC_FAMILY` in `adarl.algos.sac_config`): `sac`, `adarl`, `adarl-control`,
`sac-fixed-rank`, `sac-parseval`, `sac-sparse`.

SAC follows Spinning Up (`spinup/algos/pytorch/sac`), which the AdaRL paper builds on:
squashed-Gaussian actor with log-std clamped to [−20, 2], twin Q-networks with a Polyak-averaged
target copy, the critic's target uses a fresh action from the current policy, the actor is
updated against the just-updated critics, and there are as many gradient steps as environment
steps (`update_every` steps, then `update_every` updates).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import optax

from adarl.algos import replay, schedule
from adarl.algos.sac_config import SACConfig
from adarl.nets import mlp, rank
from adarl.nets.gaussian import gaussian_log_prob
from adarl.nets.regularisers import parseval_penalty
from adarl.policy import LOG_STD_MAX, LOG_STD_MIN, file_arrays


# ============================================================================ networks
def actor_layout(config: SACConfig, obs_dim: int) -> tuple:
    """Trunk of the actor: obs -> hidden… with an activation after every layer."""
    if config.sparse_width:
        return mlp.make_layout([obs_dim, config.sparse_width], sparse_after=0)
    sizes = [obs_dim, *config.hidden]
    return mlp.make_layout(sizes, _bottleneck_indices(config, "actor"))


def critic_layout(config: SACConfig, obs_dim: int, act_dim: int) -> tuple:
    """One Q-network: (obs, act) -> hidden… -> 1."""
    if config.sparse_width:
        return mlp.make_layout([obs_dim + act_dim, config.sparse_width, 1], sparse_after=0)
    sizes = [obs_dim + act_dim, *config.hidden, 1]
    return mlp.make_layout(sizes, _bottleneck_indices(config, "critic"))


def _bottleneck_indices(config: SACConfig, net: str) -> tuple[int, ...]:
    return tuple(int(s.split(":")[1]) for s in config.bottleneck if s.split(":")[0] == net)


def bottleneck_names(config: SACConfig) -> list[str]:
    """Names of the bottlenecks, in the order `rank_state` reports them: actor_<i>, q1_<i>, q2_<i>."""
    names = [f"actor_{i}" for i in _bottleneck_indices(config, "actor")]
    for q in ("q1", "q2"):
        names += [f"{q}_{i}" for i in _bottleneck_indices(config, "critic")]
    return names


@dataclass(frozen=True)
class Spec:
    """Static facts the jitted functions close over."""

    actor: tuple
    critic: tuple
    obs_dim: int
    act_dim: int
    act_low: tuple
    act_high: tuple
    config: SACConfig


def make_spec(config: SACConfig, obs_dim: int, act_dim: int, low, high) -> Spec:
    return Spec(
        actor=actor_layout(config, obs_dim),
        critic=critic_layout(config, obs_dim, act_dim),
        obs_dim=obs_dim,
        act_dim=act_dim,
        act_low=tuple(float(x) for x in low),
        act_high=tuple(float(x) for x in high),
        config=config,
    )


def state_bytes(spec: Spec) -> int:
    """Bytes of one seed's networks in `init_state` (float32, buffer aside): the actor (trunk and
    two heads) with Adam's two moments, and the two critics with their target copies and Adam's
    moments. Counted from the layouts, without building anything."""
    width = spec.config.sparse_width or spec.config.hidden[-1]
    actor = mlp.n_params(spec.actor) + 2 * mlp.n_params((("dense", width, spec.act_dim),))
    critics = 2 * mlp.n_params(spec.critic)
    return 4 * (3 * actor + 4 * critics)


def init_state(spec: Spec, seed: int, with_buffer: bool = True) -> dict:
    """The complete training state of one seed (parameters, optimisers, buffer, keys, counters),
    as NumPy arrays: parameters are drawn with NumPy's PCG64 seeded by `seed`; the update's JAX
    key stream starts from `PRNGKey(seed)`. `with_buffer=False` leaves the (large) replay buffer
    out, for callers that allocate it on the device directly."""
    c = spec.config
    rng = np.random.default_rng(seed)
    width = c.sparse_width or c.hidden[-1]
    init_rank = c.rank or None
    head = (("dense", width, spec.act_dim),)
    actor = {
        "trunk": mlp.init_layers(rng, spec.actor, c.init, rank=init_rank, has_output_layer=False),
        # the heads are output layers: gain 1 under orthogonal init
        "mu": mlp.init_layers(rng, head, c.init)[0],
        "log_std": mlp.init_layers(rng, head, c.init)[0],
    }
    q1 = mlp.init_layers(rng, spec.critic, c.init, rank=init_rank)
    q2 = mlp.init_layers(rng, spec.critic, c.init, rank=init_rank)
    critic = jax.tree_util.tree_map(lambda a, b: np.stack([a, b]), q1, q2)
    actor_masks = mlp.rank_masks(spec.actor, init_rank)
    critic_masks = [
        None if m is None else np.stack([m, m]) for m in mlp.rank_masks(spec.critic, init_rank)
    ]
    state = {
        "actor": actor,
        "critic": critic,
        "critic_target": jax.tree_util.tree_map(np.copy, critic),
        "masks": {"actor": actor_masks, "critic": critic_masks},
        "log_alpha": np.log(np.float32(c.alpha)),
        "opt_actor": _adam_zeros(actor),
        "opt_critic": _adam_zeros(critic),
        "opt_alpha": _adam_zeros(np.zeros((), np.float32)),
        "key": update_key(seed),
        "n_updates": np.zeros((), np.int32),
        "iteration_start": np.zeros((), np.int32),  # update count at the last truncation
        "n_truncations": np.zeros((), np.int32),
    }
    if with_buffer:
        state["buffer"] = replay.init_buffer(c.buffer_size, spec.obs_dim, spec.act_dim)
    return state


def update_key(seed: int) -> np.ndarray:
    """Raw threefry key of the update stream: the same bits as `jax.random.PRNGKey(seed)`."""
    return np.array([0, seed], np.uint32)


def _adam_zeros(params):
    """A fresh Adam state, built in NumPy (equal to `_adam().init(params)`)."""
    zeros = jax.tree_util.tree_map(np.zeros_like, params)
    return optax.ScaleByAdamState(
        count=np.zeros((), np.int32), mu=zeros, nu=jax.tree_util.tree_map(np.copy, zeros)
    )


def _adam():
    # torch.optim.Adam defaults; the learning rate is applied by the update (it follows a schedule)
    return optax.scale_by_adam(b1=0.9, b2=0.999, eps=1e-8)


def actor_features(spec: Spec, actor: dict, masks: list, obs: jnp.ndarray):
    """The actor trunk's output (the sparse code for sac-sparse), read by both heads."""
    c = spec.config
    return mlp.apply_layers(
        actor["trunk"],
        masks,
        obs,
        spec.actor,
        c.activation,
        final_activation=True,
        sparse_eta=c.sparse_eta,
        sparse_lam=c.sparse_lambda,
    )


def actor_forward(spec: Spec, actor: dict, masks: list, obs: jnp.ndarray):
    """Mean and clamped log-std of the pre-squash Gaussian."""
    h = actor_features(spec, actor, masks, obs)
    mu = h @ actor["mu"]["w"] + actor["mu"]["b"]
    log_std = jnp.clip(h @ actor["log_std"]["w"] + actor["log_std"]["b"], LOG_STD_MIN, LOG_STD_MAX)
    return mu, log_std


def squash(spec: Spec, u: jnp.ndarray) -> jnp.ndarray:
    low, high = jnp.asarray(spec.act_low), jnp.asarray(spec.act_high)
    return (high + low) / 2 + (high - low) / 2 * jnp.tanh(u)


def sample_action(spec: Spec, actor, masks, obs, key):
    """Reparameterised squashed-Gaussian sample and its log-probability (Spinning Up):
    log π(a|s) = log N(u; μ, σ) − Σ 2(log 2 − u − softplus(−2u)), a = c + h·tanh(u)."""
    mu, log_std = actor_forward(spec, actor, masks, obs)
    std = jnp.exp(log_std)
    u = mu + std * jax.random.normal(key, mu.shape)
    logp = gaussian_log_prob(u, mu, log_std) - tanh_log_det(u)
    return squash(spec, u), logp


def tanh_log_det(u):
    """Σ_i log(1 − tanh²(u_i)) written stably as 2(log 2 − u − softplus(−2u))."""
    return jnp.sum(2.0 * (jnp.log(2.0) - u - jax.nn.softplus(-2.0 * u)), axis=-1)


def q_values(spec: Spec, critic, critic_masks, obs, act):
    """Both Q-networks at once (their parameters are stacked on axis 0): shape (2, batch)."""
    c = spec.config
    x = jnp.concatenate([obs, act], axis=-1)

    def one(params, masks):
        out = mlp.apply_layers(
            params,
            masks,
            x,
            spec.critic,
            c.activation,
            sparse_eta=c.sparse_eta,
            sparse_lam=c.sparse_lambda,
        )
        return out[..., 0]

    return jax.vmap(one)(critic, critic_masks)


# ============================================================================ losses
def critic_loss(spec: Spec, critic, state, batch, key):
    """Σ_j mean (Q_j(s,a) − y)², y = r + γ(1−d)(min_j Q̄_j(s',ã') − α log π(ã'|s')), ã' ~ π(·|s')."""
    c = spec.config
    alpha = jnp.exp(state["log_alpha"])
    next_act, next_logp = sample_action(
        spec, state["actor"], state["masks"]["actor"], batch["next_obs"], key
    )
    q_next = q_values(
        spec, state["critic_target"], state["masks"]["critic"], batch["next_obs"], next_act
    ).min(axis=0)
    target = batch["rew"] + c.gamma * (1.0 - batch["done"]) * (q_next - alpha * next_logp)
    target = jax.lax.stop_gradient(target)
    q = q_values(spec, critic, state["masks"]["critic"], batch["obs"], batch["act"])
    loss = jnp.sum(jnp.mean((q - target[None]) ** 2, axis=1))
    penalty = regulariser(spec, critic, stacked=True)
    return loss + penalty, {"loss_q": loss, "q_mean": q.mean(), "penalty_critic": penalty}


def actor_loss(spec: Spec, actor, state, batch, key):
    """mean(α log π(ã|s) − min_j Q_j(s, ã)), ã ~ π(·|s) reparameterised."""
    alpha = jnp.exp(state["log_alpha"])
    act, logp = sample_action(spec, actor, state["masks"]["actor"], batch["obs"], key)
    q = q_values(spec, state["critic"], state["masks"]["critic"], batch["obs"], act).min(axis=0)
    loss = jnp.mean(alpha * logp - q)
    penalty = regulariser(spec, actor["trunk"], stacked=False)
    return loss + penalty, {"loss_pi": loss, "logp": logp, "penalty_actor": penalty}


def alpha_loss(log_alpha, logp, target_entropy):
    """−mean(log α · (log π + H̄)) (SAC v2 temperature loss)."""
    return -jnp.mean(log_alpha * jax.lax.stop_gradient(logp + target_entropy))


def regulariser(spec: Spec, layers, stacked: bool):
    """Extra loss on a network's hidden weights; zero unless the config turns one on."""
    c = spec.config
    if c.parseval_coef <= 0:
        return jnp.zeros(())
    layout = spec.critic if stacked else spec.actor
    if stacked:  # one penalty per Q-network, summed
        return jnp.sum(jax.vmap(lambda p: parseval_penalty(p, layout, c, True))(layers))
    return parseval_penalty(layers, layout, c, False)  # the actor trunk: every layer is hidden


# ============================================================================ update
def learning_rate(spec: Spec, state, base_lr: float):
    """The learning rate of the current update, from the counters the state carries
    (`schedule.learning_rate`, the one schedule, computed here with `jax.numpy`)."""
    return schedule.learning_rate(spec.config, base_lr, state, jnp)


def update_step(spec: Spec, state: dict, _=None):
    """One SAC gradient step on a minibatch sampled from the device buffer."""
    c = spec.config
    key, k_batch, k_critic, k_actor = jax.random.split(state["key"], 4)
    batch = replay.sample(state["buffer"], k_batch, c.batch_size)
    lr_q = learning_rate(spec, state, c.lr_critic)
    lr_pi = learning_rate(spec, state, c.lr_actor)

    (_, q_info), q_grads = jax.value_and_grad(critic_loss, argnums=1, has_aux=True)(
        spec, state["critic"], state, batch, k_critic
    )
    q_step, opt_critic = _adam().update(q_grads, state["opt_critic"])
    critic = optax.apply_updates(
        state["critic"], jax.tree_util.tree_map(lambda u: -lr_q * u, q_step)
    )
    state = dict(state, critic=critic, opt_critic=opt_critic)

    (_, pi_info), pi_grads = jax.value_and_grad(actor_loss, argnums=1, has_aux=True)(
        spec, state["actor"], state, batch, k_actor
    )
    pi_step, opt_actor = _adam().update(pi_grads, state["opt_actor"])
    actor = optax.apply_updates(
        state["actor"], jax.tree_util.tree_map(lambda u: -lr_pi * u, pi_step)
    )

    logp = pi_info.pop("logp")
    log_alpha, opt_alpha = state["log_alpha"], state["opt_alpha"]
    if c.autotune_alpha:
        target_entropy = -spec.act_dim if c.target_entropy is None else c.target_entropy
        a_grad = jax.grad(alpha_loss)(log_alpha, logp, target_entropy)
        a_step, opt_alpha = _adam().update(a_grad, opt_alpha)
        log_alpha = log_alpha - c.lr_alpha * a_step

    target = jax.tree_util.tree_map(
        lambda t, o: c.polyak * t + (1.0 - c.polyak) * o, state["critic_target"], critic
    )
    state = dict(
        state,
        actor=actor,
        opt_actor=opt_actor,
        critic_target=target,
        log_alpha=log_alpha,
        opt_alpha=opt_alpha,
        key=key,
        n_updates=state["n_updates"] + 1,
    )
    info = {**q_info, **pi_info, "alpha": jnp.exp(log_alpha), "entropy": -logp.mean(), "lr": lr_pi}
    return state, info


def append_and_update(spec: Spec, state: dict, rows: dict, n_rows, n_updates: int):
    """Append a chunk of rows to the buffer, then run `n_updates` gradient steps (lax.scan).
    Returns the new state and the metrics averaged over the steps."""
    state = dict(state, buffer=replay.append_rows(state["buffer"], rows, n_rows))
    if n_updates == 0:
        return state, {}
    state, infos = jax.lax.scan(lambda s, x: update_step(spec, s, x), state, None, length=n_updates)
    return state, jax.tree_util.tree_map(jnp.mean, infos)


# ============================================================================ rank adaptation
def truncate(spec: Spec, state: dict):
    """AdaRL's rank-adaptation step on every bottleneck of actor and critics (one seed).

    For each bottleneck: the SVD of W1·W2 and the rank rule give a candidate rank
    r_c = max(1, min(r_old, r̂)); the retain clause (`rank.retain_or_cut`) accepts it when the
    network with only that bottleneck truncated to r_c changes its output by at most
    `retain_tolerance` (relative error over `retain_samples` replay rows: the deterministic action
    for the actor, each Q-network's values for the critics), else keeps r_old. The bottleneck is
    then re-parameterised W1 = U_r√Σ_r, W2 = √Σ_r V_rᵀ at the chosen rank. The control
    (`apply_cuts` false) chooses r_old every time: the same SVD basis, resets and schedule as
    AdaRL, with the rule's proposal and the candidate's error still measured and reported, so
    the two arms differ only in the components removed.
    The target critics become a copy of the truncated critics (as Spinning Up builds its target:
    a deep copy), so target and online networks have the same shapes and ranks. Adam states are
    reset and the learning-rate schedule restarts; everything else (replay buffer, α, counters,
    the update's key stream) carries over (warm start).
    Returns the new state and, per bottleneck, (spectrum, proposed r̂, new rank, candidate rank,
    relative error of the candidate).
    """
    c = spec.config
    # the test sample has its own key, derived without advancing the update's stream
    sample = replay.sample(
        state["buffer"], jax.random.fold_in(state["key"], 0x7E7A1), c.retain_samples
    )
    obs, act = sample["obs"], sample["act"]
    report = {}

    actor, actor_masks = state["actor"], state["masks"]["actor"]

    def actor_with(i, layer, mask):  # the deterministic action with bottleneck i replaced
        trunk, masks = list(actor["trunk"]), list(actor_masks)
        trunk[i], masks[i] = layer, mask
        return squash(spec, actor_forward(spec, dict(actor, trunk=trunk), masks, obs)[0])

    reference = squash(spec, actor_forward(spec, actor, actor_masks, obs)[0])
    actor_trunk, new_actor_masks = list(actor["trunk"]), list(actor_masks)
    for i, layer in enumerate(spec.actor):
        if layer[0] == "bottleneck":
            actor_trunk[i], new_actor_masks[i], report[f"actor_{i}"] = _truncate_bottleneck(
                c, actor["trunk"][i], actor_masks[i], functools.partial(actor_with, i), reference
            )

    critic, critic_masks = state["critic"], state["masks"]["critic"]

    def critics_with(i, layer, mask):  # both Q-networks' values with bottleneck i replaced
        layers, masks = list(critic), list(critic_masks)
        layers[i], masks[i] = layer, mask
        return q_values(spec, layers, masks, obs, act)

    reference = q_values(spec, critic, critic_masks, obs, act)  # (2, samples)
    new_critic, new_critic_masks = list(critic), list(critic_masks)
    for i, layer in enumerate(spec.critic):
        if layer[0] == "bottleneck":
            # both Q-networks cut at layer i at once: each one's output depends on its own only
            new_critic[i], new_critic_masks[i], both = _truncate_bottleneck(
                c, critic[i], critic_masks[i], functools.partial(critics_with, i), reference, 2
            )
            for q in range(2):
                report[f"q{q + 1}_{i}"] = tuple(x[q] for x in both)

    actor = dict(actor, trunk=actor_trunk)
    state = dict(
        state,
        actor=actor,
        critic=new_critic,
        critic_target=new_critic,
        masks={"actor": new_actor_masks, "critic": new_critic_masks},
        opt_actor=_adam().init(actor),
        opt_critic=_adam().init(new_critic),
        iteration_start=state["n_updates"],
        n_truncations=state["n_truncations"] + 1,
    )
    return state, report


def _truncate_bottleneck(c: SACConfig, p: dict, mask, output_with, reference, networks=0):
    """One bottleneck's cut (`truncate`), by `adarl.lowrank.cut_layer`: the SVD of W1·W2 (within
    `mask`), the rule's r̂, the candidate r_c = max(1, min(r_old, r̂)), the retain clause on the
    relative change of `output_with(layer, mask)` against `reference`, and W1 = U_r√Σ_r,
    W2 = √Σ_r V_rᵀ at the chosen rank. `networks` > 0: `p` and `mask` stack that many networks'
    bottlenecks (the critics), each cut on its own. Returns the new layer, its mask and
    (spectrum, r̂, new rank, r_c, error), per network when stacked."""
    each = jax.vmap if networks else (lambda f: f)

    def error_fn(w1, w2, m):
        return each(rank.relative_error)(output_with(dict(p, w1=w1, w2=w2), m), reference)

    w1, w2, m, record = rank.cut_layer(
        p["w1"],
        p["w2"],
        mask,
        rule=c.rank_rule,
        beta=c.beta,
        retain_tolerance=c.retain_tolerance,
        error_fn=error_fn,
        apply_cuts=c.apply_cuts,
        batched=bool(networks),
    )
    summary = (record.spectrum, record.proposed, record.applied, record.candidate, record.error)
    return dict(p, w1=w1, w2=w2), m, summary


def bottleneck_widths(spec: Spec) -> dict[str, int]:
    """Stored width of every bottleneck layer: {"actor:1": 64, "critic:1": 64}."""
    return {
        f"{net}:{i}": layer[2]
        for net, layout in (("actor", spec.actor), ("critic", spec.critic))
        for i, layer in enumerate(layout)
        if layer[0] == "bottleneck"
    }


def layers_of_width(key: str) -> list[str]:
    """The bottlenecks (`bottleneck_names`) stored at the width keyed `key` by
    `bottleneck_widths`: "actor:1" -> [actor_1], "critic:1" -> [q1_1, q2_1] (twin critics share
    their layout)."""
    net, _, i = key.partition(":")
    return [f"actor_{i}"] if net == "actor" else [f"q1_{i}", f"q2_{i}"]


def with_widths(spec: Spec, widths: dict[str, int]) -> Spec:
    """The same spec with the bottlenecks stored `widths` wide (keys as `bottleneck_widths`)."""

    def relayout(net, layout):
        return tuple(
            ("bottleneck", layer[1], int(widths[f"{net}:{i}"]), layer[3])
            if layer[0] == "bottleneck"
            else layer
            for i, layer in enumerate(layout)
        )

    return dataclasses.replace(
        spec, actor=relayout("actor", spec.actor), critic=relayout("critic", spec.critic)
    )


def resize_bottlenecks(spec: Spec, state: dict) -> dict:
    """Store every bottleneck of `state` (any leading seed axes) at the widths of `spec`: the
    factors W1[..., :w], W2[..., :w, :], their Adam moments and the rank masks are cut, or padded
    with zeros, to w. Exact both ways when no rank exceeds the new width (the components past
    the rank are zero)."""

    def fit(x, axis: int, w: int):
        axis %= x.ndim
        if x.shape[axis] >= w:
            return x[(slice(None),) * axis + (slice(0, w),)]
        pad = [(0, 0)] * x.ndim
        pad[axis] = (0, w - x.shape[axis])
        return jnp.pad(x, pad) if isinstance(x, jax.Array) else np.pad(x, pad)

    def cut(layers, layout):
        out = list(layers)
        for i, layer in enumerate(layout):
            if layer[0] == "bottleneck":
                w = layer[2]
                w1, w2 = fit(layers[i]["w1"], -1, w), fit(layers[i]["w2"], -2, w)
                out[i] = dict(layers[i], w1=w1, w2=w2)
        return out

    def cut_masks(masks, layout):
        return [m if m is None else fit(m, -1, layer[2]) for m, layer in zip(masks, layout)]

    def cut_actor(tree):
        return dict(tree, trunk=cut(tree["trunk"], spec.actor))

    def cut_adam(opt, cutter):
        return optax.ScaleByAdamState(count=opt.count, mu=cutter(opt.mu), nu=cutter(opt.nu))

    def cut_critic(tree):
        return cut(tree, spec.critic)

    return dict(
        state,
        actor=cut_actor(state["actor"]),
        critic=cut_critic(state["critic"]),
        critic_target=cut_critic(state["critic_target"]),
        opt_actor=cut_adam(state["opt_actor"], cut_actor),
        opt_critic=cut_adam(state["opt_critic"], cut_critic),
        masks={
            "actor": cut_masks(state["masks"]["actor"], spec.actor),
            "critic": cut_masks(state["masks"]["critic"], spec.critic),
        },
    )


def rank_state(spec: Spec, state: dict) -> dict[str, jnp.ndarray]:
    """Current rank of every bottleneck, keyed like `bottleneck_names`."""
    out = {}
    for i, layer in enumerate(spec.actor):
        if layer[0] == "bottleneck":
            out[f"actor_{i}"] = state["masks"]["actor"][i].sum().astype(jnp.int32)
    for i, layer in enumerate(spec.critic):
        if layer[0] == "bottleneck":
            for q in range(2):
                out[f"q{q + 1}_{i}"] = state["masks"]["critic"][i][q].sum().astype(jnp.int32)
    return out


# ============================================================================ export
def export_policy(
    spec: Spec, actor: dict, masks: list, log_std: bool = False
) -> dict[str, np.ndarray]:
    """The deterministic policy of one seed in the `adarl.policy` file format; bottleneck
    factors are cut to their rank, so the file holds the compressed network. `log_std=True`
    adds the log-std head, which the trainer's host-side exploration (`NumpyPolicy.sample`)
    reads."""
    c = spec.config
    layers = []
    for i, (layer, p) in enumerate(zip(spec.actor, actor["trunk"])):
        p = {k: np.asarray(v) for k, v in p.items()}
        if layer[0] == "dense":
            layers.append(("dense", p["w"], p["b"]))
        elif layer[0] == "bottleneck":
            r = int(np.asarray(masks[i]).sum())
            layers.append(("bottleneck", p["w1"][:, :r], p["w2"][:r], p["b"]))
        else:
            layers.append(("sparse", p["d"], c.sparse_eta, c.sparse_lambda))
    head = actor["log_std"] if log_std else None
    return file_arrays(
        layers,
        (actor["mu"]["w"], actor["mu"]["b"]),
        spec.act_low,
        spec.act_high,
        c.activation,
        log_std=None if head is None else (head["w"], head["b"]),
        n_params_full=True,
    )
