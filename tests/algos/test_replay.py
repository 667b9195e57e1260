"""The replay buffer stores each observation once and samples only real transitions."""

import jax
import jax.numpy as jnp
import numpy as np

from adarl.algos import replay


def fill(capacity, episodes, obs_dim=3, act_dim=2, chunk=7):
    """Stream `episodes` (lists of lengths) through ChunkBuilder/append_rows like the trainer.
    Observations encode (episode, t) so next-observation correctness can be checked."""
    buf = replay.init_buffer(capacity, obs_dim, act_dim)
    builder = replay.ChunkBuilder(1, chunk, obs_dim, act_dim)
    append = jax.jit(replay.append_rows)
    transitions = []
    steps = 0
    obs = np.array([0, 0, 1], np.float32)
    for e, length in enumerate(episodes):
        for t in range(length):
            nxt = np.array([e, t + 1, 1], np.float32)
            done = t == length - 1
            builder.add(0, obs, np.array([e, t], np.float32), float(10 * e + t), done, nxt, done)
            transitions.append((obs.copy(), nxt.copy(), float(10 * e + t)))
            obs = np.array([e + 1, 0, 1], np.float32) if done else nxt
            steps += 1
            if steps % chunk == 0:
                builder.close(0, obs)
                rows, n = builder.rows()
                buf = append(buf, {k: jnp.asarray(v[0]) for k, v in rows.items()}, n[0])
                builder.clear()
    builder.close(0, obs)
    rows, n = builder.rows()
    buf = append(buf, {k: jnp.asarray(v[0]) for k, v in rows.items()}, n[0])
    return buf, transitions


def test_next_observation_including_episode_ends():
    buf, transitions = fill(1000, [5, 3, 9, 1, 4])
    batch = replay.sample(buf, jax.random.PRNGKey(0), 4096)
    expected = {float(r): (o, n) for o, n, r in transitions}
    for obs, nxt, rew in zip(
        np.asarray(batch["obs"]), np.asarray(batch["next_obs"]), np.asarray(batch["rew"])
    ):
        o, n = expected[float(rew)]
        np.testing.assert_array_equal(obs, o)
        np.testing.assert_array_equal(nxt, n)  # true final obs at episode ends, not the reset obs
    # every transition gets sampled (uniformity is checked loosely)
    assert len(set(np.asarray(batch["rew"]).tolist())) == len(transitions)


def test_done_flag_marks_only_terminations():
    buf, _ = fill(1000, [4, 4])
    batch = replay.sample(buf, jax.random.PRNGKey(1), 512)
    rew, done = np.asarray(batch["rew"]), np.asarray(batch["done"])
    assert set(rew[done == 1].tolist()) == {3.0, 13.0}


def test_wrap_around_keeps_only_recent_valid_transitions():
    capacity = 32
    buf, transitions = fill(capacity, [6] * 20, chunk=5)
    assert int(buf["size"]) == capacity
    batch = replay.sample(buf, jax.random.PRNGKey(2), 4096)
    expected = {float(r): (o, n) for o, n, r in transitions}
    recent = {float(r) for _, _, r in transitions[-20:]}
    seen = set()
    for obs, nxt, rew in zip(
        np.asarray(batch["obs"]), np.asarray(batch["next_obs"]), np.asarray(batch["rew"])
    ):
        o, n = expected[float(rew)]
        np.testing.assert_array_equal(obs, o)
        np.testing.assert_array_equal(nxt, n)
        seen.add(float(rew))
    assert recent <= seen  # the newest transitions are all there
    assert float(transitions[0][2]) not in seen  # the oldest were overwritten


def test_sampling_is_uniform_over_transitions():
    buf, transitions = fill(10_000, [10] * 30)
    rew = np.asarray(replay.sample(buf, jax.random.PRNGKey(3), 60_000)["rew"])
    counts = np.unique(rew, return_counts=True)[1]
    assert len(counts) == 300
    expected = 60_000 / 300
    assert counts.min() > 0.6 * expected and counts.max() < 1.4 * expected


def test_humanoid_buffer_fits_in_one_and_a_half_gigabytes_per_seed():
    from adarl.envs import get_task

    task = get_task("humanoid")
    rows = 1_000
    buf = replay.init_buffer(rows, task.obs_dim, task.act_dim)
    per_row = sum(v.nbytes for v in buf.values() if v.ndim) / rows
    assert task.obs_dim == 348
    assert per_row * 1_000_000 <= 1.5e9  # 1.47 GB at 10⁶ rows: observations stored once


def test_chunk_rows_do_not_share_memory_with_the_builder():
    """JAX may copy a host array after the call that was given it returns (when the device is
    busy with another lane's update), so the rows handed over must not be the builder's arrays,
    which the next chunk overwrites."""
    builder = replay.ChunkBuilder(2, 4, 3, 2)
    builder.add(0, np.ones(3), np.ones(2), 1.0, False, np.ones(3), False)
    rows, n = builder.rows()
    owned = [builder.obs, builder.act, builder.rew, builder.term, builder.valid, builder.n]
    for array in [*rows.values(), n]:
        assert not any(np.shares_memory(array, mine) for mine in owned)
    builder.clear()
    assert rows["valid"][0, 0] == 1 and n[0] == 1


def test_row_bytes_is_what_a_buffer_allocates():
    buf = replay.init_buffer(10, 11, 3)
    per_row = sum(v.nbytes for k, v in buf.items() if k not in ("ptr", "size")) // 10
    assert replay.row_bytes(11, 3) == per_row
