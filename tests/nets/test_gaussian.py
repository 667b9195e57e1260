"""The diagonal Gaussian shared by SAC and RNAC, against a NumPy reference."""

import numpy as np

from adarl.nets import gaussian


def test_gaussian_log_prob_and_entropy():
    rng = np.random.default_rng(2)
    a, mean = rng.standard_normal((2, 7, 3))
    log_std = rng.standard_normal(3) * 0.5
    std = np.exp(log_std)
    ref = np.sum(-((a - mean) ** 2) / (2 * std**2) - np.log(std) - 0.5 * np.log(2 * np.pi), -1)
    np.testing.assert_allclose(gaussian.gaussian_log_prob(a, mean, log_std), ref, rtol=1e-5)
    np.testing.assert_allclose(gaussian.gaussian_log_prob(a, mean, log_std, np), ref, rtol=1e-12)
    np.testing.assert_allclose(
        gaussian.gaussian_entropy(log_std),
        np.sum(0.5 * np.log(2 * np.pi * np.e * std**2)),
        rtol=1e-5,
    )
