"""RNAC's training loop: the double-sampling simulator, a short run with checkpoints and exact
resume, the best policy, seed grouping, bad run folders (the maths: tests/algos/test_rnac.py)."""

from __future__ import annotations

import dataclasses
import shutil

import jax
import numpy as np
import pytest
from seed_slices import assert_seed_slice_equal

from adarl.algos import onpolicy, rnac, rnac_config
from adarl.errors import UsageError
from adarl.runs.logs import read_csv
from adarl.train import rnac_learner, trainers


# ----------------------------------------------------------------------------- double sampling
@pytest.mark.parametrize("task", ["hopper", "walker2d", "ant", "humanoid"])
def test_state_copy_round_trip(task):
    """Candidates come from the real env's exact state under the current episode's model: the
    real env stepping with a candidate's action lands bit-exactly on that candidate."""
    from adarl.envs import make

    env = make(task, dynamics="paper", seed=0)
    shadow = rnac_learner.ShadowSimulator(env)
    rng = np.random.default_rng(0)
    low, high = env.action_space.low, env.action_space.high
    models = set()
    for episode in range(3):  # paper dynamics: a new model every episode
        env.reset()
        models.add(id(env.unwrapped.model))
        for _ in range(3):
            env.step(rng.uniform(low, high).astype(np.float32))
        before = env.get_state()
        actions = rng.uniform(low, high, (3, low.size)).astype(np.float32)
        cand = shadow.candidates(actions)
        after = env.get_state()  # the real env is untouched
        np.testing.assert_array_equal(before["mj_state"], after["mj_state"])
        obs, *_ = env.step(actions[episode])
        np.testing.assert_array_equal(obs, cand[episode])
        assert not np.array_equal(cand[0], cand[1])
    assert len(models) == 3
    env.close()


# ----------------------------------------------------------------------------- a short run
def _config(**kw) -> rnac_config.RNACConfig:
    # the first checkpoint (640) falls inside a rollout (256 steps): its buffer is checkpointed
    base = dict(
        rnac_config.PRESETS["smoke"],
        total_steps=1024,
        checkpoint_every=640,
        eval_every=512,
        log_every=256,
    )
    return rnac_config.RNACConfig(**{**base, **kw})


def _rows(run, name, seed=None):
    rows = read_csv(run / f"{name}.csv")
    for r in rows:
        r.pop("steps_per_s", None)
    return [r for r in rows if seed is None or r["seed"] == str(seed)]


def test_run_checkpoint_and_exact_resume(tmp_path):
    config = _config(seeds=(0, 1))
    full = tmp_path / "full"
    trainers.train(config, full)
    assert (full / "DONE").read_text().strip() == "1024"
    ckpts = sorted(p.name for p in (full / "checkpoints").iterdir())
    assert ckpts == ["step_000000000640", "step_000000001024"]
    for name in ("episodes", "train", "eval"):
        assert _rows(full, name), name
    assert {r["step"] for r in _rows(full, "train")} == {str(256 * k) for k in range(1, 5)}
    assert len(_rows(full, "eval")) == 2 * 2  # 2 evaluations × 2 seeds × 1 episode
    assert float(_rows(full, "train")[-1]["loss_v"]) > 0

    # the policy file is the trained deterministic policy: normalise, tanh MLP, c + h·tanh(mean)
    from adarl.policy import load
    from adarl.runs.checkpoints import load_checkpoint
    from adarl.runs.codec import unflatten_tree

    arrays, _ = load_checkpoint(full / "checkpoints/step_000000001024")
    state = unflatten_tree(rnac.init_states([0, 1], config, 11, 3)[0], arrays, "state")
    actor = jax.tree.map(lambda x: np.asarray(x[1]), state.actor)
    count, m2 = arrays["host/obs_count"][1], arrays["host/obs_m2"][1]
    obs = np.random.default_rng(5).standard_normal((4, 11))
    norm = onpolicy.normalise_obs(obs, arrays["host/obs_mean"][1], m2 / count, config.obs_clip)
    expected = onpolicy.actor_mean(actor, norm, -np.ones(3), np.ones(3), np)
    policy = load(full / "checkpoints/step_000000001024/policy_seed_1.npz")
    np.testing.assert_allclose(policy(obs), expected, rtol=1e-5, atol=1e-6)
    before = (full / "train.csv").read_bytes()
    trainers.train(config, full, resume=True)  # a finished run: nothing to do
    assert (full / "train.csv").read_bytes() == before

    # kill after the first checkpoint: later checkpoint, DONE and half a CSV line are lost
    cut = tmp_path / "cut"
    shutil.copytree(full, cut)
    shutil.rmtree(cut / "checkpoints/step_000000001024")
    (cut / "DONE").unlink()
    with open(cut / "episodes.csv", "a") as f:
        f.write("1000,0,99,12.")
    # resumed with candidates simulated at every step (the original's way): same transitions
    trainers.train(dataclasses.replace(config, eager_candidates=True), cut, resume=True)
    for name in ("episodes", "train", "eval"):
        assert _rows(cut, name) == _rows(full, name), name
    with (
        np.load(full / "checkpoints/step_000000001024/arrays.npz") as a,
        np.load(cut / "checkpoints/step_000000001024/arrays.npz") as b,
    ):
        assert a.files == b.files
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)


# ----------------------------------------------------------------------------- best checkpoint
def _best(checkpoint):
    import json

    return json.loads((checkpoint / "meta.json").read_text())["best"]


