"""SAC's training chunk on a device task (`adarl.device`), every seed of a run at once: the device
learner (`adarl.train.device_learner`) jits `chunk` and `evaluate`; every array carries the
seeds on its leading axis, each seed's arithmetic `vmap`ped.

A chunk is Spinning Up's schedule, the shape of Brax's SAC training epoch: `lax.scan` over
`n_steps` environment steps (act, step the task, reset it where an episode ended, append the
step's rows to the replay buffer), then `update_every` gradient steps of `adarl.algos.sac`
(`lax.scan`). The rank masks live in the SAC state (`state["masks"]`), so seeds whose ranks
differ share one shape; `sac.truncate` cuts them by SVD of the masked factors.

Resets come from a pool drawn once per chunk (`reset_pool`): the reset states of each seed's
next `POOL` episodes, computed before the steps in one vmapped ``mjx.forward``, so that an
environment step costs its `frame_skip` physics steps and nothing more (a reset computed for
every seed at every step, kept only where an episode ended, was a fifth solve per step). A seed
that ends more than `POOL` episodes in one chunk takes the next from a reset of every seed
computed at that step, under a `lax.cond` on whether any seed needs one (free where none does).
Either way episode e's reset is ``task.reset(fold_in(k, e), fields(e))``, k the chunk's reset
key (split from the seed's key at the chunk's start; `episode_reset`).

The environment side of a seed is a dict (`init_env`): the task state, the observation the next
action is taken from, the running return and length, the episode index and the seed's key of
actions and resets. Per-episode physics is a table of `mjx.Model` leaves (dotted name -> array
whose first axis is the episode): episode e runs with row e mod (rows) (`episode_fields`); an
empty table is the task's own model.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from adarl.algos import replay, sac

#: Reset states drawn per seed at the start of each chunk (episodes e+1 … e+POOL of a seed whose
#: episode e is running): more than the episodes that end in a 50-step chunk once a policy
#: stands, so the fallback reset of every seed (one more solve at that step) is rare.
POOL = 4


def env_key(seed: int) -> np.ndarray:
    """Raw threefry key of a seed's actions and resets: [1, seed], a stream apart from the
    update's [0, seed] (`sac.update_key`)."""
    return np.array([1, seed], np.uint32)


def eval_key(seed: int) -> np.ndarray:
    """Raw threefry key of a seed's device evaluation resets: [2, 1,000,000 + seed] (the host
    evaluation's seed is 1,000,000 + seed); episode k's reset key is ``fold_in(key, k)``."""
    return np.array([2, 1_000_000 + seed], np.uint32)


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


def episode_reset(task, table: dict, key, episode):
    """One seed's reset state of episode `episode` and its observation:
    ``task.reset(fold_in(key, episode), fields(episode))``."""
    state = task.reset(jax.random.fold_in(key, episode), episode_fields(table, episode))
    return state, task.observation(state.data).astype(jnp.float32)


def reset_pool(task, table: dict, key, episode, size: int):
    """One seed's reset states and observations of episodes `episode` + 1 … `episode` + `size`
    (`episode_reset`), stacked along a leading axis."""
    episodes = episode + 1 + jnp.arange(size, dtype=jnp.int32)
    return jax.vmap(functools.partial(episode_reset, task, table, key))(episodes)


def select(flags, new, old):
    """`new` where `flags` ((seeds,) booleans), else `old`, leaf by leaf (seeds leading)."""

    def one(a, b):
        return jnp.where(flags.reshape(flags.shape + (1,) * (a.ndim - flags.ndim)), a, b)

    return jax.tree_util.tree_map(one, new, old)


def act_and_step(spec: sac.Spec, task, state: dict, env: dict, t):
    """One seed's environment step `t` up to the task step: the key after it, the action, the
    task state, the next observation, the reward and whether it terminated."""
    key, k_act = jax.random.split(env["key"])
    action = choose_action(spec, state, env["obs"], k_act, t)
    task_state, next_obs, reward, terminated, _ = task.step(env["task"], action)
    return (
        key,
        action,
        task_state,
        next_obs.astype(jnp.float32),
        reward.astype(jnp.float32),
        terminated,
    )


