"""Issue 55: `adarl.lowrank` checks its inputs (a ValueError naming the argument and what is
allowed), never decomposes a non-finite layer (the SVD of a matrix holding inf does not return on
this jaxlib), and behaves as documented for traced values; plus behaviour tests of the cut, the
optimiser reset, the initialisation and the schedules, each checked against a planted bug."""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from adarl import lowrank


def layer_from(rng, n_in, n_out, width, rank=None):
    w1 = jnp.asarray(rng.normal(size=(n_in, width)), jnp.float32)
    scale = np.logspace(0, -2, width)[:, None]
    w2 = jnp.asarray(rng.normal(size=(width, n_out)) * scale, jnp.float32)
    layer = {"w1": w1, "w2": w2, "b": jnp.zeros(n_out)}
    if rank is not None:
        mask = lowrank.rank_mask(rank, width)
        layer.update(w1=w1 * mask, w2=w2 * mask[:, None], mask=mask)
    return layer


# ----------------------------------------------------------------------------- bad inputs
@pytest.mark.parametrize(
    "kwargs, needle",
    [
        (dict(rank=0), "rank must be an integer >= 1, got 0"),
        (dict(rank=-2), "rank must be an integer >= 1, got -2"),
        (dict(rank=2.5), "rank must be an integer >= 1, got 2.5"),
        (dict(rank=8, width=4), "rank 8 exceeds width 4; allowed: 1 <= rank <= width"),
        (dict(rank=2, width=0), "width must be an integer >= 1, got 0"),
        (dict(n_in=0), "n_in must be an integer >= 1, got 0"),
    ],
)
def test_init_factorised_refuses_bad_sizes(kwargs, needle):
    args = dict(n_in=5, n_out=3, rank=2) | kwargs
    with pytest.raises(ValueError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        lowrank.init_factorised(jax.random.PRNGKey(0), **args)


@pytest.mark.parametrize(
    "kwargs, needle",
    [
        (dict(rank=0), "rank must be an integer >= 1, got 0"),
        (dict(rank=-1, width=None), "rank must be an integer >= 1, got -1"),
        (dict(rank=2.5), "rank must be an integer >= 1, got 2.5"),
        (dict(rank=4, width=2), "rank 4 exceeds width 2; allowed: 1 <= rank <= width"),
        (dict(rank=2, width=0), "width must be an integer >= 1, got 0"),
        (dict(features=0), "features must be an integer >= 1, got 0"),
    ],
)
def test_the_flax_layer_refuses_bad_sizes(kwargs, needle):
    """As init_factorised: rank 0 gave biases of ±inf (0**-0.5), rank > width a layer of rank
    `width` that reads as `rank`."""
    linen = pytest.importorskip("adarl.lowrank.linen", reason="flax is not installed")
    args = dict(features=3, rank=2) | kwargs
    with pytest.raises(ValueError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        linen.FactorisedDense(**args).init(jax.random.PRNGKey(0), jnp.ones((1, 5)))


@pytest.mark.parametrize("beta", [-0.5, 0.0, 1.5, math.nan, math.inf])
def test_a_beta_outside_0_1_is_refused(beta):
    params = {"l": layer_from(np.random.default_rng(0), 6, 5, 4)}
    with pytest.raises(ValueError, match=r"beta must be a number in \(0, 1\], got"):
        lowrank.truncate(params, beta=beta)
    with pytest.raises(ValueError, match="beta must be a number"):
        lowrank.select_rank(jnp.ones(4), beta, "energy")
    with pytest.raises(ValueError, match="beta must be a number"):
        jax.jit(lambda p: lowrank.truncate(p, beta=beta))(params)  # a Python β: at trace time


@pytest.mark.parametrize("tolerance", [-1.0, math.nan, math.inf])
def test_a_retain_tolerance_below_0_or_nan_is_refused(tolerance):
    params = {"l": layer_from(np.random.default_rng(0), 6, 5, 4)}
    with pytest.raises(ValueError, match=r"retain_tolerance must be None \(off\) or a finite"):
        lowrank.truncate(params, retain_tolerance=tolerance)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_a_non_finite_layer_is_refused_naming_it(value):
    """NaN weights were cut 4 -> 1 without a word; inf hung the SVD forever."""
    layer = layer_from(np.random.default_rng(1), 6, 5, 4)
    layer["w1"] = layer["w1"].at[2, 1].set(value)
    with pytest.raises(ValueError, match=r"layer \['mid'\]'s W1·diag\(mask\)·W2 holds inf or NaN"):
        lowrank.truncate({"mid": layer, "head": {"w": jnp.ones(2)}})
    with pytest.raises(ValueError, match="holds inf or NaN"):
        lowrank.cut_layer(layer["w1"], layer["w2"], jnp.ones(4))


def test_factors_whose_product_overflows_are_refused():
    layer = layer_from(np.random.default_rng(1), 6, 5, 4)
    layer["w1"], layer["w2"] = layer["w1"] * 1e30, layer["w2"] * 1e30  # finite, product inf
    assert np.isfinite(layer["w1"]).all() and not np.isfinite(layer["w1"] @ layer["w2"]).all()
    with pytest.raises(ValueError, match="holds inf or NaN"):
        lowrank.truncate({"l": layer})


def test_a_mask_that_is_not_0_1_is_refused():
    """A mask of 0.5s read as rank 2 (of 4); weight decay makes such masks."""
    layer = layer_from(np.random.default_rng(2), 6, 5, 4, rank=4)
    for bad in (jnp.full(4, 0.5), jnp.array([1.0, 0.0, 1.0, 0.0]), jnp.full(4, 0.999)):
        with pytest.raises(ValueError, match="is not a 0/1 mask with its ones first"):
            lowrank.truncate({"l": dict(layer, mask=bad)})
        with pytest.raises(ValueError, match="weight_decay_mask"):
            lowrank.layer_rank(dict(layer, mask=bad))
        with pytest.raises(ValueError, match="not a 0/1 mask"):
            lowrank.to_compact({"l": dict(layer, mask=bad)})


def test_select_rank_takes_a_1d_spectrum_only():
    with pytest.raises(ValueError, match=r"sigma must be a 1-D spectrum, got shape \(2, 3\)"):
        lowrank.select_rank(jnp.ones((2, 3)), 0.9, "energy")
    with pytest.raises(ValueError, match="sigma must be a 1-D"):
        jax.jit(lambda s: lowrank.select_rank(s, 0.9, "energy"))(jnp.ones((2, 3)))
    with pytest.raises(ValueError, match="unknown rank rule 'eq5'"):
        lowrank.select_rank(jnp.ones(3), 0.9, "eq5")


def test_mismatched_factors_are_refused():
    with pytest.raises(ValueError, match=r"w1, w2, mask have shapes \(6, 4\), \(3, 5\), \(4,\)"):
        lowrank.cut_layer(jnp.ones((6, 4)), jnp.ones((3, 5)), jnp.ones(4))
    with pytest.raises(ValueError, match="allowed: a stack on axis 0 of"):
        lowrank.cut_layer(jnp.ones((6, 4)), jnp.ones((4, 5)), jnp.ones(4), batched=True)


@pytest.mark.parametrize(
    "make",
    [
        lambda **kw: lowrank.envelope_schedule(1e-3, total_steps=100, warmup_steps=10, **kw),
        lambda **kw: lowrank.restart_schedule(1e-3, warmup_steps=10, **kw),
    ],
    ids=["envelope", "restart"],
)
def test_schedules_refuse_cut_every_below_1(make):
    for bad in (0, -5, 2.5):
        with pytest.raises(ValueError, match=f"cut_every must be an integer >= 1, got {bad}"):
            make(cut_every=bad)
    with pytest.raises(ValueError, match=r"min_ratio must be a number in \[0, 1\]"):
        make(cut_every=10, min_ratio=2.0)
    make(cut_every=10)  # fine


def test_envelope_refuses_total_steps_below_1():
    with pytest.raises(ValueError, match="total_steps must be an integer >= 1, got 0"):
        lowrank.envelope_schedule(1e-3, total_steps=0, warmup_steps=10, cut_every=10)


# ----------------------------------------------------------------------------- traced values
def test_a_traced_non_finite_layer_is_left_as_it_was():
    """Under jit nothing can raise: the non-finite layer comes back unchanged (rank kept, NaN
    spectrum and error), the finite one beside it is cut as alone."""
    rng = np.random.default_rng(3)
    bad, good = layer_from(rng, 6, 5, 4, rank=4), layer_from(rng, 6, 5, 4, rank=4)
    bad["w2"] = bad["w2"].at[0, 0].set(jnp.nan)
    cut = jax.jit(lambda p: lowrank.truncate(p, rule="energy", beta=0.6))
    new, _, rec = cut({"bad": bad, "good": good})
    for name in ("w1", "w2", "mask"):
        np.testing.assert_array_equal(new["bad"][name], bad[name])
    assert int(rec["['bad']"].applied) == int(rec["['bad']"].proposed) == 4
    assert np.isnan(rec["['bad']"].spectrum).all() and np.isnan(rec["['bad']"].error)
    alone, _, rec_alone = lowrank.truncate({"good": good}, rule="energy", beta=0.6)
    assert int(rec["['good']"].applied) == int(rec_alone["['good']"].applied) < 4
    np.testing.assert_allclose(new["good"]["w1"], alone["good"]["w1"], rtol=1e-5, atol=1e-6)


def test_a_traced_inf_layer_does_not_hang_the_svd():
    """jaxlib's SVD of a matrix holding inf does not return: in a child process, so that a
    regression fails in a minute instead of hanging the suite."""
    code = textwrap.dedent(
        """
        import jax, jax.numpy as jnp, numpy as np
        from adarl import lowrank
        layer = lowrank.init_factorised(jax.random.PRNGKey(0), 6, 5, 4, width=4)
        layer["w1"] = layer["w1"].at[0, 0].set(jnp.inf)
        new, _, rec = jax.jit(lowrank.truncate)({"l": layer})
        np.testing.assert_array_equal(new["l"]["w1"], layer["w1"])
        w1, w2, m, r = jax.jit(lowrank.cut_layer)(layer["w1"], layer["w2"], layer["mask"])
        assert int(r.applied) == 4 and np.isnan(r.spectrum).all()
        print("returned")
        """
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "returned" in done.stdout, done.stderr[-2000:]


def test_a_traced_beta_outside_0_1_cuts_nothing():
    layer = layer_from(np.random.default_rng(4), 6, 5, 4, rank=4)
    cut = jax.jit(lambda p, b: lowrank.truncate(p, rule="cumulative", beta=b))
    for beta in (-0.5, 1.5, math.nan):
        new, _, rec = cut({"l": layer}, jnp.float32(beta))
        assert int(rec["['l']"].applied) == 4, beta
    _, _, rec = cut({"l": layer}, jnp.float32(0.3))
    assert int(rec["['l']"].applied) < 4  # a valid traced β cuts


def test_a_traced_nan_or_negative_tolerance_keeps_every_rank():
    layer = layer_from(np.random.default_rng(4), 6, 5, 4, rank=4)
    cut = jax.jit(lambda p, t: lowrank.truncate(p, beta=0.5, retain_tolerance=t))
    for tolerance in (math.nan, -1.0):
        _, _, rec = cut({"l": layer}, jnp.float32(tolerance))
        assert int(rec["['l']"].candidate) < 4 and int(rec["['l']"].applied) == 4


# ----------------------------------------------------------------------------- defaults
def test_the_defaults_are_adarls():
    """adarl trains with --rank-rule energy --beta 0.98 (SACConfig); the library's defaults
    agree, and a default cut equals the explicit one."""
    from adarl.algos.sac_config import SACConfig

    assert (SACConfig.rank_rule, SACConfig.beta) == ("energy", 0.98)
    assert (lowrank.DEFAULT_RULE, lowrank.DEFAULT_BETA) == ("energy", 0.98)
    layer = layer_from(np.random.default_rng(5), 9, 7, 6)
    _, _, default = lowrank.truncate({"l": layer})
    _, _, energy = lowrank.truncate({"l": layer}, rule="energy", beta=0.98)
    _, _, paper = lowrank.truncate({"l": layer}, rule="cumulative", beta=0.9)
    assert int(default["['l']"].applied) == int(energy["['l']"].applied)
    assert int(energy["['l']"].applied) != int(paper["['l']"].applied)  # the old default differs


def test_weight_decay_mask_keeps_masks_out_of_weight_decay():
    """adamw decays every parameter it is given, the mask too (1 -> 1 - lr·wd): with
    `mask=weight_decay_mask` the mask stays 0/1 and the other parameters still decay."""
    layer = lowrank.init_factorised(jax.random.PRNGKey(0), 5, 3, 2, width=4)
    params = {"l": layer, "head": {"w": jnp.ones((3, 2))}}
    zero = jax.tree_util.tree_map(jnp.zeros_like, params)
    for mask, expect_kept in ((None, False), (lowrank.weight_decay_mask, True)):
        opt = optax.adamw(0.1, weight_decay=0.5, mask=mask)
        updates, _ = opt.update(zero, opt.init(params), params)
        after = optax.apply_updates(params, updates)
        kept = bool(jnp.all(after["l"]["mask"] == layer["mask"]))
        assert kept == expect_kept
        assert float(after["head"]["w"][0, 0]) < 1.0  # decay still applies elsewhere
    assert lowrank.weight_decay_mask(params)["l"] == {
        "w1": True,
        "w2": True,
        "mask": False,
        "b": True,
    }


# ----------------------------------------------------------------------------- behaviour
def np_energy_rank(sigma, beta):
    frac = np.cumsum(sigma) / sigma.sum()
    return min(
        [ell for ell in range(1, len(sigma) + 1) if frac[ell - 1] >= beta], default=len(sigma)
    )


def test_a_compact_stack_cut_to_two_ranks_keeps_the_larger_width():
    """Two compact layers stacked (twin critics) cut to different ranks: the stack is as wide as
    the larger one, and each layer equals its cut alone (components past its rank zero)."""
    rng = np.random.default_rng(10)
    a = layer_from(rng, 7, 5, 6)
    b = {**layer_from(rng, 7, 5, 6)}
    b["w2"] = b["w2"] * jnp.asarray([1.0, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4])[:, None]  # ~rank 1
    stack = jax.tree_util.tree_map(lambda x, y: jnp.stack([x, y]), a, b)
    new, _, rec = lowrank.truncate({"q": stack}, rule="energy", beta=0.9)
    ranks = [int(r) for r in rec["['q']"].applied]
    assert ranks[0] > ranks[1]
    for layer, want in ((a, ranks[0]), (b, ranks[1])):
        s = np.linalg.svd(np.asarray(layer["w1"] @ layer["w2"], np.float64), compute_uv=False)
        assert want == np_energy_rank(s, 0.9)
    assert new["q"]["w1"].shape == (2, 7, ranks[0]) and new["q"]["w2"].shape == (2, ranks[0], 5)
    for k, one in enumerate((a, b)):
        alone, _, _ = lowrank.truncate({"q": one}, rule="energy", beta=0.9)
        r = alone["q"]["w1"].shape[-1]
        np.testing.assert_allclose(new["q"]["w1"][k][:, :r], alone["q"]["w1"], rtol=1e-5, atol=1e-6)
        np.testing.assert_array_equal(new["q"]["w1"][k][:, r:], 0.0)
    masked = jax.tree_util.tree_map(lambda x, y: jnp.stack([x, y]), *[
        dict(one, mask=jnp.ones(6)) for one in (a, b)
    ])  # fmt: skip
    cut, _, _ = lowrank.truncate({"q": masked}, rule="energy", beta=0.9)
    compact = lowrank.to_compact(cut)
    assert compact["q"]["w1"].shape == (2, 7, ranks[0]) and "mask" not in compact["q"]
    for k in range(2):
        np.testing.assert_allclose(
            compact["q"]["w1"][k] @ compact["q"]["w2"][k],
            new["q"]["w1"][k] @ new["q"]["w2"][k],
            rtol=1e-4,
            atol=1e-5,
        )


def test_after_a_cut_every_adam_moment_and_the_count_are_zero():
    rng = np.random.default_rng(11)
    params = {"l": layer_from(rng, 8, 4, 4, rank=4), "head": {"w": jnp.ones((4, 2))}}
    opt = optax.adam(1e-3)
    state = opt.init(params)
    for _ in range(3):
        _, state = opt.update(jax.tree_util.tree_map(jnp.ones_like, params), state, params)
    assert int(state[0].count) == 3
    for optimizer in (None, opt):
        _, reset, _ = lowrank.truncate(params, state, beta=0.5, optimizer=optimizer)
        leaves = jax.tree_util.tree_leaves(reset)
        assert leaves and all(float(jnp.abs(x).max()) == 0 for x in leaves)
        assert int(reset[0].count) == 0


def test_a_masked_layer_is_the_compact_one_of_the_same_key_padded():
    """Same key, rank r: the masked layer at width d computes the compact layer's function
    (its first r components are the compact factors, W2 and b at the scale 1/√r)."""
    key = jax.random.PRNGKey(7)
    compact = lowrank.init_factorised(key, 6, 5, 3)
    masked = lowrank.init_factorised(key, 6, 5, 3, width=8)
    np.testing.assert_array_equal(masked["w1"][:, :3], compact["w1"])
    np.testing.assert_array_equal(masked["w2"][:3], compact["w2"])
    np.testing.assert_array_equal(masked["b"], compact["b"])
    np.testing.assert_array_equal(masked["w1"][:, 3:], 0.0)
    x = jnp.asarray(np.random.default_rng(0).normal(size=(4, 6)), jnp.float32)
    np.testing.assert_allclose(
        lowrank.apply_factorised(masked, x), lowrank.apply_factorised(compact, x), rtol=1e-6
    )
    assert float(jnp.abs(compact["w2"]).max()) <= 1 / math.sqrt(3)
    assert float(jnp.abs(compact["w2"]).max()) > 1 / math.sqrt(8)  # 1/√r, not 1/√d
    assert float(jnp.abs(compact["w1"]).max()) <= 1 / math.sqrt(6)


def test_layer_rank_of_a_compact_layer_is_w1s_width():
    layer = lowrank.init_factorised(jax.random.PRNGKey(0), 6, 9, 2)  # n_out 9 != rank 2
    assert int(lowrank.layer_rank(layer)) == 2
    stack = jax.tree_util.tree_map(lambda x: jnp.stack([x, x, x]), layer)
    np.testing.assert_array_equal(lowrank.layer_rank(stack), [2, 2, 2])


def test_the_envelope_with_default_arguments_is_0_at_total_steps():
    schedule = lowrank.envelope_schedule(1e-3, total_steps=1000, warmup_steps=10, cut_every=300)
    assert float(schedule(1000)) == 0.0  # min_ratio 0: the cosine reaches 0 at T (past warm-up)
    assert float(schedule(999)) > 0.0
    assert float(schedule(1)) == pytest.approx(1e-3 * 0.5 * (1 + math.cos(math.pi / 1000)))


@pytest.mark.parametrize("rule", ["cumulative", "ratio", "energy", "energy-squared"])
@pytest.mark.parametrize("sigma", [[3.0, math.nan, 1.0], [math.inf, 1.0, 0.5], [3.0, -1.0, 0.5]])
def test_a_non_finite_or_negative_spectrum_is_refused_naming_sigma(rule, sigma):
    # issue 61 §9: [3, nan, 1] gave 1 under `energy`, [inf, 1, .5] gave 2 under `ratio`, silently
    with pytest.raises(ValueError, match="sigma must be a spectrum of finite, non-negative"):
        lowrank.select_rank(jnp.asarray(sigma), 0.9, rule)


def test_a_traced_spectrum_is_not_checked_and_still_selects():
    rank = jax.jit(lambda s: lowrank.select_rank(s, 0.9, "energy"))(jnp.asarray([3.0, 2.0, 1.0]))
    assert int(rank) == 3  # 3/6, 5/6 < 0.9 <= 6/6


def test_another_models_optimiser_state_is_refused_without_reset():
    # issue 61 §9: truncate(..., reset=False) with another tree's state returned that state
    rng = np.random.default_rng(5)
    params = {"l": layer_from(rng, 8, 4, 4, rank=4), "head": {"w": jnp.ones((4, 2))}}
    other = {"x": {"w": jnp.ones((3, 3))}}
    foreign = optax.adam(1e-3).init(other)
    with pytest.raises(ValueError, match="opt_state does not match params"):
        lowrank.truncate(params, foreign, beta=0.5, reset=False)
    own = optax.adam(1e-3).init(params)
    kept = lowrank.truncate(params, own, beta=0.5, reset=False).opt_state
    assert jax.tree_util.tree_structure(kept) == jax.tree_util.tree_structure(own)
    empty = optax.sgd(1e-3).init(params)  # no per-parameter state: nothing to match
    assert lowrank.truncate(params, empty, beta=0.5, reset=False).opt_state == empty
