"""SAC's training chunk on a device task (`adarl.device`), as pure JAX functions of one seed; the
device learner (`adarl.train.device_learner`) `vmap`s them over a run's seeds and jits them.

A chunk is Spinning Up's schedule, the shape of Brax's SAC training epoch: `lax.scan` over
`n_steps` environment steps (act, step the task, reset it where an episode ended, append the
step's rows to the replay buffer), then `update_every` gradient steps of `adarl.algos.sac`
(`lax.scan`). The rank masks live in the SAC state (`state["masks"]`), so seeds whose ranks
differ share one shape; `sac.truncate` cuts them by SVD of the masked factors.

The environment side of a seed is a dict (`init_env`): the task state, the observation the next
action is taken from, the running return and length, the episode index and the seed's key of
actions and resets. Per-episode physics is a table of `mjx.Model` leaves (dotted name -> array
whose first axis is the episode): episode e runs with row e mod (rows) (`episode_fields`); an
empty table is the task's own model.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from adarl.algos import replay, sac


def env_key(seed: int) -> np.ndarray:
    """Raw threefry key of a seed's actions and resets: [1, seed], a stream apart from the
    update's [0, seed] (`sac.update_key`)."""
    return np.array([1, seed], np.uint32)


def episode_fields(table: dict, episode) -> dict:
    """The model fields of episode `episode`: row `episode` mod (rows) of every table entry."""
    return {
        name: jnp.take(rows, episode % rows.shape[0], axis=0, mode="clip")
        for name, rows in table.items()
    }


def init_env(task, key, table: dict) -> dict:
    """A seed's environment side at the start of its first episode (episode 0)."""
    key, k_reset = jax.random.split(key)
    state = task.reset(k_reset, episode_fields(table, 0))
    return {
        "task": state,
        "obs": task.observation(state.data).astype(jnp.float32),
        "ep_return": jnp.zeros((), jnp.float32),
        "ep_length": jnp.zeros((), jnp.int32),
        "episode": jnp.zeros((), jnp.int32),
        "key": key,
    }


def choose_action(spec: sac.Spec, state: dict, obs, key, t):
    """The action of environment step `t` (1-based): uniform over the action box before
    `start_steps`, then a = c + h·tanh(μ + σε) from the current actor (`sac.sample_action`)."""
    low, high = jnp.asarray(spec.act_low), jnp.asarray(spec.act_high)
    uniform = jax.random.uniform(key, low.shape, jnp.float32, low, high)
    sampled, _ = sac.sample_action(spec, state["actor"], state["masks"]["actor"], obs[None], key)
    return jnp.where(t - 1 < spec.config.start_steps, uniform, sampled[0])


def step_rows(obs, action, reward, terminated, next_obs, start_obs) -> dict:
    """The replay rows of one environment step (`replay.append_rows`, rows as the host's
    `ChunkBuilder` writes them): the transition, then a row holding `next_obs` (the pseudo-row
    of an ended episode, else the provisional row), then the provisional row `start_obs` of the
    next episode (written only when the episode ended: 2 + done rows)."""
    zeros_act = jnp.zeros_like(action)
    return {
        "obs": jnp.stack([obs, next_obs, start_obs]),
        "act": jnp.stack([action, zeros_act, zeros_act]),
        "rew": jnp.stack([reward, 0.0, 0.0]).astype(jnp.float32),
        "term": jnp.stack([terminated, False, False]).astype(jnp.uint8),
        "valid": jnp.array([1, 0, 0], jnp.uint8),
    }


def env_step(spec: sac.Spec, task, table: dict, state: dict, env: dict, t):
    """Environment step `t` of one seed: act, step the task, append the rows, reset where the
    episode ended (terminated, or `max_episode_steps` reached). Returns the new buffer, the new
    environment side and what ended: (done, return, length, episode index)."""
    c = spec.config
    key, k_act, k_reset = jax.random.split(env["key"], 3)
    action = choose_action(spec, state, env["obs"], k_act, t)
    task_state, next_obs, reward, terminated, _ = task.step(env["task"], action)
    next_obs = next_obs.astype(jnp.float32)
    reward = reward.astype(jnp.float32)
    ep_return, ep_length = env["ep_return"] + reward, env["ep_length"] + 1
    done = terminated | (ep_length >= c.max_episode_steps)
    episode = env["episode"] + done.astype(jnp.int32)
    fresh = task.reset(k_reset, episode_fields(table, episode))
    task_state = jax.tree_util.tree_map(
        lambda new, old: jnp.where(done, new, old), fresh, task_state
    )
    start_obs = jnp.where(done, task.observation(fresh.data).astype(jnp.float32), next_obs)
    rows = step_rows(env["obs"], action, reward, terminated, next_obs, start_obs)
    buffer = replay.append_rows(state["buffer"], rows, 2 + done.astype(jnp.int32))
    ended = (done, ep_return, ep_length, env["episode"])
    env = {
        "task": task_state,
        "obs": start_obs,
        "ep_return": jnp.where(done, 0.0, ep_return),
        "ep_length": jnp.where(done, 0, ep_length),
        "episode": episode,
        "key": key,
    }
    return buffer, env, ended


def chunk(spec: sac.Spec, task, n_steps: int, state: dict, env: dict, table: dict, step, update):
    """One chunk of a seed: environment steps `step` + 1 … `step` + `n_steps` (`lax.scan`), then,
    if `update` (a traced bool shared by the seeds), `update_every` gradient steps
    (`sac.update_step`, `lax.scan`). Returns the state, the environment side, what ended at each
    step ((n_steps,) arrays: done, return, length, episode) and the update metrics averaged over
    the gradient steps (zeros when `update` is false)."""

    def one_step(carry, t):
        state, env = carry
        buffer, env, ended = env_step(spec, task, table, state, env, t)
        return (dict(state, buffer=buffer), env), ended

    ts = step + 1 + jnp.arange(n_steps, dtype=jnp.int32)
    (state, env), ended = jax.lax.scan(one_step, (state, env), ts)

    def learn(state):
        state, infos = jax.lax.scan(
            lambda s, _: sac.update_step(spec, s), state, None, length=spec.config.update_every
        )
        return state, jax.tree_util.tree_map(jnp.mean, infos)

    def skip(state):
        info = jax.eval_shape(learn, state)[1]
        return state, jax.tree_util.tree_map(lambda x: jnp.zeros(x.shape, x.dtype), info)

    state, info = jax.lax.cond(update, learn, skip, state)
    return state, env, ended, info