def chunk(spec: sac.Spec, task, n_steps: int, states: dict, envs: dict, table: dict, step, update):
    """One chunk of every seed (leading axis): environment steps `step` + 1 … `step` + `n_steps`
    (`lax.scan`), resets from the chunk's pool (the module's docstring), then, if `update` (a
    traced bool shared by the seeds), `update_every` gradient steps per seed (`sac.update_step`,
    `lax.scan`). Returns the states, the environment sides, what ended at each step ((seeds,
    n_steps) arrays: done, return, length, episode) and each seed's update metrics averaged over
    its gradient steps (zeros when `update` is false)."""
    c = spec.config
    vmap = jax.vmap
    keys = vmap(jax.random.split)(envs["key"])
    envs = dict(envs, key=keys[:, 0])
    reset_keys, first = keys[:, 1], envs["episode"]
    size = min(POOL, n_steps)
    pool = vmap(functools.partial(reset_pool, task, size=size))(table, reset_keys, first)
    step_seed = vmap(functools.partial(act_and_step, spec, task), in_axes=(0, 0, None))
    take = vmap(lambda p, j: jax.tree_util.tree_map(lambda x: x[jnp.clip(j, 0, size - 1)], p))

    def one_step(carry, t):
        states, envs = carry
        key, action, task_state, next_obs, reward, terminated = step_seed(states, envs, t)
        ep_return, ep_length = envs["ep_return"] + reward, envs["ep_length"] + 1
        done = terminated | (ep_length >= c.max_episode_steps)
        episode = envs["episode"] + done.astype(jnp.int32)
        slot = episode - first - 1  # the new episode's place in the pool
        beyond = done & (slot >= size)

        def reset_all(fresh):
            computed = vmap(functools.partial(episode_reset, task))(table, reset_keys, episode)
            return select(beyond, computed, fresh)

        fresh = jax.lax.cond(jnp.any(beyond), reset_all, lambda f: f, take(pool, slot))
        task_state = select(done, fresh[0], task_state)
        start_obs = select(done, fresh[1], next_obs)
        rows = vmap(step_rows)(envs["obs"], action, reward, terminated, next_obs, start_obs)
        n_rows = 2 + done.astype(jnp.int32)
        buffers = vmap(replay.append_rows)(states["buffer"], rows, n_rows)
        ended = (done, ep_return, ep_length, envs["episode"])
        envs = {
            "task": task_state,
            "obs": start_obs,
            "ep_return": jnp.where(done, 0.0, ep_return),
            "ep_length": jnp.where(done, 0, ep_length),
            "episode": episode,
            "key": key,
        }
        return (dict(states, buffer=buffers), envs), ended

    ts = step + 1 + jnp.arange(n_steps, dtype=jnp.int32)
    (states, envs), ended = jax.lax.scan(one_step, (states, envs), ts)
    ended = jax.tree_util.tree_map(lambda x: x.T, ended)  # (seeds, n_steps)

    def learn_one(state):
        state, infos = jax.lax.scan(
            lambda s, _: sac.update_step(spec, s), state, None, length=c.update_every
        )
        return state, jax.tree_util.tree_map(jnp.mean, infos)

    learn = vmap(learn_one)

    def skip(states):
        info = jax.eval_shape(learn, states)[1]
        return states, jax.tree_util.tree_map(lambda x: jnp.zeros(x.shape, x.dtype), info)

    states, info = jax.lax.cond(update, learn, skip, states)
    return states, envs, ended, info


def evaluate(spec: sac.Spec, task, max_steps: int, n_episodes: int, actors, masks, keys, fields):
    """`n_episodes` deterministic episodes of every seed's policy on `task`, all at once: seed i's
    episode k starts from ``task.reset(fold_in(keys[i], k), fields[i, k])`` (`fields`: name ->
    (seeds, episodes, …), or {} for the task's own model) and acts a = c + h·tanh(μ) (what the
    policy file computes) until it terminates or reaches `max_steps` steps, inside one
    `while_loop` that stops once every episode has. Returns (returns, lengths), each (seeds,
    episodes)."""
    vmap = jax.vmap
    episodes = jnp.arange(n_episodes, dtype=jnp.int32)

    def start(key, k, fields):
        state = task.reset(jax.random.fold_in(key, k), fields)
        return state, task.observation(state.data).astype(jnp.float32)

    states, obs = vmap(vmap(start, in_axes=(None, 0, 0)))(
        keys, jnp.broadcast_to(episodes, (keys.shape[0], n_episodes)), fields
    )

    def act(actor, mask, obs):  # one seed's episodes
        mu, _ = sac.actor_forward(spec, actor, mask, obs)
        return sac.squash(spec, mu)

    step = vmap(vmap(task.step))
    shape = (keys.shape[0], n_episodes)

    def running(carry):
        t, *_, alive = carry
        return (t < max_steps) & jnp.any(alive)

    def body(carry):
        t, states, obs, returns, lengths, alive = carry
        states, obs, reward, terminated, _ = step(states, vmap(act)(actors, masks, obs))
        returns = returns + jnp.where(alive, reward.astype(jnp.float32), 0.0)
        lengths = lengths + alive.astype(jnp.int32)
        return t + 1, states, obs.astype(jnp.float32), returns, lengths, alive & ~terminated

    returns, lengths = jnp.zeros(shape, jnp.float32), jnp.zeros(shape, jnp.int32)
    carry = (jnp.zeros((), jnp.int32), states, obs, returns, lengths, jnp.ones(shape, bool))
    _, _, _, returns, lengths, _ = jax.lax.while_loop(running, body, carry)
    return returns, lengths
