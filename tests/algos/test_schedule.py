"""The one schedule (`adarl.algos.schedule`): the learning-rate formulas (on the device with
`jax.numpy`, and with NumPy), the truncation steps and the counters the jitted update carries."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import schedule
from adarl.algos.rnac_config import PRESETS as RNAC_PRESETS
from adarl.algos.rnac_config import RNACConfig
from adarl.algos.sac_config import PRESETS, SAC_FAMILY, SACConfig


def test_restart_schedule_boundaries():
    lr, w, total, m = 3e-3, 2000, 10_000, 0.1
    f = lambda t: float(schedule.restart_learning_rate(t, lr, w, total, m, jnp))  # noqa: E731
    assert f(0) == 0.0
    assert f(1000) == pytest.approx(lr / 2)
    assert f(1999) == pytest.approx(lr * 1999 / 2000)
    assert f(2000) == pytest.approx(lr)  # warm-up ends at the target
    assert f(6000) == pytest.approx(lr * (m + (1 - m) * 0.5))  # half-way through the cosine
    assert f(10_000) == pytest.approx(lr * m)  # end of the iteration: the floor
    assert f(50_000) == pytest.approx(lr * m)
    values = [f(t) for t in range(2000, 10_001, 500)]
    assert all(a >= b for a, b in zip(values, values[1:]))  # cosine only decreases


def np_envelope(t, start, base, w, total, m, warm_up):
    env = lambda x: base * (m + (1 - m) * 0.5 * (1 + np.cos(np.pi * min(1.0, x / total))))  # noqa: E731
    if warm_up and t - start < w:
        return env(start + w) * (t - start) / w
    return env(t)


def test_envelope_schedule_matches_relora_reference():
    base, w, total, m = 3e-3, 2000, 100_000, 0.1
    for start in (0, 20_000, 61_000):
        for t in range(start, start + 30_000, 250):
            for warm_up in (False, True):
                got = float(
                    schedule.envelope_learning_rate(t, start, base, w, total, m, warm_up, jnp)
                )
                assert got == pytest.approx(np_envelope(t, start, base, w, total, m, warm_up))
    f = lambda t, s: float(schedule.envelope_learning_rate(t, s, base, w, total, m, True, jnp))  # noqa: E731
    assert f(20_000, 20_000) == 0.0  # each reset warms up from zero …
    assert f(22_000, 20_000) == pytest.approx(np_envelope(22_000, 0, base, w, total, m, False))
    assert f(100_000, 61_000) == pytest.approx(base * m)  # … to one envelope that ends at the floor
    later = [f(t, 20_000) for t in range(22_000, 100_001, 1000)]
    assert all(a >= b for a, b in zip(later, later[1:]))


def _adarl(**values) -> SACConfig:
    return SACConfig(**{**SAC_FAMILY["adarl"], **PRESETS["smoke"], "task": "hopper", **values})


def test_truncation_steps_follow_the_chunks():
    config = _adarl()  # 2,000 steps, updates from 500 in chunks of 50, d_t 500
    assert schedule.truncation_steps(config) == [950, 1450, 1950]
    assert schedule.truncation_updates(config) == [500, 1000, 1500]
    assert schedule.total_updates(config) == 1550
    assert schedule.chunk_end(config, 950) == 1000 and schedule.chunk_end(config, 1990) == 2000
    assert not schedule.chunk_updates(config, 450) and schedule.chunk_updates(config, 500)
    assert schedule.truncation_steps(dataclasses.replace(config, adapt_rank=False)) == []
    assert schedule.truncation_steps(RNACConfig(**RNAC_PRESETS["smoke"])) == []


def test_counters_are_the_updates_after_each_truncation():
    c = schedule.counters(_adarl(), np.array([0, 499, 500, 1499, 1500, 1549]))
    assert c["n_truncations"].tolist() == [0, 0, 1, 2, 3, 3]
    assert c["iteration_start"].tolist() == [0, 0, 500, 1000, 1500, 1500]


@pytest.mark.parametrize("name", ["envelope", "restart"])
@pytest.mark.parametrize("first", [False, True])
def test_numpy_and_the_device_give_the_same_learning_rate(name, first):
    config = _adarl(lr_schedule=name, schedule_first_iteration=first)
    state = schedule.counters(config, np.arange(0, 1550, 7))
    host = schedule.learning_rate(config, 3e-4, state)
    device = schedule.learning_rate(
        config, 3e-4, {k: jnp.asarray(v) for k, v in state.items()}, jnp
    )
    np.testing.assert_allclose(np.asarray(host), np.asarray(device), rtol=1e-6)
    constant = schedule.learning_rate(dataclasses.replace(config, adapt_rank=False), 3e-4, state)
    assert float(constant) == np.float32(3e-4)


def test_rnac_learning_rate_decays_from_the_previous_update():
    config = RNACConfig(**RNAC_PRESETS["smoke"])  # 2,048 steps, rollouts of 256
    assert schedule.rnac_learning_rate(config, 256) == config.lr
    assert schedule.rnac_learning_rate(config, 2048) == config.lr * (1 - 1792 / 2048)
    assert (
        schedule.rnac_learning_rate(dataclasses.replace(config, lr_decay=False), 2048) == config.lr
    )
