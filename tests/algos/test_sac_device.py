"""The device chunk's pure parts (`adarl.algos.sac_device`) that need no MJX: the replay rows of
one environment step against the host's chunk builder, and the per-episode physics table."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import replay, sac_device
from adarl.algos.sac_config import SACConfig
from adarl.errors import UsageError

OBS, ACT = 3, 2


def test_rows_of_single_steps_fill_the_buffer_as_the_host_chunks_do():
    """Steps appended one at a time (`step_rows`, 2 + done rows each) leave the same buffer as the
    host's `ChunkBuilder` chunks of the same steps, episode ends included."""
    rng = np.random.default_rng(0)
    n_steps, capacity = 12, 64
    dones = [False, False, True, False, False, False, True, True, False, False, True, False]
    obs = rng.normal(size=(OBS,)).astype(np.float32)
    steps = []
    for done in dones:
        act = rng.normal(size=(ACT,)).astype(np.float32)
        rew, term = np.float32(rng.normal()), bool(done and rng.random() < 0.5)
        next_obs = rng.normal(size=(OBS,)).astype(np.float32)
        start = rng.normal(size=(OBS,)).astype(np.float32) if done else next_obs
        steps.append((obs, act, rew, term, next_obs, start, done))
        obs = start

    device = jax.device_put(replay.init_buffer(capacity, OBS, ACT))
    for o, a, r, term, nxt, start, done in steps:
        rows = sac_device.step_rows(o, a, r, term, nxt, start)
        device = replay.append_rows(device, rows, 2 + int(done))

    host = jax.device_put(replay.init_buffer(capacity, OBS, ACT))
    for first in range(0, n_steps, 5):  # chunks of 5, 5 and 2 steps
        builder = replay.ChunkBuilder(1, 5, OBS, ACT)
        for o, a, r, term, nxt, _start, done in steps[first : first + 5]:
            builder.add(0, o, a, r, term, nxt, done)
        builder.close(0, steps[min(first + 5, n_steps) - 1][5])
        rows, n_rows = builder.rows()
        host = replay.append_rows(host, {k: v[0] for k, v in rows.items()}, n_rows[0])

    assert int(device["size"]) == n_steps + sum(dones) == int(host["size"])
    for key in ("obs", "act", "rew", "term", "valid", "ptr", "size"):
        np.testing.assert_array_equal(np.asarray(device[key]), np.asarray(host[key]), key)


def test_episode_fields_take_the_row_of_the_episode_modulo_the_table():
    table = {"body_mass": jnp.arange(6.0).reshape(3, 2), "opt.gravity": jnp.ones((3, 3))}
    fields = sac_device.episode_fields(table, 4)  # row 4 mod 3 = 1
    np.testing.assert_array_equal(np.asarray(fields["body_mass"]), [2.0, 3.0])
    assert fields["opt.gravity"].shape == (3,)
    assert sac_device.episode_fields({}, 7) == {}


def test_update_and_action_keys_are_separate_streams():
    np.testing.assert_array_equal(sac_device.env_key(5), [1, 5])


@pytest.mark.parametrize(
    ("fields", "words"),
    [
        ({"backend": "gpu"}, "unknown backend 'gpu'; allowed: host, device"),
        (
            {"backend": "device", "task": "ant", "device_solver": "fast"},
            "device-solver must be 'xml' or 'ITERATIONS,LS_ITERATIONS'",
        ),
        (
            {"backend": "device", "dynamics": "uniform", "model_version": "v4"},
            "unknown model version for --backend device 'v4'; allowed: v5",
        ),
        (
            {"backend": "device", "dynamics": "default", "algo": "sac-sparse"},
            "unknown algo for --backend device 'sac-sparse'",
        ),
        (
            {"backend": "device", "dynamics": "nominal", "physics": "ompo"},
            "unknown physics for --backend device 'ompo'; allowed: consistent",
        ),
    ],
)
def test_device_backend_refuses_what_it_cannot_train(fields, words):
    with pytest.raises(UsageError, match=words.replace("(", r"\(")):
        SACConfig(**{"algo": "sac", **fields}).validate()


def test_host_backend_is_the_default():
    assert SACConfig().validate().backend == "host"


@pytest.mark.parametrize(
    ("task", "dynamics"),
    [("hopper", "paper"), ("hopper", "ompo:foot_length=0.3"), ("walker2d", "uniform")],
)
def test_device_backend_takes_the_per_episode_schedules(task, dynamics):
    config = SACConfig(algo="sac", backend="device", task=task, dynamics=dynamics).validate()
    assert (config.task, config.dynamics) == (task, dynamics)
