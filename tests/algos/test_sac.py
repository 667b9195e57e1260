"""SAC losses, regularisers and the rank-adaptation step against NumPy references."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from bottleneck_step import truncate_bottleneck

from adarl.algos import replay, sac, sac_config, schedule
from adarl.algos.sac_config import SAC_FAMILY
from adarl.nets import mlp
from adarl.nets.regularisers import parseval_penalty

OBS, ACT = 5, 2


def make(algo="adarl", **overrides):
    config = sac_config.SACConfig(
        **{
            **SAC_FAMILY[algo],
            "algo": algo,
            "buffer_size": 512,
            "batch_size": 32,
            "update_every": 10,
            **overrides,
        }
    ).validate()
    spec = sac.make_spec(config, OBS, ACT, [-1.0, -2.0], [1.0, 2.0])
    return spec, jax.device_put(sac.init_state(spec, 0))


def np_mlp(layers, x, final_activation):
    """NumPy forward of dense/bottleneck layers with ReLU."""
    for i, p in enumerate(layers):
        w = p["w"] if "w" in p else np.asarray(p["w1"]) @ np.asarray(p["w2"])
        x = x @ np.asarray(w) + np.asarray(p["b"])
        if i < len(layers) - 1 or final_activation:
            x = np.maximum(x, 0)
    return x


def np_sample(actor, obs, noise, low, high):
    h = np_mlp(actor["trunk"], obs, True)
    mu = h @ np.asarray(actor["mu"]["w"]) + np.asarray(actor["mu"]["b"])
    log_std = np.clip(
        h @ np.asarray(actor["log_std"]["w"]) + np.asarray(actor["log_std"]["b"]), -20, 2
    )
    std = np.exp(log_std)
    u = mu + std * noise
    logp = np.sum(-0.5 * ((u - mu) / std) ** 2 - log_std - 0.5 * np.log(2 * np.pi), axis=-1)
    logp -= np.sum(np.log(1 - np.tanh(u) ** 2 + 1e-12), axis=-1)  # the textbook correction
    return (high + low) / 2 + (high - low) / 2 * np.tanh(u), logp


def np_q(critic, j, obs, act):
    layers = jax.tree_util.tree_map(lambda a: np.asarray(a)[j], critic)
    return np_mlp(layers, np.concatenate([obs, act], -1), False)[:, 0]


def random_batch(seed, n=32):
    rng = np.random.default_rng(seed)
    return {
        "obs": rng.normal(size=(n, OBS)).astype(np.float32),
        "act": rng.uniform(-1, 1, size=(n, ACT)).astype(np.float32),
        "rew": rng.normal(size=n).astype(np.float32),
        "next_obs": rng.normal(size=(n, OBS)).astype(np.float32),
        "done": (rng.uniform(size=n) < 0.2).astype(np.float32),
    }


def noise_of(key, n):
    """The Gaussian noise `sample_action` draws with `key`."""
    return np.asarray(jax.random.normal(key, (n, ACT)))


@pytest.mark.parametrize("algo", ["sac", "adarl"])
def test_critic_loss_matches_numpy(algo):
    spec, state = make(algo)
    batch = random_batch(1)
    key = jax.random.PRNGKey(5)
    loss, info = sac.critic_loss(spec, state["critic"], state, batch, key)
    low, high = np.array([-1.0, -2.0]), np.array([1.0, 2.0])
    a2, logp2 = np_sample(state["actor"], batch["next_obs"], noise_of(key, 32), low, high)
    q_targ = np.minimum(
        np_q(state["critic_target"], 0, batch["next_obs"], a2),
        np_q(state["critic_target"], 1, batch["next_obs"], a2),
    )
    y = batch["rew"] + 0.99 * (1 - batch["done"]) * (q_targ - 0.2 * logp2)
    expected = sum(
        np.mean((np_q(state["critic"], j, batch["obs"], batch["act"]) - y) ** 2) for j in range(2)
    )
    assert float(loss) == pytest.approx(expected, rel=1e-4)


def test_actor_and_alpha_losses_match_numpy():
    spec, state = make("sac")
    batch = random_batch(2)
    key = jax.random.PRNGKey(9)
    loss, info = sac.actor_loss(spec, state["actor"], state, batch, key)
    low, high = np.array([-1.0, -2.0]), np.array([1.0, 2.0])
    a, logp = np_sample(state["actor"], batch["obs"], noise_of(key, 32), low, high)
    q = np.minimum(
        np_q(state["critic"], 0, batch["obs"], a), np_q(state["critic"], 1, batch["obs"], a)
    )
    assert float(loss) == pytest.approx(np.mean(0.2 * logp - q), rel=1e-4)
    np.testing.assert_allclose(np.asarray(info["logp"]), logp, rtol=1e-4, atol=1e-4)
    log_alpha = np.log(0.3)
    expected = -np.mean(log_alpha * (logp + (-ACT)))
    assert float(sac.alpha_loss(jnp.asarray(log_alpha), jnp.asarray(logp), -ACT)) == pytest.approx(
        expected, rel=1e-5
    )


def test_tanh_correction_is_stable_and_exact():
    u = jnp.linspace(-30, 30, 101)[:, None]
    got = np.asarray(sac.tanh_log_det(u))
    assert np.all(np.isfinite(got))
    small = np.linspace(-3, 3, 7)[:, None]
    np.testing.assert_allclose(
        np.asarray(sac.tanh_log_det(jnp.asarray(small))),
        np.log(1 - np.tanh(small[:, 0]) ** 2),
        rtol=1e-5,
    )


def test_parseval_penalty_matches_numpy():
    spec, state = make("sac-parseval")
    layers = state["actor"]["trunk"]
    got = float(parseval_penalty(layers, spec.actor, spec.config, False))
    expected = 0.0
    for p in layers:  # both trunk layers are hidden layers of the actor (the heads are outputs)
        w = np.asarray(p["w"]).T  # out × in
        expected += (64 / w.shape[0]) ** 2 * np.sum((w @ w.T - 2 * np.eye(w.shape[0])) ** 2)
    assert got == pytest.approx(1e-4 * expected, rel=1e-4)
    critic = jax.tree_util.tree_map(lambda a: a[0], state["critic"])
    critic_penalty = float(parseval_penalty(critic, spec.critic, spec.config, True))
    w0 = np.asarray(critic[0]["w"]).T
    w1 = np.asarray(critic[1]["w"]).T
    expected = sum(np.sum((w @ w.T - 2 * np.eye(w.shape[0])) ** 2) for w in (w0, w1))
    assert critic_penalty == pytest.approx(1e-4 * expected, rel=1e-4)  # output layer excluded


def test_orthogonal_init_makes_hidden_layers_parseval_tight():
    spec, state = make("sac-parseval")
    w = np.asarray(state["actor"]["trunk"][1]["w"]).T  # 64×64 hidden layer
    np.testing.assert_allclose(w @ w.T, 2 * np.eye(64), atol=1e-4)


def test_sparse_layer_is_sparse_on_a_known_input():
    d = jnp.eye(4)
    x = jnp.array([[0.05, 0.5, -1.0, 2.0]])
    z = np.asarray(mlp.sparse_coding(x, d, 0.1, 0.1))
    # with D = I the step is ReLU(x − ηλ): entries below ηλ = 0.01 vanish
    np.testing.assert_allclose(z, [[0.04, 0.49, 0.0, 1.99]], atol=1e-6)
    spec, state = make("sac-sparse")
    obs = jnp.asarray(np.random.default_rng(0).normal(size=(64, OBS)), jnp.float32)
    trunk = state["actor"]["trunk"]
    h = mlp.apply_layers(trunk, state["masks"]["actor"], obs, spec.actor, final_activation=True)
    dense = jax.nn.relu(obs @ trunk[0]["w"] + trunk[0]["b"])
    assert h.shape == (64, 1024)
    # the shrinkage silences every unit the ReLU silenced and the weakest of the others
    assert 0.0 < float(jnp.mean(h > 0)) < float(jnp.mean(dense > 0))


def filled_state(spec, state, n=300):
    rng = np.random.default_rng(0)
    builder = replay.ChunkBuilder(1, n, OBS, ACT)
    for _ in range(n):
        builder.add(0, rng.normal(size=OBS), rng.uniform(-1, 1, ACT), rng.normal(), 0, None, False)
    builder.close(0, rng.normal(size=OBS))
    rows, count = builder.rows()
    rows = {k: jnp.asarray(v[0]) for k, v in rows.items()}
    return dict(state, buffer=replay.append_rows(state["buffer"], rows, count[0]))


@pytest.fixture(scope="module")
def adarl_run():
    """An AdaRL learner after 30 updates, with its jitted update (compiled once for the module)."""
    spec, state = make("adarl", beta=0.6)
    state = filled_state(spec, state)
    step = jax.jit(functools.partial(sac.update_step, spec))
    for _ in range(30):
        state, _ = step(state)
    return spec, step, state


def test_fixed_rank_starts_with_exactly_zero_components():
    spec, state = make("sac-fixed-rank", rank=7)
    for w1, w2 in [
        (state["actor"]["trunk"][1]["w1"], state["actor"]["trunk"][1]["w2"]),
        (state["critic"][1]["w1"][1], state["critic"][1]["w2"][1]),
    ]:
        assert np.all(np.asarray(w1)[:, 7:] == 0) and np.any(np.asarray(w1)[:, :7] != 0)
        assert np.all(np.asarray(w2)[7:] == 0)
    assert {k: int(v) for k, v in sac.rank_state(spec, state).items()} == {
        "actor_1": 7,
        "q1_1": 7,
        "q2_1": 7,
    }


def test_masked_components_get_zero_gradient_and_stay_zero(adarl_run):
    spec, step, state = adarl_run
    state, _ = sac.truncate(spec, state)
    ranks = {k: int(v) for k, v in sac.rank_state(spec, state).items()}
    r = ranks["actor_1"]
    batch = replay.sample(state["buffer"], jax.random.PRNGKey(1), 32)
    grads = jax.grad(lambda a: sac.actor_loss(spec, a, state, batch, jax.random.PRNGKey(2))[0])(
        state["actor"]
    )
    g = grads["trunk"][1]
    assert np.all(np.asarray(g["w1"])[:, r:] == 0) and np.all(np.asarray(g["w2"])[r:] == 0)
    assert np.any(np.asarray(g["w1"])[:, :r] != 0)
    for _ in range(20):
        state, _ = step(state)
    for name, net in [
        ("actor_1", state["actor"]["trunk"][1]),
        ("q2_1", {k: v[1] for k, v in state["critic"][1].items()}),
    ]:
        assert np.all(np.asarray(net["w1"])[:, ranks[name] :] == 0)
        assert np.all(np.asarray(net["w2"])[ranks[name] :] == 0)
    assert {k: int(v) for k, v in sac.rank_state(spec, state).items()} == ranks


def test_truncation_keeps_targets_in_step_and_resets_optimisers(adarl_run):
    spec, _, state = adarl_run
    new, report = sac.truncate(spec, state)
    ranks = sac.rank_state(spec, new)
    assert all(1 <= int(r) < 64 for r in ranks.values())
    assert set(report) == {"actor_1", "q1_1", "q2_1"}
    shapes = lambda t: jax.tree_util.tree_map(jnp.shape, t)  # noqa: E731
    assert shapes(new["critic_target"]) == shapes(new["critic"])
    for q in range(2):
        target = {k: np.asarray(v)[q] for k, v in new["critic_target"][1].items()}
        online = {k: np.asarray(v)[q] for k, v in new["critic"][1].items()}
        r = int(ranks[f"q{q + 1}_1"])
        assert np.linalg.matrix_rank(target["w1"] @ target["w2"], tol=1e-5) == r
        np.testing.assert_array_equal(target["w1"], online["w1"])
    zero = jax.tree_util.tree_map(lambda a: float(jnp.abs(a).sum()), new["opt_actor"].mu)
    assert sum(jax.tree_util.tree_leaves(zero)) == 0.0  # Adam moments reset
    assert int(new["iteration_start"]) == int(state["n_updates"])
    # learning rate restarts from zero and warms up
    assert float(sac.learning_rate(spec, new, 3e-3)) == 0.0
    assert float(sac.learning_rate(spec, state, 3e-3)) == pytest.approx(3e-3)
    # replay buffer and temperature carry over
    assert new["buffer"] is state["buffer"] or np.array_equal(
        new["buffer"]["obs"], state["buffer"]["obs"]
    )


def test_export_matches_the_jax_policy():
    from adarl.policy import NumpyPolicy

    spec, state = make("adarl", beta=0.7)
    state = filled_state(spec, state)
    state, _ = sac.truncate(spec, state)
    arrays = sac.export_policy(spec, state["actor"], state["masks"]["actor"])
    policy = NumpyPolicy(arrays)
    obs = np.random.default_rng(3).normal(size=(16, OBS)).astype(np.float32)
    mu, _ = sac.actor_forward(spec, state["actor"], state["masks"]["actor"], obs)
    expected = np.asarray(sac.squash(spec, mu))  # the deterministic action, tanh(μ) rescaled
    np.testing.assert_allclose(policy(obs), expected, rtol=1e-5, atol=1e-6)
    r = int(state["masks"]["actor"][1].sum())
    assert arrays["l1_w1"].shape == (64, r)
    assert policy.n_params() < int(arrays["n_params_full"])


@pytest.mark.parametrize("algo", ["sac", "adarl", "sac-sparse"])
def test_host_exploration_sample_matches_the_jax_sampler(algo):
    """The trainer samples exploration actions on the host (NumPy); with the same noise ε they
    equal `sac.sample_action`'s squashed Gaussian."""
    from adarl.policy import NumpyPolicy

    spec, state = make(algo, **({"beta": 0.7} if algo == "adarl" else {}))
    state = filled_state(spec, state)
    if algo == "adarl":
        state, _ = sac.truncate(spec, state)
    actor, masks = state["actor"], state["masks"]["actor"]
    policy = NumpyPolicy(sac.export_policy(spec, actor, masks, log_std=True))
    obs = np.random.default_rng(4).normal(size=(16, OBS)).astype(np.float32)
    key = jax.random.PRNGKey(7)
    expected, _ = sac.sample_action(spec, actor, masks, obs, key)
    noise = np.asarray(jax.random.normal(key, (16, ACT)))
    np.testing.assert_allclose(policy.sample(obs, noise), expected, rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="log-std"):
        NumpyPolicy(sac.export_policy(spec, actor, masks)).sample(obs, noise)


