"""The policy file (adarl.policy): what its one writer, `file_arrays`, writes, the reader runs
as the format says."""

import numpy as np
import pytest

from adarl.policy import NumpyPolicy, file_arrays, load, save


def test_every_layer_kind_written_is_read_back_as_the_format_says(tmp_path):
    rng = np.random.default_rng(0)
    w0, b0 = rng.standard_normal((3, 5)), rng.standard_normal(5)
    w1, w2, b1 = rng.standard_normal((5, 2)), rng.standard_normal((2, 5)), rng.standard_normal(5)
    d = np.eye(5) + 0.1 * rng.standard_normal((5, 5))
    mean_w, mean_b = rng.standard_normal((5, 2)), rng.standard_normal(2)
    log_w, log_b = rng.standard_normal((5, 2)), rng.standard_normal(2)
    low, high = np.array([-2.0, 0.0]), np.array([2.0, 1.0])
    norm = (np.array([0.5, -1.0, 2.0]), np.array([4.0, 1.0, 0.25]), 3.0)
    layers = [("dense", w0, b0), ("bottleneck", w1, w2, b1), ("sparse", d, 0.1, 0.2)]
    arrays = file_arrays(
        layers, (mean_w, mean_b), low, high, "relu", log_std=(log_w, log_b), obs_norm=norm,
        n_params_full=True,
    )  # fmt: skip
    save(tmp_path / "p.npz", arrays)
    policy = load(tmp_path / "p.npz")

    obs = rng.standard_normal((4, 3)) * 3
    x = np.clip((obs - norm[0]) / np.sqrt(norm[1] + 1e-8), -3.0, 3.0)
    x = np.maximum(x @ w0 + b0, 0)
    x = np.maximum(x @ w1 @ w2 + b1, 0)
    x = np.maximum(x + 0.1 * (x @ d - x @ d.T @ d) - 0.1 * 0.2, 0)
    centre, half = (low + high) / 2, (high - low) / 2
    np.testing.assert_allclose(policy(obs), centre + half * np.tanh(x @ mean_w + mean_b), rtol=1e-5)
    noise = rng.standard_normal((4, 2))
    log_std = np.clip(x @ log_w + log_b, -20, 2)
    np.testing.assert_allclose(
        policy.sample(obs, noise),
        centre + half * np.tanh(x @ mean_w + mean_b + np.exp(log_std) * noise),
        rtol=1e-5,
    )
    stored = 15 + 5 + 10 + 10 + 5 + 25 + 10 + 2  # dense, bottleneck, dictionary, mean head
    assert policy.n_params() == stored
    assert int(arrays["n_params_full"]) == stored - 20 + 25 + 25  # W1·W2 at its full 5 × 5


def test_optional_parts_are_left_out():
    arrays = file_arrays([("dense", np.ones((2, 3)), np.zeros(3))], (np.ones((3, 1)), [0.0]),
                         [-1.0], [1.0], "tanh")  # fmt: skip
    assert {"log_std_w", "obs_mean", "n_params_full"}.isdisjoint(arrays)
    with pytest.raises(ValueError, match="no log-std head"):
        NumpyPolicy(arrays).sample(np.ones(2), np.ones(1))
