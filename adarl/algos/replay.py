"""Device-resident replay buffer that stores each observation once.

Rows form a stream: row i holds (obs_i, act_i, rew_i, term_i, valid_i) and the next observation of
the transition starting at row i is the observation of row i+1 (ring order). When an episode ends,
an extra *pseudo-row* holding only the final observation follows its last transition, with
`valid = 0`, so time-limit truncations keep their true next observation (needed for bootstrapping)
without storing next observations twice. Memory per row: 4·(obs_dim + act_dim + 1) + 2 bytes
(Humanoid-v5 at 10⁶ rows: 1.47 GB).

The host appends rows in chunks (`append_rows`): every chunk ends with a *provisional* row holding
the observation the next action will be taken from (valid = 0); the next chunk starts by
overwriting it with the full row. Sampling draws rows uniformly among those written and rejects
invalid ones (pseudo and provisional rows), redrawing up to `REDRAWS` times; a row still invalid
after that (probability ≈ (episodes/rows)^5) falls back to the nearest valid row before it.
All functions are pure and jit/vmap-friendly; `capacity` is static (from array shapes).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

REDRAWS = 4


def row_bytes(obs_dim: int, act_dim: int) -> int:
    """Bytes per buffer row: float32 obs, act and rew, uint8 term and valid (`init_buffer`)."""
    return 4 * (obs_dim + act_dim + 1) + 2


def init_buffer(capacity: int, obs_dim: int, act_dim: int) -> dict:
    """An empty buffer (NumPy arrays; they move to the device with the rest of the state)."""
    return {
        "obs": np.zeros((capacity, obs_dim), np.float32),
        "act": np.zeros((capacity, act_dim), np.float32),
        "rew": np.zeros((capacity,), np.float32),
        "term": np.zeros((capacity,), np.uint8),
        "valid": np.zeros((capacity,), np.uint8),
        "ptr": np.zeros((), np.int32),  # where the next chunk starts (its provisional row)
        "size": np.zeros((), np.int32),  # rows written, excluding the provisional one
    }


def empty_buffers(n_seeds: int, capacity: int, obs_dim: int, act_dim: int) -> dict:
    """`n_seeds` empty buffers stacked on axis 0, allocated on the device directly."""
    template = init_buffer(1, obs_dim, act_dim)
    return {
        k: jnp.zeros((n_seeds, capacity, *v.shape[1:]) if v.ndim else (n_seeds,), v.dtype)
        for k, v in template.items()
    }


def append_rows(buf: dict, rows: dict, n_rows: jnp.ndarray) -> dict:
    """Write the first `n_rows` of the padded `rows` (obs, act, rew, term, valid; leading axis =
    max rows) starting at `ptr`. The last written row is provisional: `ptr` advances by
    `n_rows − 1` so the next chunk overwrites it."""
    capacity = buf["obs"].shape[0]
    max_rows = rows["obs"].shape[0]
    offsets = jnp.arange(max_rows)
    idx = jnp.where(offsets < n_rows, (buf["ptr"] + offsets) % capacity, capacity)  # pad -> dropped
    out = dict(buf)
    for name in ("obs", "act", "rew", "term", "valid"):
        out[name] = buf[name].at[idx].set(rows[name].astype(buf[name].dtype), mode="drop")
    committed = n_rows - 1
    out["ptr"] = (buf["ptr"] + committed) % capacity
    out["size"] = jnp.minimum(buf["size"] + committed, capacity)
    return out


def sample_indices(buf: dict, key: jnp.ndarray, batch_size: int) -> jnp.ndarray:
    """Uniform indices of valid transition rows among those written."""
    capacity = buf["obs"].shape[0]
    high = jnp.maximum(buf["size"], 1)
    keys = jax.random.split(key, REDRAWS)
    idx = jax.random.randint(keys[0], (batch_size,), 0, high)
    for k in keys[1:]:
        redraw = jax.random.randint(k, (batch_size,), 0, high)
        idx = jnp.where(buf["valid"][idx] == 1, idx, redraw)
    # a pseudo-row follows a valid row; the provisional row may follow a pseudo-row
    prev = (idx - 1) % capacity
    fallback = jnp.where(buf["valid"][prev] == 1, prev, (idx - 2) % capacity)
    return jnp.where(buf["valid"][idx] == 1, idx, fallback)


def sample(buf: dict, key: jnp.ndarray, batch_size: int) -> dict:
    """A minibatch {obs, act, rew, next_obs, done} of transitions."""
    capacity = buf["obs"].shape[0]
    idx = sample_indices(buf, key, batch_size)
    return {
        "obs": buf["obs"][idx],
        "act": buf["act"][idx],
        "rew": buf["rew"][idx],
        "next_obs": buf["obs"][(idx + 1) % capacity],
        "done": buf["term"][idx].astype(jnp.float32),
    }


class ChunkBuilder:
    """Host-side collector of one chunk of rows per seed, padded for `append_rows`."""

    def __init__(self, n_seeds: int, max_steps: int, obs_dim: int, act_dim: int):
        max_rows = 2 * max_steps + 1  # every step may end an episode, plus the provisional row
        self.obs = np.zeros((n_seeds, max_rows, obs_dim), np.float32)
        self.act = np.zeros((n_seeds, max_rows, act_dim), np.float32)
        self.rew = np.zeros((n_seeds, max_rows), np.float32)
        self.term = np.zeros((n_seeds, max_rows), np.uint8)
        self.valid = np.zeros((n_seeds, max_rows), np.uint8)
        self.n = np.zeros((n_seeds,), np.int32)

    def clear(self) -> None:
        self.valid[:] = 0
        self.n[:] = 0

    def add(self, seed_idx: int, obs, act, rew, term, next_obs, episode_ended: bool) -> None:
        """Add the transition (obs, act, rew, term); if the episode ended, also its final obs."""
        i = self.n[seed_idx]
        self.obs[seed_idx, i] = obs
        self.act[seed_idx, i] = act
        self.rew[seed_idx, i] = rew
        self.term[seed_idx, i] = term
        self.valid[seed_idx, i] = 1
        i += 1
        if episode_ended:
            self.obs[seed_idx, i] = next_obs
            self.act[seed_idx, i] = 0.0
            self.rew[seed_idx, i] = 0.0
            self.term[seed_idx, i] = 0
            self.valid[seed_idx, i] = 0
            i += 1
        self.n[seed_idx] = i

    def close(self, seed_idx: int, current_obs) -> None:
        """End the chunk with the provisional row: the observation the next action starts from."""
        i = self.n[seed_idx]
        self.obs[seed_idx, i] = current_obs
        self.act[seed_idx, i] = 0.0
        self.rew[seed_idx, i] = 0.0
        self.term[seed_idx, i] = 0
        self.valid[seed_idx, i] = 0
        self.n[seed_idx] = i + 1

    def rows(self) -> tuple[dict, np.ndarray]:
        """Copies of the chunk's rows. JAX may read a host array after the call that was given
        it returns (when the device is busy), so the builder's own arrays, which the next chunk
        overwrites, must not be handed over."""
        return (
            {
                "obs": self.obs.copy(),
                "act": self.act.copy(),
                "rew": self.rew.copy(),
                "term": self.term.copy(),
                "valid": self.valid.copy(),
            },
            self.n.copy(),
        )