@pytest.mark.parametrize(
    "bad, message",
    [
        ({"beta": 1.0}, "beta"),
        ({"beta": 0.0}, "beta"),
        ({"truncate_every": 0}, "truncate-every"),
        ({"algo": "sac-fixed-rank", "rank": 65}, "rank"),
        ({"algo": "sac-fixed-rank", "rank": 0}, "rank"),
        ({"rank_rule": "median"}, "rank rule"),
        ({"bottleneck": ("actor:2",)}, "actor:2"),
        ({"algo": "nope"}, "algo"),
        ({"total_steps": -5}, "total-steps"),
        ({"algo": "sac-parseval", "parseval_coef": 0.0}, "parseval-coef"),
        ({"hidden": (64, 0)}, "hidden"),
    ],
)
def test_bad_config_is_a_one_line_error(bad, message):
    from adarl.errors import UsageError

    with pytest.raises(UsageError, match=message) as err:
        sac_config.SACConfig(**bad).validate()
    assert "\n" not in str(err.value)


def test_each_width_key_names_the_bottlenecks_stored_at_it(adarl_run):
    spec, _, _ = adarl_run
    assert sac.layers_of_width("actor:1") == ["actor_1"]
    assert sac.layers_of_width("critic:3") == ["q1_3", "q2_3"]
    names = [n for key in sac.bottleneck_widths(spec) for n in sac.layers_of_width(key)]
    assert sorted(names) == sorted(sac.bottleneck_names(spec.config))


