"""Rank rules, SVD truncation and the restart schedule against NumPy references."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from bottleneck_step import truncate_bottleneck

from adarl.nets import rank


def np_cumulative_rule(sigma, beta):
    """Paper Eq. 5 literally: max{ℓ ∈ 1..d : Σ_{i≤ℓ}σ_i / Σ_i σ_i ≤ β} (0 if the set is empty)."""
    total = sigma.sum()
    best = 0
    for ell in range(1, len(sigma) + 1):
        if sigma[:ell].sum() / total <= beta:
            best = ell
    return best


def np_ratio_rule(sigma, beta):
    """Paper Eq. 7 literally: min{ℓ : σ_ℓ/σ_1 ≤ β} (d if the set is empty)."""
    for ell in range(1, len(sigma) + 1):
        if sigma[ell - 1] / sigma[0] <= beta:
            return ell
    return len(sigma)


def spectra():
    rng = np.random.default_rng(0)
    out = [np.sort(rng.uniform(0, 5, size=64))[::-1] for _ in range(20)]
    out += [np.sort(rng.exponential(1.0, size=16))[::-1] for _ in range(20)]
    out.append(np.ones(64))  # flat
    out.append(np.array([100.0] + [1e-3] * 63))  # one dominant value
    out.append(np.array([3.0, 3.0, 2.0, 2.0, 2.0, 1.0, 1.0, 0.0]))  # ties and a zero
    out.append(np.array([1.0, 0.5, 0.25, 0.125]))
    return out


@pytest.mark.parametrize("beta", [1e-6, 0.02, 0.5, 0.9, 0.98, 0.999999])
def test_cumulative_rule_matches_numpy(beta):
    for sigma in spectra():
        got = int(rank.select_rank(jnp.asarray(sigma, jnp.float32), beta, "cumulative"))
        assert got == np_cumulative_rule(sigma, beta), (sigma, beta)


@pytest.mark.parametrize("beta", [1e-6, 0.3, 0.5, 0.98, 0.999999])
def test_ratio_rule_matches_numpy(beta):
    for sigma in spectra():
        got = int(rank.select_rank(jnp.asarray(sigma, jnp.float32), beta, "ratio"))
        assert got == np_ratio_rule(sigma, beta), (sigma, beta)


def test_hand_made_spectra():
    flat = jnp.ones(10)
    assert int(rank.select_rank_cumulative(flat, 0.98)) == 9  # 10/10 > 0.98, 9/10 ≤ 0.98
    assert int(rank.select_rank_cumulative(flat, 0.5)) == 5
    dominant = jnp.array([100.0, 1.0, 1.0])
    assert int(rank.select_rank_cumulative(dominant, 0.9)) == 0  # empty set: floored later
    assert int(rank.next_rank(64, rank.select_rank_cumulative(dominant, 0.9))) == 1
    assert int(rank.select_rank_ratio(jnp.array([4.0, 4.0, 4.0]), 0.98)) == 3  # none qualifies


def test_rank_never_grows_and_is_at_least_one():
    for old in range(1, 10):
        for proposed in range(0, 12):
            new = int(rank.next_rank(old, proposed))
            assert 1 <= new <= old
            assert new == max(1, min(old, proposed))


@pytest.mark.parametrize("beta", [0.9, 0.98, 0.999])
def test_cumulative_rule_always_cuts_a_bottleneck_of_rank_above_one(beta):
    """Eq. 5 has no fixed point above rank 1: a rank-r product has σ_{r+1..} = 0, so
    Σ_{i≤r}σ_i / Σσ_i = 1 > β and r̂ ≤ r − 1 at every truncation. The rank after k truncations
    is at most r₀ − k: the number of truncations, total steps / d_t, bounds how far it falls."""
    rng = np.random.default_rng(1)
    for r in range(2, 65):
        for _ in range(5):
            sigma = np.zeros(64)
            sigma[:r] = np.sort(rng.uniform(0.01, 5, size=r) ** rng.uniform(0.5, 4))[::-1]
            proposed = int(rank.select_rank_cumulative(jnp.asarray(sigma, jnp.float32), beta))
            assert proposed == np_cumulative_rule(sigma, beta) <= r - 1


def random_factors(seed, n_in=64, width=64, n_out=64, rank_=64):
    rng = np.random.default_rng(seed)
    w1 = rng.normal(size=(n_in, width)).astype(np.float32)
    w2 = rng.normal(size=(width, n_out)).astype(np.float32)
    mask = (np.arange(width) < rank_).astype(np.float32)
    return w1 * mask, w2 * mask[:, None], mask


@pytest.mark.parametrize("seed", range(5))
def test_truncation_is_the_best_rank_r_approximation(seed):
    w1, w2, mask = random_factors(seed)
    beta = 0.5
    new_w1, new_w2, new_mask, sigma, proposed = truncate_bottleneck(
        jnp.asarray(w1), jnp.asarray(w2), jnp.asarray(mask), beta
    )
    product = w1.astype(np.float64) @ w2
    u, s, vt = np.linalg.svd(product)
    r = max(1, min(64, np_cumulative_rule(s, beta)))
    assert int(new_mask.sum()) == r
    best = (u[:, :r] * s[:r]) @ vt[:r]  # Eckart–Young
    got = np.asarray(new_w1, np.float64) @ np.asarray(new_w2, np.float64)
    scale = np.abs(product).max()
    np.testing.assert_allclose(got, best, atol=2e-4 * scale)
    np.testing.assert_allclose(np.asarray(sigma), s[:64], rtol=1e-4, atol=1e-4 * s[0])
    # the product's top-r singular values are kept, the rest are gone
    s_new = np.linalg.svd(got, compute_uv=False)
    np.testing.assert_allclose(s_new[:r], s[:r], rtol=1e-4)
    assert np.all(s_new[r:] < 1e-3 * s[0])
    # components past r are exactly zero, and the factors are balanced: W1 = U√Σ, W2 = √ΣVᵀ
    assert np.all(np.asarray(new_w1)[:, r:] == 0) and np.all(np.asarray(new_w2)[r:] == 0)
    np.testing.assert_allclose(
        np.linalg.norm(np.asarray(new_w1)[:, :r], axis=0) ** 2, s[:r], rtol=1e-4
    )


def test_truncation_changes_the_function_by_at_most_the_discarded_singular_value():
    w1, w2, mask = random_factors(7)
    new_w1, new_w2, new_mask, sigma, _ = truncate_bottleneck(
        jnp.asarray(w1), jnp.asarray(w2), jnp.asarray(mask), 0.6
    )
    r = int(new_mask.sum())
    x = np.random.default_rng(1).normal(size=(256, 64)).astype(np.float32)
    before = x @ w1 @ w2
    after = x @ np.asarray(new_w1) @ np.asarray(new_w2)
    # ‖x(W − W_r)‖ ≤ σ_{r+1}‖x‖ per row
    bound = float(sigma[r]) * np.linalg.norm(x, axis=1)
    assert np.all(np.linalg.norm(before - after, axis=1) <= bound * (1 + 1e-4) + 1e-3)


def test_truncation_respects_the_current_rank():
    w1, w2, mask = random_factors(3, rank_=10)
    _, _, new_mask, sigma, proposed = truncate_bottleneck(
        jnp.asarray(w1), jnp.asarray(w2), jnp.asarray(mask), 0.999999
    )
    assert int(new_mask.sum()) <= 10  # rank never grows
    assert np.all(np.asarray(sigma)[10:] < 1e-3)  # a rank-10 product has 10 non-zero values


def test_truncation_vmaps_with_per_seed_ranks():
    parts = [random_factors(s, rank_=r) for s, r in [(0, 64), (1, 20), (2, 5)]]
    w1 = jnp.stack([p[0] for p in parts])
    w2 = jnp.stack([p[1] for p in parts])
    mask = jnp.stack([p[2] for p in parts])
    out = jax.vmap(lambda a, b, m: truncate_bottleneck(a, b, m, 0.98))(w1, w2, mask)
    ranks = np.asarray(out[2].sum(axis=1))
    assert ranks[1] <= 20 and ranks[2] <= 5 and ranks[0] <= 64


def np_energy_rule(sigma, beta):
    """The srank form literally: min{ℓ ∈ 1..d : Σ_{i≤ℓ}σ_i / Σ_i σ_i ≥ β} (d if the set is empty)."""
    total = sigma.sum()
    for ell in range(1, len(sigma) + 1):
        if total > 0 and sigma[:ell].sum() / total >= beta:
            return ell
    return len(sigma)


@pytest.mark.parametrize("beta", [1e-6, 0.02, 0.5, 0.9, 0.98, 0.999999])
@pytest.mark.parametrize("squared", [False, True])
def test_energy_rules_match_numpy_reference(beta, squared):
    for sigma in spectra():
        mass = sigma**2 if squared else sigma
        # float32 cumulative sums can differ from float64 at an exact tie with β: skip those
        if np.any(np.isclose(np.cumsum(mass) / mass.sum(), beta, rtol=0, atol=1e-6)):
            continue
        rule = "energy-squared" if squared else "energy"
        got = int(rank.select_rank(jnp.asarray(sigma, jnp.float32), beta, rule))
        assert got == np_energy_rule(mass, beta), (rule, beta, sigma[:5])


def test_energy_rule_differs_from_eq5_by_at_most_one_component():
    for sigma in spectra():
        for beta in (0.3, 0.9, 0.98):
            s = jnp.asarray(sigma, jnp.float32)
            energy = int(rank.select_rank_energy(s, beta))
            cumulative = int(rank.select_rank_cumulative(s, beta))
            assert energy - cumulative in (0, 1)


@pytest.mark.parametrize("rule", ["energy", "energy-squared"])
def test_energy_rules_have_a_fixed_point(rule):
    """A rank-r spectrum whose smallest non-zero value holds more than 1 − β of the mass is kept
    at r; one whose smallest holds less is cut. Eq. 5 cuts both (see the test above)."""
    beta = 0.9
    kept = np.array([4.0, 3.0, 2.0, 2.0] + [0.0] * 60)  # last share 2/11, 4/33 > 0.1 (σ, σ²)
    cut = np.array([4.0, 3.0, 2.0, 0.1] + [0.0] * 60)  # last share 0.1/9.1 < 0.1
    for sigma, expected in ((kept, 4), (cut, 3)):
        proposed = rank.select_rank(jnp.asarray(sigma, jnp.float32), beta, rule)
        assert int(rank.next_rank(4, proposed)) == expected
    assert int(rank.next_rank(4, rank.select_rank_cumulative(jnp.asarray(kept), beta))) < 4
    # iterating the truncation on a bottleneck whose spectrum is already its own fixed point
    rng = np.random.default_rng(3)
    u, _ = np.linalg.qr(rng.normal(size=(20, 20)))
    v, _ = np.linalg.qr(rng.normal(size=(20, 20)))
    w = (u[:, :4] * kept[:4]) @ v[:, :4].T
    w1, w2 = jnp.asarray(u[:, :16] * 1.0), jnp.asarray(np.linalg.pinv(u[:, :16]) @ w)
    mask = jnp.ones(16)
    for _ in range(3):
        w1, w2, mask, _, _ = truncate_bottleneck(w1, w2, mask, beta, rule)
        assert int(mask.sum()) == 4


def test_truncate_bottleneck_is_spectrum_then_reparameterise():
    rng = np.random.default_rng(4)
    w1 = jnp.asarray(rng.normal(size=(12, 8)), jnp.float32)
    w2 = jnp.asarray(rng.normal(size=(8, 10)), jnp.float32)
    mask = rank.rank_mask(6, 8)
    a1, a2, am, s, proposed = truncate_bottleneck(w1, w2, mask, 0.7)
    u, s2, vt = rank.spectrum(w1, w2, mask)
    b1, b2, bm = rank.reparameterise(u, s2, vt, rank.next_rank(6, proposed))
    for x, y in ((a1, b1), (a2, b2), (am, bm), (s, s2)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    assert np.all(np.asarray(s)[6:] < 1e-5)  # rank 6: the masked components are zero


def test_relative_error_and_retain_clause():
    ref = jnp.asarray([3.0, 4.0])
    assert float(rank.relative_error(jnp.asarray([3.0, 4.5]), ref)) == pytest.approx(0.1)
    assert float(rank.relative_error(jnp.zeros(2), jnp.zeros(2))) == 0.0
    assert np.isinf(float(rank.relative_error(jnp.ones(2), jnp.zeros(2))))
    old, cand = jnp.asarray([10, 10, 10]), jnp.asarray([7, 7, 10])
    err = jnp.asarray([0.01, 0.2, jnp.nan])
    np.testing.assert_array_equal(np.asarray(rank.retain_or_cut(old, cand, err, 0.05)), [7, 10, 10])
    np.testing.assert_array_equal(np.asarray(rank.retain_or_cut(old, cand, err, None)), [7, 7, 10])


def test_svd_under_vmap_is_the_batched_svd_bit_for_bit():
    x = jnp.asarray(np.random.default_rng(5).normal(size=(3, 2, 16, 12)), jnp.float32)
    batched = jax.jit(jax.vmap(jax.vmap(lambda a: jnp.linalg.svd(a, full_matrices=False))))(x)
    sequential = jax.jit(jax.vmap(jax.vmap(rank.svd)))(x)
    for a, b in zip(batched, sequential):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


STRESS = """
from adarl.runtime import configure_xla
import os; os.environ.pop("XLA_FLAGS", None); configure_xla(cpus=2)
import jax, jax.numpy as jnp, numpy as np
from adarl.nets import rank
def f(x):  # a vmapped SVD and an independent one, as the truncation of actor and critics
    s = jax.vmap(jax.vmap(rank.svd))(x)[1]
    return s.sum() + rank.svd(x[0, 0] @ x[1, 1])[1].sum()
