"""RNAC (adarl.algos.rnac): the maths against NumPy references, the double-sampling simulator,
a short run with checkpoint and exact resume, and bad input."""

from __future__ import annotations

import dataclasses
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import rnac
from adarl.errors import UsageError
from adarl.train.io import read_csv

# jitted once: eager JAX compiles every primitive separately, which is slow on 2 shared cores
gae = jax.jit(rnac.gae)
ipm_norm = jax.jit(rnac.ipm_norm)


# ----------------------------------------------------------------------------- the maths
def gae_reference(r, v, v_next, dw, done, gamma, lam, penalty=0.0):
    """The original's loop (ppo_continuous.py, PPO_continuous.update)."""
    deltas = r + gamma * (1.0 - dw) * v_next - v - penalty
    adv, g = [], 0.0
    for delta, d in zip(deltas[::-1], done[::-1]):
        g = delta + gamma * lam * g * (1.0 - d)
        adv.insert(0, g)
    adv = np.array(adv)
    return adv, adv + v


@pytest.mark.parametrize("penalty", [0.0, 0.3])
def test_gae_matches_numpy_reference(penalty):
    rng = np.random.default_rng(0)
    n = 257
    r, v, v_next = (rng.standard_normal(n) for _ in range(3))
    done = (rng.random(n) < 0.05).astype(float)
    dw = done * (rng.random(n) < 0.5)  # some ends are truncations: bootstrap through them
    adv, targets = gae(
        *(jnp.asarray(x, jnp.float32) for x in (r, v, v_next, dw, done)), 0.99, 0.95, penalty
    )
    ref_adv, ref_targets = gae_reference(r, v, v_next, dw, done, 0.99, 0.95, penalty)
    np.testing.assert_allclose(adv, ref_adv, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(targets, ref_targets, rtol=1e-5, atol=1e-5)


def test_clipped_objective_matches_numpy_reference():
    rng = np.random.default_rng(1)
    logp_old = rng.standard_normal(500)
    logp_new = logp_old + 0.3 * rng.standard_normal(500)
    adv = rng.standard_normal(500)
    ratio = np.exp(logp_new - logp_old)
    ref = np.minimum(ratio * adv, np.clip(ratio, 0.8, 1.2) * adv)
    got = rnac.ppo_clip_objective(
        jnp.asarray(logp_new), jnp.asarray(logp_old), jnp.asarray(adv), 0.2
    )
    np.testing.assert_allclose(got, ref, rtol=1e-5)
    # where the ratio has left [1-ε, 1+ε] in the direction the advantage favours, no gradient
    grad = jax.grad(lambda lp: jnp.sum(rnac.ppo_clip_objective(lp, logp_old, adv, 0.2)))(logp_new)
    frozen = ((adv > 0) & (ratio > 1.2)) | ((adv < 0) & (ratio < 0.8))
    assert frozen.any() and np.all(np.asarray(grad)[frozen] == 0)
    np.testing.assert_allclose(np.asarray(grad)[~frozen], (ratio * adv)[~frozen], rtol=1e-5)


def test_gaussian_log_prob_and_entropy():
    rng = np.random.default_rng(2)
    a, mean = rng.standard_normal((2, 7, 3))
    log_std = rng.standard_normal(3) * 0.5
    std = np.exp(log_std)
    ref = np.sum(-((a - mean) ** 2) / (2 * std**2) - np.log(std) - 0.5 * np.log(2 * np.pi), -1)
    np.testing.assert_allclose(rnac.gaussian_log_prob(a, mean, log_std), ref, rtol=1e-5)
    np.testing.assert_allclose(rnac.gaussian_log_prob(a, mean, log_std, np), ref, rtol=1e-12)
    np.testing.assert_allclose(
        rnac.gaussian_entropy(log_std), np.sum(0.5 * np.log(2 * np.pi * np.e * std**2)), rtol=1e-5
    )


def test_ipm_penalty_value():
    critic = rnac.init_critic(np.random.default_rng(0), 11, (64, 64))
    critic["out"]["b"] = np.asarray([5.0], np.float32)  # the output bias is not in the norm
    critic["trunk"][0]["b"] = np.full(64, 0.1, np.float32)  # hidden biases are
    squares = sum(
        float(np.sum(np.asarray(x) ** 2)) for layer in critic["trunk"] for x in layer.values()
    )
    squares += float(np.sum(np.asarray(critic["out"]["w"]) ** 2))
    assert float(ipm_norm(critic)) == pytest.approx(np.sqrt(squares), rel=1e-6)
    # the penalty lowers every TD residual by weight_reg·‖θ‖: with no episode end the advantage
    # drops by weight_reg·‖θ‖·Σ_k (γλ)^k, counted to the end of the rollout
    n, gamma, lam, penalty = 50, 0.99, 0.95, 1e-5 * float(ipm_norm(critic))
    zeros = jnp.zeros(n)
    adv, _ = gae(zeros, zeros, zeros, zeros, zeros, gamma, lam, penalty)
    expected = -penalty * np.array(
        [sum((gamma * lam) ** k for k in range(n - t)) for t in range(n)]
    )
    np.testing.assert_allclose(adv, expected, rtol=1e-5)


def test_worst_case_selection_picks_the_lowest_valued_candidate():
    critic = rnac.init_critic(np.random.default_rng(1), 11, (64, 64))
    candidates = np.random.default_rng(3).standard_normal((5, 11)).astype(np.float32)
    values = rnac.critic_value(critic, candidates, np)
    assert rnac.select_candidate(values, worst=True, random_index=4) == int(np.argmin(values))
    assert values[rnac.select_candidate(values, True, 0)] == values.min()
    assert rnac.select_candidate(values, worst=False, random_index=4) == 4
    np.testing.assert_allclose(
        values, rnac.critic_value(critic, jnp.asarray(candidates)), rtol=1e-5
    )
    # the draws: noise within ±noise, the worst case with probability δ, random index uniform
    rng = np.random.default_rng(4)
    draws = [rnac.draw_double_sampling(rng, 3, 2, 5e-3, 0.25) for _ in range(4000)]
    assert all(np.abs(d[0]).max() <= 5e-3 and d[0].shape == (3, 2) for d in draws)
    assert np.mean([d[1] for d in draws]) == pytest.approx(0.25, abs=0.03)
    assert np.bincount([d[2] for d in draws], minlength=3) / 4000 == pytest.approx(
        [1 / 3] * 3, abs=0.04
    )


# ----------------------------------------------------------------------------- double sampling
@pytest.mark.parametrize("task", ["hopper", "walker2d", "ant", "humanoid"])
def test_state_copy_round_trip(task):
    """Candidates come from the real env's exact state under the current episode's model: the
    real env stepping with a candidate's action lands bit-exactly on that candidate."""
    from adarl.envs import make

    env = make(task, dynamics="paper", seed=0)
    shadow = rnac.ShadowSimulator(env)
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
def _config(**kw) -> rnac.RNACConfig:
    # the first checkpoint (640) falls inside a rollout (256 steps): its buffer is checkpointed
    base = dict(
        rnac.PRESETS["smoke"], total_steps=1024, checkpoint_every=640, eval_every=512, log_every=256
    )
    return rnac.RNACConfig(**{**base, **kw})


def _rows(run, name, seed=None):
    rows = read_csv(run / f"{name}.csv")
    for r in rows:
        r.pop("steps_per_s", None)
    return [r for r in rows if seed is None or r["seed"] == str(seed)]


def test_run_checkpoint_and_exact_resume(tmp_path):
    config = _config(seeds=(0, 1))
    full = tmp_path / "full"
    rnac.train(config, full)
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
    from adarl.train.io import load_checkpoint, unflatten_tree

    arrays, _ = load_checkpoint(full / "checkpoints/step_000000001024")
    state = unflatten_tree(rnac.init_states([0, 1], config, 11, 3)[0], arrays, "state")
    actor = jax.tree.map(lambda x: np.asarray(x[1]), state.actor)
    count, m2 = arrays["host/obs_count"][1], arrays["host/obs_m2"][1]
    obs = np.random.default_rng(5).standard_normal((4, 11))
    norm = rnac.normalise_obs(obs, arrays["host/obs_mean"][1], m2 / count, config.obs_clip)
    expected = rnac.actor_mean(actor, norm, -np.ones(3), np.ones(3), np)
    policy = load(full / "checkpoints/step_000000001024/policy_seed_1.npz")
    np.testing.assert_allclose(policy(obs), expected, rtol=1e-5, atol=1e-6)
    before = (full / "train.csv").read_bytes()
    rnac.train(config, full, resume=True)  # a finished run: nothing to do
    assert (full / "train.csv").read_bytes() == before

    # kill after the first checkpoint: later checkpoint, DONE and half a CSV line are lost
    cut = tmp_path / "cut"
    shutil.copytree(full, cut)
    shutil.rmtree(cut / "checkpoints/step_000000001024")
    (cut / "DONE").unlink()
    with open(cut / "episodes.csv", "a") as f:
        f.write("1000,0,99,12.")
    # resumed with candidates simulated at every step (the original's way): same transitions
    rnac.train(dataclasses.replace(config, eager_candidates=True), cut, resume=True)
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

    from adarl.evaluation.rollout import run_episodes
    from adarl.policy import load

    config = _config(seeds=(0, 1))
    full, last, first = (
        tmp_path / "full",
        "checkpoints/step_000000001024",
        "checkpoints/step_000000000640",
    )
    rnac.train(config, full, progress=False)
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
    rnac.train(config, cut, resume=True, progress=False)
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
    rnac.train(config, forged, resume=True, progress=False)
    assert _best(forged / last)["seeds"]["0"] == {"step": 512, "return": 1e9}
    assert _best(forged / last)["seeds"]["1"] == record["seeds"]["1"]
    kept = _policy_arrays(forged / last / "best_policy_seed_0.npz")
    for key, value in _policy_arrays(forged / first / "best_policy_seed_0.npz").items():
        np.testing.assert_array_equal(kept[key], value, err_msg=key)

    # a checkpoint whose best policy file is missing: one line, no resume
    (forged / "DONE").unlink()
    shutil.rmtree(forged / last)
    (forged / first / "best_policy_seed_1.npz").unlink()
    with pytest.raises(UsageError, match="has no best_policy_seed_1.npz") as err:
        rnac.train(config, forged, resume=True, progress=False)
    assert "\n" not in str(err.value)


def test_ipm_run_and_seed_grouping(tmp_path):
    """IPM trains too; a seed trained alone logs what it logs when trained with others."""
    alone = tmp_path / "alone"
    rnac.train(_config(seeds=(1,), uncertainty_set="ipm", total_steps=512), alone)
    group = tmp_path / "group"
    rnac.train(_config(seeds=(0, 1), uncertainty_set="ipm", total_steps=512), group)
    import yaml

    doc = yaml.safe_load((group / "config.yaml").read_text())
    assert doc["algo"] == "rnac" and doc["uncertainty_set"] == "ipm" and doc["seeds"] == [0, 1]
    for name in ("episodes", "train", "eval"):
        assert _rows(alone, name) == _rows(group, name, seed=1), name


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "change, words",
    [
        ({"uncertainty_set": "kl"}, "uncertainty set 'kl'"),
        ({"delta": 1.5}, "delta"),
        ({"delta": -0.1}, "delta"),
        ({"n_candidates": 0}, "n-candidates"),
        ({"total_steps": 0}, "total-steps"),
        ({"rollout_steps": 100}, "multiple of minibatch-size"),
        ({"seeds": ()}, "seeds"),
        ({"eval_every": -5}, "eval-every"),
    ],
)
def test_bad_config_raises_one_line_usage_error(change, words):
    config = dataclasses.replace(rnac.RNACConfig(), **change)
    with pytest.raises(UsageError, match=words) as err:
        config.validate()
    assert "\n" not in str(err.value)


def test_bad_run_folder(tmp_path):
    with pytest.raises(UsageError, match="not a run folder"):
        rnac.train(_config(), tmp_path / "missing", resume=True)
    (tmp_path / "used").mkdir()
    (tmp_path / "used" / "notes.txt").write_text("mine\n")
    with pytest.raises(UsageError, match="not empty"):
        rnac.train(_config(), tmp_path / "used")
    assert (tmp_path / "used" / "notes.txt").read_text() == "mine\n"
    with pytest.raises(UsageError):
        rnac.train(_config(task="cartpole"), tmp_path / "new")


def test_presets_are_valid_configs():
    assert rnac.CONFIG_CLASS is rnac.RNACConfig
    for name, overrides in rnac.PRESETS.items():
        rnac.RNACConfig(**overrides).validate(), name