def test_narrowing_bottlenecks_keeps_the_networks_function(adarl_run):
    spec, _, state = adarl_run
    state, _ = sac.truncate(spec, state)
    ranks = {k: int(v) for k, v in sac.rank_state(spec, state).items()}
    widths = {"actor:1": ranks["actor_1"], "critic:1": max(ranks["q1_1"], ranks["q2_1"])}
    narrow_spec = sac.with_widths(spec, widths)
    narrow = sac.resize_bottlenecks(narrow_spec, state)
    assert narrow["actor"]["trunk"][1]["w1"].shape == (64, widths["actor:1"])
    assert narrow["critic"][1]["w2"].shape == (2, widths["critic:1"], 64)
    assert narrow["opt_critic"].mu[1]["w1"].shape == (2, 64, widths["critic:1"])
    assert sac.bottleneck_widths(narrow_spec) == widths
    obs = jnp.asarray(np.random.default_rng(4).normal(size=(16, OBS)), jnp.float32)
    act = jnp.asarray(np.random.default_rng(5).uniform(-1, 1, size=(16, ACT)), jnp.float32)
    np.testing.assert_allclose(
        sac.actor_forward(narrow_spec, narrow["actor"], narrow["masks"]["actor"], obs)[0],
        sac.actor_forward(spec, state["actor"], state["masks"]["actor"], obs)[0],
        rtol=1e-5,
        atol=1e-5,
    )
    np.testing.assert_allclose(
        sac.q_values(narrow_spec, narrow["critic"], narrow["masks"]["critic"], obs, act),
        sac.q_values(spec, state["critic"], state["masks"]["critic"], obs, act),
        rtol=1e-5,
        atol=1e-5,
    )
    assert {k: int(v) for k, v in sac.rank_state(narrow_spec, narrow).items()} == ranks