g = jax.jit(f)
devices = jax.devices()
xs = [jax.device_put(np.ones((3, 2, 32, 32), np.float32) + i, devices[i % len(devices)]) for i in range(2)]
for _ in range(20):
    [o.block_until_ready() for o in [g(x) for x in xs]]
print("done")
"""


def _svd_operands(jaxpr, found: list) -> list:
    """The operand shapes of every `svd` in a jaxpr, nested ones (scan, jit, custom_vmap) too."""
    for eqn in jaxpr.eqns:
        if eqn.primitive.name == "svd":
            found.append(tuple(eqn.invars[0].aval.shape))
        for param in eqn.params.values():
            for sub in param if isinstance(param, list | tuple) else [param]:
                inner = getattr(sub, "jaxpr", sub)
                if hasattr(inner, "eqns"):
                    _svd_operands(inner, found)
    return found


def test_concurrent_truncations_on_two_devices_do_not_deadlock():
    """jaxlib's batched CPU SVD waits on the thread pool it runs in; two at once on two devices
    hung the trainer (`rank.svd` runs batches sequentially instead). The proof: under (nested)
    vmap every SVD the trainer computes is of one matrix, never a batch (jnp.linalg.svd's own
    vmap would give one of shape (3, 8, 8)); and two devices running them at once finish."""
    import subprocess
    import sys

    batched = jax.make_jaxpr(jax.vmap(jax.vmap(rank.svd)))(jnp.ones((3, 2, 8, 8)))
    assert _svd_operands(batched.jaxpr, []) == [(8, 8)]
    plain = jax.make_jaxpr(jax.vmap(lambda m: jnp.linalg.svd(m, full_matrices=False)))
    assert _svd_operands(plain(jnp.ones((3, 8, 8))).jaxpr, []) == [(3, 8, 8)]  # what it avoids
    out = subprocess.run(
        [sys.executable, "-c", STRESS], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0 and "done" in out.stdout, out.stderr[-2000:]


def test_the_retain_clause_keeps_the_old_rank_when_the_error_is_nan():
    old, cand = jnp.asarray([10, 10, 10, 10]), jnp.asarray([6, 6, 6, 6])
    err = jnp.asarray([jnp.nan, jnp.inf, 0.05, 0.0500001])
    kept = rank.retain_or_cut(old, cand, err, 0.05)
    np.testing.assert_array_equal(np.asarray(kept), [10, 10, 6, 10])  # NaN fails the test
    jitted = jax.jit(lambda o, c, e: rank.retain_or_cut(o, c, e, 0.05))(old, cand, err)
    np.testing.assert_array_equal(np.asarray(jitted), [10, 10, 6, 10])


# Exact ties (Σ share = β, or σ_ℓ/σ_1 = β): spectra of small integers whose cumulative shares are
# dyadic fractions, so float32 computes them exactly and the rule's ≤ / ≥ / < decides. Expected
# ranks worked out by hand from each rule's definition (see the reference functions above).
TIES = [
    # (rule, sigma, beta, expected r̂)
    ("energy", [1, 1, 1, 1], 0.5, 2),  # shares .25 .5 .75 1: the first ≥ .5 is ℓ = 2
    ("energy", [1, 1, 1, 1], 0.75, 3),
    ("energy", [2, 1, 1], 0.5, 1),  # shares .5 .75 1
    ("energy", [3, 1], 0.75, 1),  # shares .75 1
    ("energy", [1, 1, 1, 1, 0, 0, 0, 0], 0.75, 3),
    ("energy-squared", [1, 1, 1, 1], 0.5, 2),  # σ² shares .25 .5 .75 1
    ("energy-squared", [2, 1, 1, 1, 1], 0.75, 3),  # σ² = 4 1 1 1 1: shares .5 .625 .75 …
    ("energy-squared", [2, 1, 1, 1, 1], 0.5, 1),
    ("cumulative", [1, 1, 1, 1], 0.5, 2),  # Eq. 5: the longest prefix with share ≤ .5
    ("cumulative", [1, 1, 1, 1], 0.75, 3),
    ("cumulative", [2, 1, 1], 0.5, 1),
    ("cumulative", [3, 1], 0.75, 1),
    ("ratio", [4, 2, 1], 0.5, 2),  # Eq. 7: σ_2/σ_1 = .5 ≤ .5
    ("ratio", [4, 2, 1], 0.25, 3),  # σ_3/σ_1 = .25
    ("ratio", [4, 4, 2, 2], 0.5, 3),
]


@pytest.mark.parametrize("rule, sigma, beta, expected", TIES)
def test_rules_at_an_exact_tie(rule, sigma, beta, expected):
    s = np.asarray(sigma, np.float32)
    mass = s.astype(np.float64) ** (2 if rule == "energy-squared" else 1)
    shares = np.cumsum(mass) / mass.sum()
    assert beta in shares or rule == "ratio"  # a tie indeed (exact in float32 and float64)
    assert int(rank.select_rank(jnp.asarray(s), beta, rule)) == expected
    # under jit and vmap too (the trainer's path)
    batched = jax.jit(jax.vmap(lambda x: rank.select_rank(x, beta, rule)))(jnp.stack([s, s]))
    assert np.asarray(batched).tolist() == [expected, expected]
