"""Per-episode physics on the device backend (`--dynamics paper`; `PhysicsRing` in
`adarl.device.physics`, read by `adarl.train.device_learner`) on CPU, tiny (2 seeds, 600 steps,
(32, 32) networks, 10-step chunks and 7-step episodes, so each seed's ring of 21 rows wraps
often and episodes start anywhere in a chunk): every episode runs the model the host env
compiles for it, though chunk k+1 is dispatched before chunk k's episodes are read, the ring is
refilled row by row, episodes.csv records the host env's parameters, and a run killed between
two checkpoints and resumed equals an uninterrupted one. One config, so every
test uses the same compiled chunk (a compile takes 30-130 s on these CPUs)."""

import copy

import jax
import numpy as np
import pytest

from adarl.algos import registry
from adarl.device import missing_reason
from adarl.runs import checkpoints
from adarl.runs.layout import CHECKPOINT_DIR
from adarl.runs.logs import read_csv

pytestmark = [
    pytest.mark.skipif(missing_reason() is not None, reason=str(missing_reason())),
    pytest.mark.slow,
]

BUDGET = {
    "backend": "device",
    "task": "hopper",
    "dynamics": "paper",
    "seeds": (0, 1),
    "hidden": (32, 32),
    "total_steps": 600,
    "start_steps": 200,
    "update_after": 200,
    "update_every": 10,
    "checkpoint_every": 200,
    "eval_every": 600,
    "log_every": 200,
    "buffer_size": 2_000,
    "batch_size": 64,
    "max_episode_steps": 7,
}


class Crash(Exception):
    pass


class HostEpisodes:
    """One seed's host env (`adarl.envs.make`, schedule seed = the seed), reset once per episode
    as the host learner resets it: its compiled model and parameters for each episode index."""

    def __init__(self, task: str, dynamics: str, seed: int):
        from adarl.envs import make

        self.env = make(task, dynamics, seed=seed)
        self.models, self.params = [], []

    def episode(self, index: int):
        while len(self.models) <= index:
            self.env.reset()
            self.models.append(copy.copy(self.env.unwrapped.model))
            self.params.append(self.env.dynamics_params)
        return self.models[index], self.params[index]

    def field(self, index: int, name: str, shape) -> np.ndarray:
        from adarl.device.physics import host_value

        return host_value(self.episode(index)[0], name, shape).astype(np.float32)


@pytest.fixture(scope="module")
def config():
    return registry.resolve_config("sac", "smoke", BUDGET)


@pytest.fixture(scope="module")
def learner(config):
    """A learner of the config; holding it keeps the compiled functions for every test."""
    from adarl.train.device_learner import DeviceSACLearner

    return DeviceSACLearner(config)


@pytest.fixture(scope="module")
def host():
    return [HostEpisodes("hopper", BUDGET["dynamics"], s) for s in BUDGET["seeds"]]


@pytest.fixture(scope="module")
def full_run(config, learner, tmp_path_factory):
    from adarl.train.trainers import train

    return train(config, tmp_path_factory.mktemp("ring") / "full", progress=False)


def _csv(run, name):
    rows = read_csv(run / name)
    for row in rows:
        row.pop("steps_per_s", None)  # wall-clock
    return rows