def test_truncate_without_retain_test_is_the_rule_alone(adarl_run):
    """`retain_tolerance=None` (the paper's text as before the retain clause): every bottleneck
    gets exactly `truncate_bottleneck`'s factors, bit for bit."""
    spec, _, state = adarl_run
    new, report = sac.truncate(spec, state)
    c = spec.config
    p, m = state["actor"]["trunk"][1], state["masks"]["actor"][1]
    w1, w2, mask, s, proposed = truncate_bottleneck(p["w1"], p["w2"], m, c.beta, c.rank_rule)
    for got, want in ((new["actor"]["trunk"][1]["w1"], w1), (new["actor"]["trunk"][1]["w2"], w2)):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    np.testing.assert_array_equal(np.asarray(new["masks"]["actor"][1]), np.asarray(mask))
    q = state["critic"][1]
    trunc = jax.vmap(lambda a, b, k: truncate_bottleneck(a, b, k, c.beta, c.rank_rule))
    w1, w2, mask, _, _ = trunc(q["w1"], q["w2"], state["masks"]["critic"][1])
    np.testing.assert_array_equal(np.asarray(new["critic"][1]["w1"]), np.asarray(w1))
    np.testing.assert_array_equal(np.asarray(new["critic"][1]["w2"]), np.asarray(w2))
    assert int(report["actor_1"][2]) == int(report["actor_1"][3])  # new rank = candidate


