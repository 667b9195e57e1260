"""The device chunk (`adarl.algos.sac_device`): its pure parts without MJX (the replay rows of one
environment step against the host's chunk builder, the per-episode physics table), then on MJX
the physics solves an env step costs and the resets drawn from each chunk's pool."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import replay, sac_device
from adarl.algos.sac_config import SACConfig
from adarl.device import missing_reason
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
            {"backend": "device", "dynamics": "nominal", "physics": "ompo"},
            "unknown physics for --backend device 'ompo'; allowed: consistent",
        ),
    ],
)
def test_device_backend_refuses_what_it_cannot_train(fields, words):
    with pytest.raises(UsageError, match=words.replace("(", r"\(")):
        SACConfig(**{"algo": "sac", **fields}).validate()


def test_every_algorithm_of_the_sac_family_trains_on_the_device():
    from adarl.algos.sac_config import DEVICE_ALGOS, SAC_FAMILY

    assert set(DEVICE_ALGOS) == set(SAC_FAMILY)
    config = SACConfig(algo="sac-sparse", backend="device", sparse_width=16).validate()
    assert config.backend == "device"


def test_host_backend_is_the_default():
    assert SACConfig().validate().backend == "host"


@pytest.mark.parametrize(
    ("task", "dynamics"),
    [("hopper", "paper"), ("hopper", "ompo:foot_length=0.3"), ("walker2d", "uniform")],
)
def test_device_backend_takes_the_per_episode_schedules(task, dynamics):
    config = SACConfig(algo="sac", backend="device", task=task, dynamics=dynamics).validate()
    assert (config.task, config.dynamics) == (task, dynamics)


# ---------------------------------------------------------------------------- the chunk on MJX
needs_mjx = pytest.mark.skipif(missing_reason() is not None, reason=str(missing_reason()))
TINY = {
    "backend": "device",
    "task": "hopper",
    "dynamics": "default",
    "seeds": (0, 1),
    "hidden": (8, 8),
    "update_every": 6,
    "start_steps": 0,
    "update_after": 6,
    "buffer_size": 64,
    "batch_size": 8,
    "max_episode_steps": 2,
    "eval_every": 60,
    "log_every": 60,
    "checkpoint_every": 60,
}


def _counted_solves(monkeypatch):
    """Make every MJX constraint solve traced from now on show in a jaxpr as a call named
    `counted_solve` (a nested jit), which `_solves` counts."""
    from mujoco.mjx._src import solver

    original = solver.solve

    def solve(m, d):
        def counted_solve(d):
            return original(m, d)

        return jax.jit(counted_solve)(d)

    monkeypatch.setattr(solver, "solve", solve)


def _solves(jaxpr, in_cond: bool = False) -> tuple[int, int]:
    """(unconditional, under a `cond`) `counted_solve` calls of `jaxpr`, each scan's body counted
    `length` times."""
    plain = conditional = 0
    for eqn in jaxpr.eqns:
        if eqn.params.get("name") == "counted_solve":
            plain, conditional = (plain, conditional + 1) if in_cond else (plain + 1, conditional)
            continue
        times = eqn.params["length"] if eqn.primitive.name == "scan" else 1
        for value in eqn.params.values():
            for sub in value if isinstance(value, tuple) else (value,):
                sub = getattr(sub, "jaxpr", sub)
                if hasattr(sub, "eqns"):
                    p, c = _solves(sub, in_cond or eqn.primitive.name == "cond")
                    plain, conditional = plain + times * p, conditional + times * c
    return plain, conditional


def _tiny(**fields):
    from adarl.algos import registry
    from adarl.train.device_learner import DeviceSACLearner

    return DeviceSACLearner(registry.resolve_config("sac", "smoke", TINY | fields))


def _abstract_chunk_inputs(learner):
    state = jax.eval_shape(
        lambda: dict(
            learner.initial_state(),
            buffer=replay.empty_buffers(
                learner.n, learner.config.buffer_size, learner.spec.obs_dim, learner.spec.act_dim
            ),
        )
    )
    env = jax.eval_shape(learner.fns.init_env, learner.env_keys(), {})
    return state, env


@needs_mjx
@pytest.mark.slow
def test_an_env_step_costs_its_physics_steps_and_resets_come_from_the_chunks_pool(monkeypatch):
    """Solves of the constraint solver traced in a chunk of 6 env steps: each env step runs
    exactly its `frame_skip` (4) physics steps' solves (MJX's RK4: 4 per physics step, counted
    from `mjx.step` alone); the resets are one vmapped pool before the steps and, under a
    `cond` at each step, the fallback reset for a seed past its pool (not a fifth solve per env
    step)."""
    import functools

    from mujoco import mjx

    from adarl.train.device_learner import device_task

    _counted_solves(monkeypatch)
    learner = _tiny()
    task = device_task("hopper", "default", learner.config.device_solver)
    physics_step = jax.make_jaxpr(lambda d: mjx.step(task.model, d))(task._data0)
    per_physics_step, _ = _solves(physics_step.jaxpr)
    assert per_physics_step == 4  # RK4's four stages, each a forward with its solve
    state, env = _abstract_chunk_inputs(learner)
    chunk = functools.partial(sac_device.chunk, learner.spec, task, 6)
    jaxpr = jax.make_jaxpr(chunk)(state, env, {}, jnp.int32(0), jnp.bool_(True)).jaxpr
    plain, conditional = _solves(jaxpr)
    assert plain == 6 * task.rules.frame_skip * per_physics_step + 1  # the steps; the pool once
    assert conditional == 6  # one fallback reset per step, run only where a seed needs one


@needs_mjx
@pytest.mark.slow
def test_every_episode_starts_from_its_own_reset_from_the_pool_or_past_it(monkeypatch):
    """A chunk of 6 env steps with 2-step episodes and a pool of 2: each seed ends 3 episodes,
    so its third start comes from the fallback. Every episode e that starts in the chunk starts
    at the observation of ``task.reset(fold_in(k, e), fields)``, k the second half of
    ``split`` of the seed's key at the chunk's start, computed here one reset at a time."""
    import functools

    from adarl.train.device_learner import device_task

    monkeypatch.setattr(sac_device, "POOL", 2)
    learner = _tiny()
    learner.fresh()
    task = device_task("hopper", "default", learner.config.device_solver)
    keys = np.asarray(jax.device_get(learner.env["key"]))
    first = np.asarray(jax.device_get(learner.env["episode"]))
    chunk = jax.jit(functools.partial(sac_device.chunk, learner.spec, task, 6))
    states, env, ended, _ = chunk(learner.state, learner.env, {}, np.int32(0), np.bool_(False))
    done = np.asarray(jax.device_get(ended[0]))
    assert done.sum(axis=1).min() >= 3  # past the pool of 2: the fallback ran
    obs = np.asarray(jax.device_get(states["buffer"]["obs"]))
    reset = jax.jit(lambda key, e: task.observation(task.reset(jax.random.fold_in(key, e)).data))
    for i in range(2):
        k_chunk = jax.random.split(keys[i])[1]
        ptr, episode = 0, int(first[i])
        for t in range(6):  # a step writes 2 rows, 3 where it ends: then the next start is third
            if done[i, t]:
                episode += 1
                expected = np.asarray(reset(k_chunk, episode))
                np.testing.assert_array_equal(obs[i, ptr + 2], expected, f"seed {i} step {t}")
            ptr += 1 + int(done[i, t])
        assert episode == int(jax.device_get(env["episode"])[i])
