"""The device learner (`adarl.train.device_learner`, `--backend device`) on CPU, tiny (2 seeds,
1,200 steps, (32, 32) networks): the masked truncation of seeds whose ranks differ gives the
compacted networks' outputs; a run killed between two checkpoints and resumed equals an
uninterrupted one; the same seeds give the same numbers; and it learns. A compile of the device
chunk takes 30-130 s on these CPUs, so every test uses the one config's compiled functions
(module fixtures), and the learning check reads the uninterrupted run."""

import json

import jax
import numpy as np
import pytest

from adarl.algos import registry, sac
from adarl.device import missing_reason
from adarl.policy import NumpyPolicy
from adarl.runs import checkpoints
from adarl.runs.layout import CHECKPOINT_DIR
from adarl.runs.logs import read_csv

pytestmark = [
    pytest.mark.skipif(missing_reason() is not None, reason=str(missing_reason())),
    pytest.mark.slow,
]

# truncations after 300 gradient steps: at steps 450 (before the crash), 750 and 1,050 (after)
BUDGET = {
    "backend": "device",
    "task": "hopper",
    "dynamics": "default",
    "seeds": (0, 1),
    "hidden": (32, 32),
    "total_steps": 1_200,
    "start_steps": 200,
    "update_after": 200,
    "truncate_every": 300,
    "warmup_steps": 100,
    "checkpoint_every": 600,
    "eval_every": 600,
    "log_every": 200,
    "buffer_size": 2_000,
    "batch_size": 64,
    "max_episode_steps": 200,
    "retain_samples": 64,
}


class Crash(Exception):
    pass


@pytest.fixture(scope="module")
def config():
    return registry.resolve_config("adarl", "smoke", BUDGET)


@pytest.fixture(scope="module")
def learner(config):
    """A learner of the config; holding it keeps the compiled functions for every test."""
    from adarl.train.device_learner import DeviceSACLearner

    return DeviceSACLearner(config)


@pytest.fixture(scope="module")
def full_run(config, learner, tmp_path_factory):
    from adarl.train.trainers import train

    return train(config, tmp_path_factory.mktemp("device") / "full", progress=False)


@pytest.fixture(scope="module")
def killed_run(config, learner, full_run, tmp_path_factory):
    """The same run, killed while writing its second checkpoint, before resuming; returns the
    run folder and its first checkpoint."""
    from adarl.train.trainers import train

    run = tmp_path_factory.mktemp("device") / "killed"
    saved = []
    original = checkpoints.save_checkpoint

    def save_then_crash(*args, **kwargs):
        if kwargs.get("folder", CHECKPOINT_DIR) != CHECKPOINT_DIR:
            return original(*args, **kwargs)  # a pre-truncation checkpoint
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
    return run, saved[0]


def _csv(run, name):
    rows = read_csv(run / name)
    for row in rows:
        row.pop("steps_per_s", None)  # wall-clock
    return rows