def test_retain_error_is_the_relative_output_change_on_replay_rows(adarl_run):
    """The measured error, recomputed in NumPy: deterministic actions (actor) and each Q-network's
    values (critics) of the network with only that bottleneck truncated, against the current one,
    on the replay rows the truncation samples."""
    spec, _, state = adarl_run
    _, report = sac.truncate(spec, state)
    c = spec.config
    sample = replay.sample(
        state["buffer"], jax.random.fold_in(state["key"], 0x7E7A1), c.retain_samples
    )
    obs, act = np.asarray(sample["obs"]), np.asarray(sample["act"])
    low, high = np.array([-1.0, -2.0]), np.array([1.0, 2.0])

    def det_action(actor):
        h = np_mlp(actor["trunk"], obs, True)
        mu = h @ np.asarray(actor["mu"]["w"]) + np.asarray(actor["mu"]["b"])
        return (high + low) / 2 + (high - low) / 2 * np.tanh(mu)

    def masked(layers, masks):  # fold each bottleneck's mask into W1
        out = [dict(p) for p in layers]
        for i, m in enumerate(masks):
            if m is not None:
                out[i]["w1"] = np.asarray(out[i]["w1"]) * np.asarray(m)[..., None, :]
        return out

    actor = state["actor"]
    p, m = actor["trunk"][1], state["masks"]["actor"][1]
    w1, w2, mask, _, _ = truncate_bottleneck(p["w1"], p["w2"], m, c.beta, c.rank_rule)
    ref = det_action(dict(actor, trunk=masked(actor["trunk"], state["masks"]["actor"])))
    trial_trunk = list(actor["trunk"])
    trial_trunk[1] = dict(p, w1=w1, w2=w2)
    trial = det_action(dict(actor, trunk=masked(trial_trunk, [None, mask])))
    want = np.linalg.norm(trial - ref) / np.linalg.norm(ref)
    assert float(report["actor_1"][4]) == pytest.approx(want, rel=1e-3, abs=1e-6)
    assert want > 0

    critic = masked(list(state["critic"]), state["masks"]["critic"])
    q = state["critic"][1]
    trunc = jax.vmap(lambda a, b, k: truncate_bottleneck(a, b, k, c.beta, c.rank_rule))
    w1, w2, mask, _, _ = trunc(q["w1"], q["w2"], state["masks"]["critic"][1])
    trial_critic = list(state["critic"])
    trial_critic[1] = dict(q, w1=w1, w2=w2)
    trial_critic = masked(trial_critic, [None, mask, None])
    for j in range(2):
        ref_q, trial_q = np_q(critic, j, obs, act), np_q(trial_critic, j, obs, act)
        want = np.linalg.norm(trial_q - ref_q) / np.linalg.norm(ref_q)
        assert float(report[f"q{j + 1}_1"][4]) == pytest.approx(want, rel=1e-3, abs=1e-6)