def _policy_arrays(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def test_best_checkpoint_is_kept_and_resume_exact(tmp_path):
    """Each seed's best policy by mean nominal evaluation return is kept beside the final one:
    its record matches eval.csv, its file scores what was recorded, and a resumed run takes the
    best from its checkpoint, so it ends with the same record and arrays."""
    import json

    from adarl.envs.rollout import run_episodes
    from adarl.policy import load

    config = _config(seeds=(0, 1))
    full, last, first = (
        tmp_path / "full",
        "checkpoints/step_000000001024",
        "checkpoints/step_000000000640",
    )
    trainers.train(config, full, progress=False)
    record = _best(full / last)
    assert record["metric"] == "mean nominal evaluation return"
    assert _best(full / first)["seeds"].keys() == {"0", "1"}  # from the evaluation at 512
    evals = [r for r in _rows(full, "eval") if r["dynamics"] == "nominal"]
    for s in (0, 1):
        mine = [r for r in evals if r["seed"] == str(s)]  # one episode per evaluation
        top = max(mine, key=lambda r: float(r["return"]))  # the first maximum: ties keep it
        best = record["seeds"][str(s)]
        assert best["step"] == int(top["step"])
        assert best["return"] == pytest.approx(float(top["return"]), rel=1e-5)
        policy = load(full / last / f"best_policy_seed_{s}.npz")
        assert (
            run_episodes(policy, "hopper", "nominal", 1, 1_000_000 + s)[0]["return"]
            == best["return"]
        )
        assert (full / last / f"policy_seed_{s}.npz").is_file()  # the final one stays

    # killed after the first checkpoint and resumed: the same best record and arrays
    cut = tmp_path / "cut"
    shutil.copytree(full, cut)
    shutil.rmtree(cut / last)
    (cut / "DONE").unlink()
    forged = tmp_path / "forged"
    shutil.copytree(cut, forged)
    trainers.train(config, cut, resume=True, progress=False)
    assert _best(cut / last) == record
    for s in (0, 1):
        a = _policy_arrays(full / last / f"best_policy_seed_{s}.npz")
        b = _policy_arrays(cut / last / f"best_policy_seed_{s}.npz")
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)

    # the best comes from the checkpoint, not from a recount: an unbeatable record survives
    meta = json.loads((forged / first / "meta.json").read_text())
    meta["best"]["seeds"]["0"]["return"] = 1e9
    (forged / first / "meta.json").write_text(json.dumps(meta))
    trainers.train(config, forged, resume=True, progress=False)
    assert _best(forged / last)["seeds"]["0"] == {"step": 512, "return": 1e9}
    assert _best(forged / last)["seeds"]["1"] == record["seeds"]["1"]
    kept = _policy_arrays(forged / last / "best_policy_seed_0.npz")
    for key, value in _policy_arrays(forged / first / "best_policy_seed_0.npz").items():
        np.testing.assert_array_equal(kept[key], value, err_msg=key)

    # a checkpoint whose best policy file is missing is damaged (its meta.json lists the file
    # and its checksum): one line, no resume
    (forged / "DONE").unlink()
    shutil.rmtree(forged / last)
    (forged / first / "best_policy_seed_1.npz").unlink()
    with pytest.raises(UsageError, match="has no intact checkpoint") as err:
        trainers.train(config, forged, resume=True, progress=False)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("uncertainty_set", ["ds", "ipm"])
def test_a_seed_gives_the_same_bits_alone_and_among_other_seeds(tmp_path, uncertainty_set):
    """A seed's CSVs, policies and checkpoint arrays are a function of (code, config, seed):
    seed 3 trained alone and beside seed 0 are bit-identical. With 512-step rollouts, four updates,
    one vmapped call over both seeds changed seed 3's loss_pi in the last digits (f7f5ab1)."""
    from adarl.runs import checkpoints

    config = _config(uncertainty_set=uncertainty_set, total_steps=2048, rollout_steps=512, checkpoint_every=2048)  # fmt: skip
    alone, group = tmp_path / "alone", tmp_path / "group"
    trainers.train(dataclasses.replace(config, seeds=(3,)), alone, progress=False)
    trainers.train(dataclasses.replace(config, seeds=(0, 3)), group, progress=False)
    import yaml

    doc = yaml.safe_load((group / "config.yaml").read_text())
    assert doc["algo"] == "rnac" and doc["uncertainty_set"] == uncertainty_set
    for name in ("episodes", "train", "eval"):
        assert _rows(alone, name) == _rows(group, name, seed=3), name
    assert len(_rows(alone, "train")) == 8  # every 256 steps: four updates logged
    last = "checkpoints/step_000000002048"
    for name in ("policy_seed_3.npz", "best_policy_seed_3.npz"):
        a, b = _policy_arrays(alone / last / name), _policy_arrays(group / last / name)
        assert sorted(a) == sorted(b)
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name} {key}")
    arrays_alone, _ = checkpoints.load_checkpoint(alone / last)
    arrays_group, _ = checkpoints.load_checkpoint(group / last)
    assert_seed_slice_equal(arrays_alone, arrays_group, index=1)


# ----------------------------------------------------------------------------- bad input
def test_bad_run_folder(tmp_path):
    with pytest.raises(UsageError, match="not a run folder"):
        trainers.train(_config(), tmp_path / "missing", resume=True)
    (tmp_path / "used").mkdir()
    (tmp_path / "used" / "notes.txt").write_text("mine\n")
    with pytest.raises(UsageError, match="not empty"):
        trainers.train(_config(), tmp_path / "used")
    assert (tmp_path / "used" / "notes.txt").read_text() == "mine\n"
    with pytest.raises(UsageError):
        trainers.train(_config(task="cartpole"), tmp_path / "new")