def test_masked_truncation_gives_the_compacted_networks_output(config, learner):
    """Seeds whose ranks differ (16 and 9 of 32) cut in one vmapped call: each seed's masked
    network gives what its compacted policy file computes and what the best rank-r
    approximation of its old bottleneck (NumPy's SVD, r by the energy rule) gives."""
    learner.fresh()
    rng = np.random.default_rng(0)
    state = jax.tree_util.tree_map(np.array, jax.device_get(learner.state))
    n_rows = 1_000
    state["buffer"]["obs"][:, :n_rows] = rng.normal(size=(2, n_rows, 11)).astype(np.float32)
    state["buffer"]["act"][:, :n_rows] = rng.uniform(-1, 1, (2, n_rows, 3)).astype(np.float32)
    state["buffer"]["valid"][:, :n_rows] = 1
    state["buffer"]["size"][:] = n_rows
    old_ranks = (16, 9)
    for i, r in enumerate(old_ranks):
        keep = (np.arange(32) < r).astype(np.float32)
        state["masks"]["actor"][1][i] = keep
        state["masks"]["critic"][1][i] = keep
    old_actor = jax.tree_util.tree_map(np.copy, state["actor"])
    learner.state = jax.device_put(state)

    cut = learner.truncate(450)

    obs = rng.normal(size=(64, 11)).astype(np.float32)
    after = jax.device_get(learner.state)
    new_ranks = {r["seed"]: r["new_rank"] for r in cut.rows if r["layer"] == "actor_1"}
    assert new_ranks[0] != new_ranks[1]
    for i, seed in enumerate(config.seeds):
        trunk = [jax.tree_util.tree_map(lambda a, i=i: a[i], p) for p in old_actor["trunk"]]
        w1, w2 = (np.asarray(trunk[1][k], np.float64) for k in ("w1", "w2"))
        w = w1[:, : old_ranks[i]] @ w2[: old_ranks[i]]
        u, s, vt = np.linalg.svd(w)
        r = int(np.argmax(np.cumsum(s) / s.sum() >= config.beta)) + 1  # the energy rule
        assert new_ranks[seed] == min(r, old_ranks[i])
        r = new_ranks[seed]
        best = (u[:, :r] * s[:r]) @ vt[:r]  # Eckart-Young

        h = np.maximum(obs @ trunk[0]["w"] + trunk[0]["b"], 0)
        h = np.maximum(h @ best + trunk[1]["b"], 0)
        mean = h @ old_actor["mu"]["w"][i] + old_actor["mu"]["b"][i]
        expected = np.tanh(mean)  # the action box is [-1, 1]

        actor = jax.tree_util.tree_map(lambda a, i=i: a[i], after["actor"])
        masks = [None if m is None else m[i] for m in after["masks"]["actor"]]
        assert masks[1].sum() == r and np.all(masks[1][r:] == 0)
        masked = sac.squash(learner.spec, sac.actor_forward(learner.spec, actor, masks, obs)[0])
        policy = learner.policies()[i]
        assert policy["l1_w1"].shape == (32, r) and policy["l1_w2"].shape == (r, 32)
        compacted = NumpyPolicy(policy)(obs)
        np.testing.assert_allclose(np.asarray(masked), compacted, atol=1e-5)
        np.testing.assert_allclose(compacted, expected, atol=1e-4)


def test_killed_and_resumed_run_equals_an_uninterrupted_one(config, full_run, killed_run):
    from adarl.runs import folder
    from adarl.train.trainers import train

    run, _ = killed_run
    algo, config_back = folder.config_from_run(run)
    assert (algo, config_back) == ("adarl", config)
    train(config_back, run, resume=True, progress=False)
    assert (run / "DONE").read_text() == (full_run / "DONE").read_text()
    names = sorted(p.name for p in full_run.glob("*.csv"))
    assert names == sorted(p.name for p in run.glob("*.csv"))
    for name in names:
        assert _csv(run, name) == _csv(full_run, name), name
    assert len(read_csv(run / "truncations.csv")) == 3 * 3 * 2  # 3 cuts, 3 layers, 2 seeds
    spectra = sorted(p.name for p in full_run.glob("spectra/*.npz"))
    assert spectra == sorted(p.name for p in run.glob("spectra/*.npz")) and len(spectra) == 3
    a_dir = checkpoints.latest_checkpoint(full_run)
    b_dir = checkpoints.latest_checkpoint(run)
    assert a_dir.name == b_dir.name
    with np.load(a_dir / "arrays.npz") as a, np.load(b_dir / "arrays.npz") as b:
        assert a.files == b.files
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    for p in a_dir.iterdir():
        if p.suffix == ".npz" and p.name != "arrays.npz":
            assert p.read_bytes() == (b_dir / p.name).read_bytes(), p.name