def test_retain_clause_keeps_the_old_rank_when_a_cut_costs_too_much(adarl_run):
    spec, _, state = adarl_run
    old = {k: int(v) for k, v in sac.rank_state(spec, state).items()}
    strict = sac.with_widths(spec, sac.bottleneck_widths(spec))
    strict = dataclasses.replace(
        strict, config=dataclasses.replace(spec.config, retain_tolerance=1e-12)
    )
    new, report = sac.truncate(strict, state)
    assert {k: int(v) for k, v in sac.rank_state(strict, new).items()} == old
    for name, (_, _, new_rank, candidate, error) in report.items():
        assert int(candidate) < old[name] and int(new_rank) == old[name]
        assert float(error) > 1e-12
    # the retained bottleneck is re-parameterised at its old rank: the same function
    product = lambda p, m: (np.asarray(p["w1"]) * np.asarray(m)) @ np.asarray(p["w2"])  # noqa: E731
    np.testing.assert_allclose(
        product(new["actor"]["trunk"][1], new["masks"]["actor"][1]),
        product(state["actor"]["trunk"][1], state["masks"]["actor"][1]),
        atol=1e-4,
    )
    # a loose tolerance accepts every cut: the same ranks as without the test
    loose = dataclasses.replace(
        strict, config=dataclasses.replace(spec.config, retain_tolerance=1e9)
    )
    off, _ = sac.truncate(spec, state)
    accepted, _ = sac.truncate(loose, state)
    assert sac.rank_state(loose, accepted) == sac.rank_state(spec, off)