def check_every_episode_runs_the_host_model(learner, host, steps: int) -> None:
    """Chunk by chunk from a fresh start (each advance runs several): the device table each
    chunk is dispatched with holds, in slot e mod (2 update_every + 1), the host model's
    fields of every episode e that runs in that chunk, though it was filled before the chunk
    before it had ended; the task state at each advance's end carries those of the episode
    then running; each ended episode reports the host env's parameters; and every seed's ring
    wrapped."""
    import dataclasses

    from adarl.train.device_learner import ring_slots

    learner.fresh()
    shapes = learner.physics.table.shapes
    slots = ring_slots(learner.config)
    dispatched = []  # (episodes at the chunk's start, the table it was given)
    chunk = learner.fns.chunk

    def recording(n_steps, state, env, table, *args):
        dispatched.append((np.asarray(jax.device_get(env["episode"])), jax.device_get(table)))
        return chunk(n_steps, state, env, table, *args)

    learner.fns = dataclasses.replace(learner.fns, chunk=recording)
    step = 0
    try:
        while step < steps:
            advance = learner.advance(step)
            step = advance.step
            running = jax.device_get(learner.env["task"].fields)
            for i, episodes in enumerate(host):
                for name, shape in shapes.items():
                    expected = episodes.field(int(learner.episodes[i]), name, shape)
                    np.testing.assert_array_equal(running[name][i], expected, name)
            for episode in advance.episodes:
                index = episode.info["episode_index"]
                assert episode.info["dynamics"] == host[episode.index].episode(index)[1]
    finally:
        learner.fns = dataclasses.replace(learner.fns, chunk=chunk)
    assert len(dispatched) > 2 * (steps // 200 + 1)  # advances of several chunks
    ends = [first for first, _ in dispatched[1:]] + [learner.episodes]
    for (first, table), last in zip(dispatched, ends, strict=True):
        for i, episodes in enumerate(host):
            for e in range(first[i], last[i] + 1):
                for name, shape in shapes.items():
                    expected = episodes.field(e, name, shape)
                    np.testing.assert_array_equal(table[name][i, e % slots], expected, name)
    assert min(learner.episodes) > slots


def test_chunk_k_plus_1_is_dispatched_before_chunk_ks_episodes_are_read(learner, monkeypatch):
    """Within an advance the host reads what ended in a chunk only after the next chunk is
    queued, and refills the device's ring by the rows that changed, never the whole ring."""
    import dataclasses

    from adarl.train import device_learner

    learner.fresh()
    events, uploads = [], []
    chunk, read, upload = learner.fns.chunk, device_learner.read_ended, learner.upload_rows

    def recording(n_steps, state, env, table, step, update):
        events.append(("dispatch", int(step)))
        return chunk(n_steps, state, env, table, step, update)

    def reading(ended):
        events.append(("read", None))
        return read(ended)

    def uploading(stale):
        uploads.append(len(stale))
        return upload(stale)

    monkeypatch.setattr(device_learner, "read_ended", reading)
    monkeypatch.setattr(learner, "upload_rows", uploading)
    learner.fns = dataclasses.replace(learner.fns, chunk=recording)
    try:
        advance = learner.advance(0)
    finally:
        learner.fns = dataclasses.replace(learner.fns, chunk=chunk)
    kinds = [kind for kind, _ in events]
    n = kinds.count("dispatch")
    assert n == advance.step // learner.config.update_every > 2
    assert kinds == ["dispatch", "dispatch"] + ["read", "dispatch"] * (n - 2) + ["read"] * 2
    slots = learner.physics.slots
    assert uploads and all(0 < u <= learner.n * learner.config.update_every for u in uploads)
    assert max(uploads) < learner.n * slots


def test_every_episode_runs_the_model_the_host_env_compiles_for_it(learner, host):
    check_every_episode_runs_the_host_model(learner, host, 400)
    assert len(learner.physics.table.shapes) == 19  # paper's fields (tests/device/test_physics.py)


def test_walker2d_under_uniform_draws_each_seeds_own_models_as_the_host_env_does():
    """Walker2d, `uniform` (a draw per episode from `default_rng([seed, episode])`): each seed's
    episodes run the host env's models for that seed, which differ between the seeds."""
    from adarl.train.device_learner import DeviceSACLearner

    budget = BUDGET | {"task": "walker2d", "dynamics": "uniform", "total_steps": 200}
    learner = DeviceSACLearner(registry.resolve_config("sac", "smoke", budget))
    host = [HostEpisodes("walker2d", "uniform", s) for s in budget["seeds"]]
    check_every_episode_runs_the_host_model(learner, host, 200)
    assert host[0].episode(3)[1] != host[1].episode(3)[1]


@pytest.mark.parametrize("task", ["ant", "humanoid"])
def test_ant_and_humanoid_under_paper_run_the_host_envs_gravity_and_wind(task):
    """Ant and Humanoid, `paper` (gravity and wind per episode, the only fields that change):
    every episode runs the host env's compiled model's fields, and reports its parameters."""
    from adarl.train.device_learner import DeviceSACLearner

    budget = BUDGET | {"task": task, "total_steps": 100, "start_steps": 100, "update_after": 100}
    budget |= {"update_every": 5}  # rings of 11 rows, which 100 steps of 7-step episodes wrap
    learner = DeviceSACLearner(registry.resolve_config("sac", "smoke", budget))
    assert sorted(learner.physics.table.shapes) == ["opt.gravity", "opt.wind"]
    host = [HostEpisodes(task, "paper", s) for s in budget["seeds"]]
    check_every_episode_runs_the_host_model(learner, host, 100)


def test_episodes_csv_records_the_host_envs_parameters(full_run, host):
    rows = read_csv(full_run / "episodes.csv")
    assert len(rows) > 2 * 80
    for row in rows:
        params = host[int(row["seed"])].episode(int(row["episode"]))[1]
        assert {p: row[f"p_{p}"] for p in params} == {p: f"{v:.6g}" for p, v in params.items()}


def test_killed_and_resumed_run_equals_an_uninterrupted_one(config, learner, full_run, tmp_path):
    """Killed while writing its checkpoint at step 400, resumed from step 200's: the ring is
    rebuilt from the episode counters, and every CSV and the last checkpoint are the same."""
    from adarl.runs import folder
    from adarl.train.trainers import train

    run = tmp_path / "killed"
    saved = []
    original = checkpoints.save_checkpoint

    def save_then_crash(*args, **kwargs):
        if kwargs.get("folder", CHECKPOINT_DIR) != CHECKPOINT_DIR:
            return original(*args, **kwargs)
        if saved:
            raise Crash
        saved.append(original(*args, **kwargs))
        return saved[-1]

    checkpoints.save_checkpoint = save_then_crash
    try:
        with pytest.raises(Crash):
            train(config, run, progress=False)
    finally:
        checkpoints.save_checkpoint = original
    with np.load(saved[0] / "arrays.npz") as arrays:
        at_crash = arrays["env_device['episode']"]
    assert np.all(at_crash > 2 * config.update_every + 1)  # restored rings are past a wrap
    algo, config_back = folder.config_from_run(run)
    assert (algo, config_back) == ("sac", config)
    train(config_back, run, resume=True, progress=False)
    for name in ("episodes.csv", "train.csv", "eval.csv"):
        assert _csv(run, name) == _csv(full_run, name), name
    a_dir = checkpoints.latest_checkpoint(full_run)
    b_dir = checkpoints.latest_checkpoint(run)
    assert a_dir.name == b_dir.name
    with np.load(a_dir / "arrays.npz") as a, np.load(b_dir / "arrays.npz") as b:
        assert a.files == b.files
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