def test_the_same_seeds_give_the_same_numbers(full_run, killed_run):
    """The killed run, up to its first checkpoint, is a second run of the same seeds."""
    _, first = killed_run
    same = checkpoints.checkpoint_dirs(full_run)
    twin = next(d for d in same if d.name == first.name)
    with np.load(twin / "arrays.npz") as a, np.load(first / "arrays.npz") as b:
        assert a.files == b.files and any(k.startswith("env_device") for k in a.files)
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    meta = json.loads((first / "meta.json").read_text())
    assert meta["backend"] == "device" and meta["step"] == 600
    assert "env_states" not in meta and "rng_states" not in meta  # the tasks live on the device


def test_it_learns(full_run):
    """Every seed's episodes in the last 300 steps return at least twice what the uniformly
    random episodes before `start_steps` did (measured: about 5 times at 1,500 steps)."""
    rows = read_csv(full_run / "episodes.csv")
    for seed in (0, 1):
        mine = [r for r in rows if int(r["seed"]) == seed]
        random = [float(r["return"]) for r in mine if int(r["step"]) <= 200]
        late = [float(r["return"]) for r in mine if int(r["step"]) > 900]
        assert random and late
        assert np.mean(late) > 2 * np.mean(random), (seed, np.mean(random), late)
    ranks = read_csv(full_run / "train.csv")[-1]
    assert int(ranks["rank_actor_1"]) < 32  # the bottlenecks were cut


def test_a_fork_at_a_pre_truncation_checkpoint_continues_exactly_as_its_parent(full_run, tmp_path):
    """A fork without changes at step 750 restores the checkpoint kept just before that step's
    truncation (the path `adarl train --fork … --apply-cuts false` takes to AdaRL's control)."""
    from adarl.train import fork
    from adarl.train.trainers import train

    planned = fork.prepare(full_run, 750, {})
    assert planned.record["checkpoint"] == "pre_truncation"
    child = tmp_path / "child"
    fork.write(planned, child, "")
    train(planned.config, child, resume=True, progress=False)
    for name in ("episodes.csv", "train.csv", "eval.csv", "truncations.csv"):
        assert _csv(child, name) == _csv(full_run, name), name
    a_dir = checkpoints.latest_checkpoint(full_run)
    b_dir = checkpoints.latest_checkpoint(child)
    with np.load(a_dir / "arrays.npz") as a, np.load(b_dir / "arrays.npz") as b:
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_nominal_dynamics_run_on_the_host_tasks_nominal_model():
    """`--dynamics nominal` (one model for every episode): the device task's model is the one the
    host task compiles for it, and episodes.csv gets the host's parameters."""
    from adarl.envs import make
    from adarl.train.device_learner import device_task, fixed_physics

    config = registry.resolve_config("sac", "smoke", {**BUDGET, "dynamics": "nominal"})
    env = make("hopper", dynamics="nominal", seed=0)
    env.reset()
    host = env.unwrapped.model
    device = device_task("hopper", "nominal").mj_model
    for name in ("body_mass", "body_inertia", "geom_size", "body_pos", "qpos0"):
        np.testing.assert_array_equal(getattr(device, name), getattr(host, name), name)
    assert fixed_physics(config).episode_params(1, 7) == env.dynamics_params
    assert env.dynamics_params["torso_length"] == 0.4  # not Gymnasium's 0.2