@pytest.mark.parametrize("lr_schedule", ["envelope", "restart"])
def test_learning_rate_follows_the_chosen_schedule(lr_schedule):
    spec, state = make(
        "adarl",
        lr_schedule=lr_schedule,
        total_steps=21_000,
        update_after=1_010,
        truncate_every=5_000,
    )
    c = spec.config
    assert schedule.total_updates(c) == 20_000 and schedule.n_truncations(c) == 4
    lr = lambda n, start, cuts: float(  # noqa: E731
        sac.learning_rate(
            spec,
            dict(state, n_updates=n, iteration_start=start, n_truncations=cuts),
            c.lr_actor,
        )
    )
    if lr_schedule == "envelope":
        assert lr(0, 0, 0) == pytest.approx(c.lr_actor)  # the envelope starts at the base rate
        assert lr(10_000, 0, 0) == pytest.approx(
            c.lr_actor * (c.lr_min_ratio + (1 - c.lr_min_ratio) / 2)
        )
        assert lr(10_000, 10_000, 2) == 0.0  # just after a truncation: warming up
        assert lr(20_000, 15_000, 3) == pytest.approx(c.lr_actor * c.lr_min_ratio)
    else:
        assert lr(10_000, 0, 0) == pytest.approx(c.lr_actor)  # constant before the first cut
        assert lr(10_000, 10_000, 2) == 0.0
        assert lr(15_000, 10_000, 2) == pytest.approx(c.lr_actor * c.lr_min_ratio)  # iteration end


# ----------------------------------------------------------------------------- one whole update
def _np_tree(tree):
    return jax.tree_util.tree_map(np.asarray, tree)


def _np_adam_first_step(params, grads, lr):
    """The first step of Adam (zero moments, β = (0.9, 0.999), ε = 1e-8), in NumPy: the bias
    corrections make m̂ = g and v̂ = g², so θ ← θ − lr·g / (|g| + ε)."""
    return jax.tree_util.tree_map(
        lambda p, g: np.asarray(p) - lr * np.asarray(g) / (np.abs(np.asarray(g)) + 1e-8),
        params,
        grads,
    )


def test_update_step_matches_numpy_with_a_distinct_target_critic():
    """One `update_step` against NumPy: the critic loss uses the *target* critic (perturbed
    here, so that it differs from the online one), the critic takes an Adam step, the actor's loss
    uses the just-updated critic (Spinning Up's order), and the target moves by Polyak averaging
    θ̄ ← ρθ̄ + (1 − ρ)θ towards the new critic."""
    spec, state = make("sac")
    state = filled_state(spec, state)
    rng = np.random.default_rng(3)
    state["critic_target"] = jax.tree_util.tree_map(
        lambda a: np.asarray(a) + 0.3 * rng.normal(size=np.shape(a)).astype(np.float32),
        _np_tree(state["critic"]),
    )
    new, info = jax.jit(functools.partial(sac.update_step, spec))(state)
    c = spec.config
    _, k_batch, k_critic, k_actor = jax.random.split(state["key"], 4)
    batch = _np_tree(replay.sample(state["buffer"], k_batch, c.batch_size))
    low, high = np.array([-1.0, -2.0]), np.array([1.0, 2.0])
    n = c.batch_size

    # the critic's loss: y from the target critic
    a2, logp2 = np_sample(state["actor"], batch["next_obs"], noise_of(k_critic, n), low, high)
    q_targ = np.minimum(*(np_q(state["critic_target"], j, batch["next_obs"], a2) for j in (0, 1)))
    y = batch["rew"] + c.gamma * (1 - batch["done"]) * (q_targ - c.alpha * logp2)
    q_loss = sum(
        np.mean((np_q(state["critic"], j, batch["obs"], batch["act"]) - y) ** 2) for j in (0, 1)
    )
    assert float(info["loss_q"]) == pytest.approx(q_loss, rel=1e-4)

    # the critic's Adam step
    q_grads = jax.grad(sac.critic_loss, argnums=1, has_aux=True)(
        spec, state["critic"], state, batch, k_critic
    )[0]
    expected_critic = _np_adam_first_step(state["critic"], q_grads, c.lr_critic)
    for got, want in zip(
        jax.tree_util.tree_leaves(new["critic"]), jax.tree_util.tree_leaves(expected_critic)
    ):
        np.testing.assert_allclose(np.asarray(got), want, rtol=1e-5, atol=1e-6)

    # the actor's loss, against the updated critic
    a, logp = np_sample(state["actor"], batch["obs"], noise_of(k_actor, n), low, high)
    q = np.minimum(*(np_q(_np_tree(new["critic"]), j, batch["obs"], a) for j in (0, 1)))
    assert float(info["loss_pi"]) == pytest.approx(np.mean(c.alpha * logp - q), rel=1e-4)

    # Polyak averaging towards the new critic
    for target, old, online in zip(
        jax.tree_util.tree_leaves(new["critic_target"]),
        jax.tree_util.tree_leaves(state["critic_target"]),
        jax.tree_util.tree_leaves(new["critic"]),
    ):
        expected = c.polyak * np.asarray(old) + (1 - c.polyak) * np.asarray(online)
        np.testing.assert_allclose(np.asarray(target), expected, rtol=1e-6, atol=1e-7)
    assert int(new["n_updates"]) == 1 and float(new["log_alpha"]) == float(state["log_alpha"])


