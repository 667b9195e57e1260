"""`adarl.lowrank` against NumPy references: ranks per rule, the re-parameterisation keeping W,
optimiser state shapes after a cut, masked = compact on a network's output, the schedules."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from adarl import lowrank
from adarl.nets import choices


def np_rank(sigma, beta, rule):
    """The rules written out literally (paper Eq. 5, Eq. 7, the energy rule)."""
    d, frac = len(sigma), np.cumsum(sigma) / sigma.sum()
    if rule == "cumulative":  # max{ℓ : Σ_{i≤ℓ}σ_i/Σσ ≤ β}, 0 if none
        return max([ell for ell in range(1, d + 1) if frac[ell - 1] <= beta], default=0)
    if rule == "ratio":  # min{ℓ : σ_ℓ/σ_1 ≤ β}, d if none
        return min([ell for ell in range(1, d + 1) if sigma[ell - 1] / sigma[0] <= beta], default=d)
    if rule == "energy":  # min{ℓ : Σ_{i≤ℓ}σ_i/Σσ ≥ β}
        return min([ell for ell in range(1, d + 1) if frac[ell - 1] >= beta], default=d)
    raise ValueError(rule)


def np_cut(w, beta, rule, old):
    """SVD, rule, r = max(1, min(old, r̂)), best rank-r approximation (NumPy, float64)."""
    u, s, vt = np.linalg.svd(w.astype(np.float64), full_matrices=False)
    s = s[:old]  # a bottleneck of width d has at most d non-zero singular values
    r = max(1, min(old, np_rank(s, beta, rule)))
    return r, (u[:, :r] * s[:r]) @ vt[:r]


def test_rank_rules_match_numpy():
    rng = np.random.default_rng(1)
    for _ in range(30):
        sigma = np.sort(rng.exponential(1.0, size=12))[::-1].astype(np.float32)
        for rule in ("cumulative", "ratio", "energy"):
            for beta in (0.3, 0.7, 0.95):
                got = int(lowrank.select_rank(jnp.asarray(sigma), beta, rule))
                assert got == np_rank(sigma.astype(np.float64), beta, rule), (rule, beta, sigma)


def test_rule_names_are_the_configs():
    assert lowrank.RANK_RULES == choices.RANK_RULES


def layer_from(rng, n_in, n_out, width, rank=None):
    w1 = rng.normal(size=(n_in, width)).astype(np.float32)
    w2 = rng.normal(size=(width, n_out)).astype(np.float32) * np.logspace(0, -2, width)[:, None]
    layer = {"w1": jnp.asarray(w1), "w2": jnp.asarray(w2.astype(np.float32)), "b": jnp.zeros(n_out)}
    if rank is not None:
        mask = lowrank.rank_mask(rank, width)
        layer.update(w1=layer["w1"] * mask, w2=layer["w2"] * mask[:, None], mask=mask)
    return layer


@pytest.mark.parametrize("rule", ["cumulative", "ratio", "energy"])
def test_truncate_is_the_best_rank_r_approximation(rule):
    rng = np.random.default_rng(2)
    layer = layer_from(rng, 9, 7, 6)
    w = np.asarray(layer["w1"] @ layer["w2"])
    new, _, records = lowrank.truncate({"l": layer}, rule=rule, beta=0.8)
    r, best = np_cut(w, 0.8, rule, 6)
    rec = records["['l']"]
    assert int(rec.applied) == r == new["l"]["w1"].shape[1] == new["l"]["w2"].shape[0]
    assert int(rec.old_rank) == 6
    np.testing.assert_allclose(new["l"]["w1"] @ new["l"]["w2"], best, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(rec.spectrum, np.linalg.svd(w, compute_uv=False)[:6], rtol=1e-4)


def test_reparameterisation_keeps_w_at_full_rank():
    """β = 1 under Eq. 5 keeps every component: W1·W2 is unchanged, the factors balanced."""
    rng = np.random.default_rng(3)
    layer = layer_from(rng, 10, 5, 5)
    w = layer["w1"] @ layer["w2"]
    new, _, records = lowrank.truncate({"l": layer}, rule="cumulative", beta=1.0)
    assert int(records["['l']"].applied) == 5
    np.testing.assert_allclose(new["l"]["w1"] @ new["l"]["w2"], w, rtol=1e-5, atol=1e-5)
    # W1 = U√Σ, W2 = √ΣVᵀ: W1ᵀW1 = W2W2ᵀ = Σ
    np.testing.assert_allclose(
        new["l"]["w1"].T @ new["l"]["w1"], new["l"]["w2"] @ new["l"]["w2"].T, atol=1e-4
    )


def test_optimiser_state_after_a_cut():
    rng = np.random.default_rng(4)
    params = {"l": layer_from(rng, 8, 4, 4), "head": {"w": jnp.ones((4, 2))}}
    opt = optax.adam(1e-3)
    state = opt.init(params)
    grads = jax.tree_util.tree_map(jnp.ones_like, params)
    _, state = opt.update(grads, state, params)
    new, reset, rec = lowrank.truncate(params, state, beta=0.5, optimizer=opt)
    r = int(rec["['l']"].applied)
    assert r < 4
    mu = reset[0].mu
    assert mu["l"]["w1"].shape == (8, r) and mu["l"]["w2"].shape == (r, 4)
    assert all(float(jnp.abs(x).sum()) == 0 for x in jax.tree_util.tree_leaves(mu))
    assert int(reset[0].count) == 0
    _, zeroed, _ = lowrank.truncate(params, state, beta=0.5)  # reset without the optimiser
    assert jax.tree_util.tree_map(jnp.shape, zeroed) == jax.tree_util.tree_map(jnp.shape, reset)
    _, kept, _ = lowrank.truncate(params, state, beta=0.5, reset=False)
    assert kept[0].mu["l"]["w1"].shape == (8, r)
    np.testing.assert_array_equal(kept[0].mu["head"]["w"], state[0].mu["head"]["w"])
    assert int(kept[0].count) == 1
    opt.update(jax.tree_util.tree_map(jnp.ones_like, new), kept, new)  # the shapes fit


def mlp(params, x):
    h = jax.nn.relu(lowrank.apply_factorised(params["l0"], x))
    return lowrank.apply_factorised(params["l1"], h)


@pytest.mark.parametrize("rule", ["cumulative", "energy"])
def test_masked_equals_compact_on_the_output(rule):
    rng = np.random.default_rng(5)
    compact = {"l0": layer_from(rng, 6, 16, 8), "l1": layer_from(rng, 16, 3, 3)}
    masked = {
        "l0": dict(compact["l0"], mask=jnp.ones(8)),
        "l1": dict(compact["l1"], mask=jnp.ones(3)),
    }
    x = jnp.asarray(rng.normal(size=(32, 6)), jnp.float32)
    np.testing.assert_allclose(mlp(compact, x), mlp(masked, x), rtol=1e-6)
    for _ in range(2):  # two successive cuts
        compact, _, rc = lowrank.truncate(compact, rule=rule, beta=0.8)
        masked, _, rm = jax.jit(lambda p: lowrank.truncate(p, rule=rule, beta=0.8))(masked)
        for path in rc:
            assert int(rc[path].applied) == int(rm[path].applied)
        assert masked["l0"]["w1"].shape == (6, 8)  # one shape under jit
        np.testing.assert_allclose(mlp(compact, x), mlp(masked, x), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(mlp(lowrank.to_compact(masked), x), mlp(masked, x), atol=1e-5)


def test_masked_components_get_no_gradient():
    rng = np.random.default_rng(6)
    layer = layer_from(rng, 5, 4, 6, rank=2)
    g = jax.grad(lambda p: jnp.sum(lowrank.apply_factorised(p, jnp.ones((3, 5))) ** 2))(layer)
    assert float(jnp.abs(g["w1"][:, 2:]).sum()) == 0 and float(jnp.abs(g["w2"][2:]).sum()) == 0
    assert float(jnp.abs(g["mask"]).sum()) == 0


def test_retain_clause_on_the_output():
    """Tolerance 0: any candidate that changes the output is refused, the old rank kept (the
    layer is still re-parameterised in the SVD basis at that rank); a loose one accepts."""
    rng = np.random.default_rng(7)
    params = {"l0": layer_from(rng, 6, 16, 8), "l1": layer_from(rng, 16, 3, 3)}
    x = jnp.asarray(rng.normal(size=(32, 6)), jnp.float32)
    out = lambda p: mlp(p, x)  # noqa: E731
    strict, _, rec = lowrank.truncate(params, beta=0.5, retain_tolerance=0.0, output_fn=out)
    assert int(rec["['l0']"].candidate) < 8 and int(rec["['l0']"].applied) == 8
    assert float(rec["['l0']"].error) > 0
    np.testing.assert_allclose(mlp(strict, x), mlp(params, x), rtol=1e-4, atol=1e-4)
    _, _, loose = lowrank.truncate(params, beta=0.5, retain_tolerance=10.0, output_fn=out)
    assert int(loose["['l0']"].applied) == int(loose["['l0']"].candidate) < 8


def test_control_keeps_the_rank():
    rng = np.random.default_rng(8)
    params = {"l": layer_from(rng, 8, 6, 6)}
    new, _, rec = lowrank.truncate(params, beta=0.5, apply_cuts=False)
    assert int(rec["['l']"].applied) == 6 > int(rec["['l']"].candidate)
    np.testing.assert_allclose(
        new["l"]["w1"] @ new["l"]["w2"], params["l"]["w1"] @ params["l"]["w2"], atol=1e-5
    )


def test_envelope_schedule_restarts_at_each_cut():
    kw = dict(total_steps=3000, warmup_steps=100, cut_every=500, min_ratio=0.1)
    schedule = lowrank.envelope_schedule(1e-3, **kw)
    for t in (0, 50, 499, 500, 550, 600, 1234, 2999):
        start = t // 500 * 500
        want = lowrank.envelope_learning_rate(t, start, 1e-3, 100, 3000, 0.1, start > 0)
        assert float(schedule(t)) == float(want)
    assert float(schedule(0)) == pytest.approx(1e-3)  # no warm-up before the first cut
    assert float(schedule(500)) == 0.0 and float(schedule(550)) < float(schedule(600))
    restart = lowrank.restart_schedule(1e-3, warmup_steps=100, cut_every=500, min_ratio=0.1)
    assert float(restart(0)) == 0.0 and float(restart(100)) == pytest.approx(1e-3)
    assert float(restart(500)) == pytest.approx(1e-4)


def test_flax_layer_is_cut_in_place():
    linen = pytest.importorskip("adarl.lowrank.linen", reason="flax is not installed")
    net = linen.FactorisedDense(features=3, rank=6, width=6)
    x = jnp.ones((2, 5))
    params = net.init(jax.random.PRNGKey(0), x)
    assert set(params["params"]) == {"w1", "w2", "mask", "b"}
    new, _, rec = lowrank.truncate(params, beta=0.5)
    assert jax.tree_util.tree_map(jnp.shape, new) == jax.tree_util.tree_map(jnp.shape, params)
    assert int(next(iter(rec.values())).applied) < 6
    net.apply(new, x)


def test_a_stack_is_cut_layer_by_layer():
    """Twin critics stacked on axis 0 (vmap, Flax's nn.vmap): each is cut as if alone."""
    rng = np.random.default_rng(9)
    a, b = layer_from(rng, 7, 5, 6, rank=6), layer_from(rng, 7, 5, 6, rank=4)
    stack = jax.tree_util.tree_map(lambda x, y: jnp.stack([x, y]), a, b)
    new, _, rec = lowrank.truncate({"q": stack}, rule="energy", beta=0.9)
    for k, one in enumerate((a, b)):
        alone, _, rec_one = lowrank.truncate({"q": one}, rule="energy", beta=0.9)
        assert int(rec["['q']"].applied[k]) == int(rec_one["['q']"].applied)
        for name in ("w1", "w2", "mask"):
            np.testing.assert_allclose(new["q"][name][k], alone["q"][name], rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(lowrank.layer_rank(new["q"]), rec["['q']"].applied)