@pytest.mark.slow
def test_a_sigkilled_device_run_resumes_to_the_uninterrupted_runs_bits(tmp_path):
    """A real SIGKILL of `adarl train --backend device` (AdaRL, `paper` physics through the ring,
    truncations before and after the kill) after its first checkpoint, then `--resume`: the same
    CSVs and final arrays as the same run left alone."""
    import os
    import signal
    import subprocess
    import sys
    import time

    flags = ["--algo", "adarl", "--backend", "device", "--task", "hopper", "--dynamics", "paper"]
    flags += ["--seeds", "0,1", "--hidden", "32,32", "--total-steps", "800", "--start-steps", "200"]
    flags += ["--update-after", "200", "--truncate-every", "200", "--warmup-steps", "50"]
    flags += ["--checkpoint-every", "400", "--eval-every", "400", "--eval-episodes", "1"]
    flags += ["--log-every", "200", "--buffer-size", "1000", "--batch-size", "32"]
    flags += ["--max-episode-steps", "100", "--retain-samples", "32", "--no-progress"]
    train = [sys.executable, "-m", "adarl.cli.main", "train", *flags]
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    whole = subprocess.Popen([*train, "--out", str(tmp_path / "whole")], **quiet)
    killed_dir = tmp_path / "killed"
    proc = subprocess.Popen([*train, "--out", str(killed_dir)], **quiet)
    deadline = time.time() + 600
    while time.time() < deadline and not checkpoints.checkpoint_dirs(killed_dir):
        time.sleep(0.1)
        assert proc.poll() is None, "training ended before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (killed_dir / "DONE").exists()
    resume = [sys.executable, "-m", "adarl.cli.main", "train", "--resume", str(killed_dir)]
    done = subprocess.run([*resume, "--no-progress"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert whole.wait() == 0
    for name in ("train.csv", "episodes.csv", "truncations.csv"):
        assert _csv(killed_dir, name) == _csv(tmp_path / "whole", name), name
    last = {run: checkpoints.checkpoint_dirs(run)[-1] for run in (killed_dir, tmp_path / "whole")}
    a, b = (np.load(path / "arrays.npz") for path in last.values())
    assert sorted(a.files) == sorted(b.files)
    for key in a.files:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_the_device_evaluation_is_logged_beside_the_hosts(full_run):
    """eval_device.csv (the device evaluation, written by the loop while the host evaluates)
    has a row for every row of eval.csv: the same steps, seeds, dynamics and episodes, with
    lengths within the time limit."""
    from adarl.runs.logs import EVAL_COLUMNS
    from adarl.train.device_learner import DEVICE_EVAL_COLUMNS

    assert DEVICE_EVAL_COLUMNS == EVAL_COLUMNS
    device = read_csv(full_run / "eval_device.csv")
    host = read_csv(full_run / "eval.csv")
    keys = ("step", "seed", "dynamics", "episode")
    assert [tuple(r[k] for k in keys) for r in device] == [tuple(r[k] for k in keys) for r in host]
    assert {int(r["step"]) for r in device} == {600, 1_200}
    assert all(1 <= int(r["length"]) <= BUDGET["max_episode_steps"] for r in device)


def test_the_device_evaluation_is_each_seeds_deterministic_policy_from_its_own_resets(learner):
    """`sac_device.evaluate` over both seeds and 2 episodes, 6 steps at most, against the same
    episodes run one at a time: reset from ``fold_in(eval_key(seed), k)``, the policy file's
    action (NumPy), the task stepped alone."""
    import functools

    from adarl.algos import sac_device
    from adarl.train.device_learner import device_task

    learner.fresh()
    task = device_task("hopper", "default", learner.config.device_solver)
    spec, max_steps, n_episodes = learner.spec, 6, 2
    evaluate = jax.jit(functools.partial(sac_device.evaluate, spec, task, max_steps, n_episodes))
    actor, masks = learner.state["actor"], learner.state["masks"]["actor"]
    returns, lengths = jax.device_get(evaluate(actor, masks, learner.eval_keys, {}))
    reset, step = jax.jit(task.reset), jax.jit(task.step)
    for i, seed in enumerate(learner.seeds):
        policy = NumpyPolicy(learner.policies()[i])
        for k in range(n_episodes):
            state = reset(jax.random.fold_in(sac_device.eval_key(seed), k))
            obs, total, length = np.asarray(task.observation(state.data)), 0.0, 0
            while length < max_steps:
                state, obs, reward, terminated, _ = step(state, policy(obs[None])[0])
                obs, total, length = np.asarray(obs), total + float(reward), length + 1
                if bool(terminated):
                    break
            assert lengths[i, k] == length, (seed, k)
            np.testing.assert_allclose(returns[i, k], total, rtol=1e-5, atol=1e-5)
