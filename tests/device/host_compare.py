"""Run a device task's vmapped lanes beside the host task (adarl.envs.make on MuJoCo C), one host
env per lane with that lane's physics, from the same states and actions; report how far apart
their observations and rewards are and whether they terminate together.

Each lane starts from the device's reset state (the host env reset with ``mj_resetData`` and set
to it, as Gymnasium's reset does); when either side terminates both restart from the device's
next reset state (training resets there). With ``resync_every_step`` the host is also set to the
device's state (qpos, qvel, warm start) before every env step, so what is measured is one env
step's difference from the same state, not a trajectory's chaotic growth."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from adarl.envs import make as make_host


@dataclass
class Comparison:
    """Worst absolute differences per lane over the run, and the step counts."""

    obs: np.ndarray  # (lanes,)
    reward: np.ndarray  # (lanes,)
    termination_mismatches: int = 0
    terminations: int = 0
    steps: int = 0
    worst_at: list = field(default_factory=list)  # (lane, step, obs diff) of each lane's worst
    first_apart: int | None = None  # the first env step with an observation 1e-6 apart

    @property
    def worst(self) -> float:
        return float(max(self.obs.max(), self.reward.max()))


def host_envs(task_name: str, episodes: list[tuple[str, int]], seed: int = 0):
    """One host env per lane: `adarl.envs.make(task_name, dynamics, seed)` reset into episode
    `index` for each (dynamics, index), so the host compiles that episode's model itself; the
    raw Gymnasium envs (stepped without the time limit)."""
    envs = []
    for dynamics, index in episodes:
        env = make_host(task_name, dynamics, seed)
        env.episode_index = index
        env.reset(seed=seed)
        assert env.episode_index == index
        envs.append(env.unwrapped)
    return envs


def perturbed_episodes(schedule, count: int = 40) -> list[int]:
    """Three episodes of `schedule` far apart: where its first varying parameter is highest,
    lowest, and episode 3."""
    name = next(iter(schedule.sinusoids))
    values = [schedule.params_for_episode(i)[name] for i in range(count)]
    return [int(np.argmax(values)), int(np.argmin(values)), 3]


class Lanes:
    """A device task's jitted, vmapped reset and step, compiled once and shared by a module's
    tests (a compile takes 30-130 s on a shared CPU)."""

    def __init__(self, task):
        import jax
        import jax.numpy as jnp

        self.task = task
        self.reset = jax.jit(jax.vmap(task.reset))
        self.step = jax.jit(jax.vmap(task.step))
        self.observation = jax.jit(jax.vmap(task.observation))

        def select(mask, new, old):
            return jax.tree.map(
                lambda a, b: jnp.where(mask.reshape((-1,) + (1,) * (a.ndim - 1)), a, b), new, old
            )

        self.select = jax.jit(select)


def _set_host(env, qpos, qvel, warmstart=None):
    if warmstart is None:
        mujoco.mj_resetData(env.model, env.data)
    env.set_state(np.asarray(qpos, np.float64), np.asarray(qvel, np.float64))
    if warmstart is not None:
        env.data.qacc_warmstart[:] = warmstart


def compare(
    lanes_: Lanes,
    fields: dict,
    envs: list,
    steps: int,
    seed: int = 0,
    action_scale: float = 1.1,
    resync_every_step: bool = False,
) -> Comparison:
    """Run `steps` env steps of a float64 device task (`lanes_`) on len(envs) lanes whose model
    fields are `fields` (name -> (lanes, ...)), each against its host env `envs[i]`. Actions are
    uniform over `action_scale` times the actuators' control range (> 1 exercises clamping)."""
    import jax
    import jax.numpy as jnp

    lanes = len(envs)
    reset, step, select = lanes_.reset, lanes_.step, lanes_.select
    key = jax.random.key(seed)
    key, sub = jax.random.split(key)
    state = reset(jax.random.split(sub, lanes), fields)
    result = Comparison(np.zeros(lanes), np.zeros(lanes), worst_at=[None] * lanes)
    obs_d = np.asarray(lanes_.observation(state.data))
    for i, env in enumerate(envs):
        _set_host(env, state.data.qpos[i], state.data.qvel[i])
        result.obs[i] = np.abs(env._get_obs() - obs_d[i]).max()
    rng = np.random.default_rng(seed)
    low, high = (action_scale * r for r in envs[0].model.actuator_ctrlrange.T)
    for t in range(steps):
        if resync_every_step:
            qpos, qvel = np.asarray(state.data.qpos), np.asarray(state.data.qvel)
            warm = np.asarray(state.data.qacc_warmstart)
            for i, env in enumerate(envs):
                _set_host(env, qpos[i], qvel[i], warm[i])
        actions = rng.uniform(low, high, (lanes, len(low)))
        state, obs_d, reward_d, term_d, trunc_d = step(state, actions)
        obs_d, reward_d, term_d = np.asarray(obs_d), np.asarray(reward_d), np.asarray(term_d)
        assert not np.asarray(trunc_d).any()
        restart = np.zeros(lanes, bool)
        for i, env in enumerate(envs):
            obs, reward, terminated, _, _ = env.step(actions[i])
            diff = np.abs(obs - obs_d[i]).max()
            if diff > result.obs[i]:
                result.worst_at[i] = (i, t, float(diff))
            result.obs[i] = max(result.obs[i], diff)
            if diff > 1e-6 and result.first_apart is None:
                result.first_apart = t
            result.reward[i] = max(result.reward[i], abs(reward - reward_d[i]))
            result.termination_mismatches += bool(terminated) != bool(term_d[i])
            result.terminations += bool(terminated)
            restart[i] = terminated or term_d[i]
        result.steps += lanes
        if restart.any():
            key, sub = jax.random.split(key)
            state = select(jnp.asarray(restart), reset(jax.random.split(sub, lanes), fields), state)
            qpos, qvel = np.asarray(state.data.qpos), np.asarray(state.data.qvel)
            for i in np.flatnonzero(restart):
                _set_host(envs[i], qpos[i], qvel[i])
    return result


@dataclass
class Setup:
    """A float64 device task on the centroid's model of the `paper` schedule, with four lanes
    (the nominal episode and three perturbed `paper` episodes) and their host envs."""

    lanes: Lanes
    fields: dict
    envs: list
    episodes: list


def setup(
    task_name: str,
    seed: int = 0,
    solver: tuple[int, int] | None = None,
    options: Callable[[mujoco.MjModel], None] | None = None,
) -> Setup:
    """Build `Setup` for `task_name` (call inside ``jax.enable_x64(True)``), the device task's
    solver capped at `solver` where given (the host's stays the XML's); `options`, where given,
    changes the device task's base model and every host env's model alike (e.g. the integrator)."""
    import jax.numpy as jnp

    from adarl.device.physics import physics_table, stack
    from adarl.device.tasks import make

    table = physics_table(task_name, "paper", seed)
    episodes = perturbed_episodes(table.schedule)
    params = [table.schedule.centroid()] + [table.params(i) for i in episodes]
    fields = stack([table.fields_at(p) for p in params])
    envs = host_envs(task_name, [("nominal", 0)] + [("paper", i) for i in episodes], seed)
    if options is not None:
        for model in [table.mj_model] + [env.unwrapped.model for env in envs]:
            options(model)
    lanes = Lanes(make(task_name, table.mj_model, jnp.float64, solver=solver))
    return Setup(lanes, fields, envs, episodes)