@pytest.mark.parametrize("target_entropy, falls", [(-50.0, True), (50.0, False)])
def test_autotuned_temperature_follows_the_entropy(target_entropy, falls):
    """`--autotune-alpha`: α falls while the policy's entropy is above the target and rises below
    it, and its step is the first Adam step on the gradient of the temperature loss
    ∂/∂log α [−mean(log α (log π + H̄))] = H − H̄ (H = −mean log π)."""
    spec, state = make("sac", autotune_alpha=True, target_entropy=target_entropy, lr_alpha=0.01)
    state = filled_state(spec, state)
    new, info = jax.jit(functools.partial(sac.update_step, spec))(state)
    entropy = float(info["entropy"])
    grad = entropy - target_entropy
    expected = float(state["log_alpha"]) - 0.01 * grad / (abs(grad) + 1e-8)
    assert float(new["log_alpha"]) == pytest.approx(expected, rel=1e-5)
    assert (float(new["log_alpha"]) < float(state["log_alpha"])) == falls
    assert float(info["alpha"]) == pytest.approx(np.exp(float(new["log_alpha"])), rel=1e-6)


def test_exported_policy_counts_full_rank_at_the_configured_width(adarl_run):
    """After a cut (and after narrowing the stored width), the policy file's full-rank size is
    still the configured network's: obs→64, a 64·64 + 64·64 bottleneck, 64→act (counted by
    hand), while its stored size shrinks with the rank."""
    from adarl.policy import NumpyPolicy

    spec, _, state = adarl_run
    state, _ = sac.truncate(spec, state)
    r = int(sac.rank_state(spec, state)["actor_1"])
    assert r < 64
    narrow_spec = sac.with_widths(spec, {"actor:1": r, "critic:1": 64})
    narrow = sac.resize_bottlenecks(narrow_spec, state)
    full = (OBS * 64 + 64) + (64 * 64 + 64 * 64 + 64) + (64 * ACT + ACT)
    for s, st in ((spec, state), (narrow_spec, narrow)):
        policy = NumpyPolicy(sac.export_policy(s, st["actor"], st["masks"]["actor"]))
        assert int(policy.arrays["n_params_full"]) == policy.n_params_full() == full
        assert policy.n_params() == full - 2 * 64 * (64 - r)


def test_resizing_bottlenecks_pads_with_zeros_and_cuts_back_exactly(adarl_run):
    spec, _, state = adarl_run
    state, _ = sac.truncate(spec, state)
    ranks = sac.rank_state(spec, state)
    widths = {"actor:1": int(ranks["actor_1"]), "critic:1": int(max(ranks["q1_1"], ranks["q2_1"]))}
    narrow = sac.resize_bottlenecks(sac.with_widths(spec, widths), state)
    wide = sac.resize_bottlenecks(spec, jax.device_get(narrow))
    for a, b in zip(jax.tree_util.tree_leaves(wide), jax.tree_util.tree_leaves(state)):
        np.testing.assert_array_equal(a, b)
