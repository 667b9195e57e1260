"""Rank rules, SVD truncation and the restart schedule against NumPy references."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

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
    new_w1, new_w2, new_mask, sigma, proposed = rank.truncate_bottleneck(
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
    new_w1, new_w2, new_mask, sigma, _ = rank.truncate_bottleneck(
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
    _, _, new_mask, sigma, proposed = rank.truncate_bottleneck(
        jnp.asarray(w1), jnp.asarray(w2), jnp.asarray(mask), 0.999999
    )
    assert int(new_mask.sum()) <= 10  # rank never grows
    assert np.all(np.asarray(sigma)[10:] < 1e-3)  # a rank-10 product has 10 non-zero values


def test_truncation_vmaps_with_per_seed_ranks():
    parts = [random_factors(s, rank_=r) for s, r in [(0, 64), (1, 20), (2, 5)]]
    w1 = jnp.stack([p[0] for p in parts])
    w2 = jnp.stack([p[1] for p in parts])
    mask = jnp.stack([p[2] for p in parts])
    out = jax.vmap(lambda a, b, m: rank.truncate_bottleneck(a, b, m, 0.98))(w1, w2, mask)
    ranks = np.asarray(out[2].sum(axis=1))
    assert ranks[1] <= 20 and ranks[2] <= 5 and ranks[0] <= 64


def test_restart_schedule_boundaries():
    lr, w, total, m = 3e-3, 2000, 10_000, 0.1
    f = lambda t: float(rank.restart_learning_rate(t, lr, w, total, m))  # noqa: E731
    assert f(0) == 0.0
    assert f(1000) == pytest.approx(lr / 2)
    assert f(1999) == pytest.approx(lr * 1999 / 2000)
    assert f(2000) == pytest.approx(lr)  # warm-up ends at the target
    assert f(6000) == pytest.approx(lr * (m + (1 - m) * 0.5))  # half-way through the cosine
    assert f(10_000) == pytest.approx(lr * m)  # end of the iteration: the floor
    assert f(50_000) == pytest.approx(lr * m)
    values = [f(t) for t in range(2000, 10_001, 500)]
    assert all(a >= b for a, b in zip(values, values[1:]))  # cosine only decreases
