"""Evaluation: planning and checks, determinism (same seed, same returns; one worker or two),
the CSV and its sidecar, and NumPy policy files (round trip, export)."""

import json
import pickle

import numpy as np
import pandas as pd
import pytest
from synthetic_runs import policy_arrays, write_run

from adarl.errors import UsageError
from adarl.evaluation import evaluate, parallel
from adarl.export.policy import export_policy
from adarl.policy import load, save
from adarl.results.collect import final_scores
from adarl.results.runs import find_runs, load_run
from adarl.runs.checkpoints import policy_file

pytest.importorskip("mujoco")

SHORT = {"episodes": 2, "max_steps": 25}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return load_run(write_run(tmp_path_factory.mktemp("ev"), "adarl", seeds=(0, 1)))


def spec(**kwargs):
    options = {"dynamics": "nominal", "sweeps": (), "holds": ()}
    options.update({k: kwargs.pop(k) for k in list(kwargs) if k in options})
    return evaluate.EvalSpec.from_options(**options, **{**SHORT, **kwargs})


def test_plan_covers_every_seed_and_grid_point(run):
    units = evaluate.plan(
        [run], spec(sweeps=["torso_length=0.3:0.5:3"], holds=["foot_length=0.39"])
    )
    assert len(units) == 3 * 2
    assert {u.seed for u in units} == {0, 1} and {u.step for u in units} == {10_000}
    assert units[0].label == "nominal:torso_length=0.3,foot_length=0.39"
    assert dict(units[-1].point) == {"torso_length": 0.5, "foot_length": 0.39}
    assert pickle.loads(pickle.dumps(units[0])) == units[0]  # what a spawned worker receives


def test_the_episode_budget_counts_every_seed_of_every_run(run, tmp_path, monkeypatch):
    """3 points x (2 + 3) seeds x 2 episodes = 30 episodes: a budget of 29 refuses them."""
    other = load_run(write_run(tmp_path, "other", seeds=(0, 1, 2)))
    sweep = spec(sweeps=["torso_length=0.3:0.5:3"])
    monkeypatch.setattr(evaluate.grid, "MAX_EPISODES", 29)
    with pytest.raises(UsageError, match="3 points x 5 seeds x 2 episodes are 30 episodes"):
        evaluate.plan([run, other], sweep)
    with pytest.raises(UsageError, match="3 points x 3 seeds x 2 episodes are 18 episodes"):
        monkeypatch.setattr(evaluate.grid, "MAX_EPISODES", 17)
        evaluate.plan([other], sweep)
    monkeypatch.setattr(evaluate.grid, "MAX_EPISODES", 30)
    assert len(evaluate.plan([run, other], sweep)) == 3 * 5


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"sweeps": ["gravity=5:15:3"]}, "unknown parameter 'gravity' of task hopper"),
        ({"sweeps": ["torso_length=-0.2:0.2:3"]}, "bad value"),
        ({"dynamics": "sideways"}, "unknown dynamics"),
        ({"dynamics": "default", "holds": ["mass_scale=2"]}, "takes no values"),
        ({"checkpoint": 123}, "no checkpoint at step 123"),
    ],
)
def test_bad_requests_fail_before_any_episode(run, kwargs, fragment):
    with pytest.raises(UsageError, match=fragment):
        evaluate.plan([run], spec(**kwargs))


def test_bad_episode_counts():
    with pytest.raises(UsageError, match="--episodes must be ≥ 1"):
        evaluate.EvalSpec.from_options(episodes=0)
    with pytest.raises(UsageError, match="--workers"):
        parallel.run_units([], workers=0)


def test_same_seed_same_returns_with_one_or_two_workers(run):
    s = spec(sweeps=["torso_length=0.3,0.5"], holds=["foot_length=0.39"])
    (a,) = evaluate.evaluate_runs([run], s, workers=1)
    (b,) = evaluate.evaluate_runs([run], s, workers=1)
    (c,) = evaluate.evaluate_runs([run], s, workers=2)  # two spawned processes
    pd.testing.assert_frame_equal(a, b)
    pd.testing.assert_frame_equal(a, c)
    assert len(a) == 2 * 2 * 2  # points × seeds × episodes
    assert list(a.columns[: len(evaluate.COLUMNS)]) == evaluate.COLUMNS
    assert sorted(a["p_torso_length"].unique()) == [0.3, 0.5]
    assert set(a["p_foot_length"]) == {0.39}
    assert (a["length"] <= 25).all() and np.isfinite(a["return"]).all()
    # another evaluation seed gives other initial states, hence (generically) other returns
    (d,) = evaluate.evaluate_runs(
        [run],
        spec(sweeps=["torso_length=0.3,0.5"], holds=["foot_length=0.39"], eval_seed=7),
        workers=1,
    )
    assert not np.allclose(a["return"], d["return"])


def test_written_csv_and_sidecar_feed_the_final_score(tmp_path):
    run = load_run(write_run(tmp_path, "r", seeds=(0, 1)))
    s = spec()
    (table,) = evaluate.evaluate_runs([run], s, workers=1)
    path = evaluate.write_evaluation(
        table, evaluate.default_output(run, s), s, run, "adarl evaluate r"
    )
    assert path == run.path / "evaluations" / "nominal.csv"
    meta = json.loads(path.with_suffix(".json").read_text())
    assert meta["checkpoint_step"] == 10_000 and meta["seeds"] == [0, 1] and meta["sweep"] == {}
    assert meta["command"] == "adarl evaluate r"
    # truncated episodes (max_episode_steps) are not a final score: eval.csv is used instead
    assert final_scores(run)[1].startswith("eval.csv")
    meta["max_episode_steps"] = None  # as if the episodes had run to the end
    path.with_suffix(".json").write_text(json.dumps(meta))
    scores, note = final_scores(run)
    assert note.startswith("`adarl evaluate`") and list(scores["seed"]) == [0, 1]
    assert scores["score"].to_numpy() == pytest.approx(
        table.groupby("seed")["return"].mean().to_numpy()
    )
    summary = evaluate.summarise(table)
    assert list(summary.columns) == ["dynamics", "mean", "std", "seeds"]


def test_all_seeds_of_several_runs_are_evaluated_together(tmp_path):
    write_run(tmp_path, "a", seeds=(0,))
    write_run(tmp_path, "b", algo="sac", seeds=(4, 5))
    tables = evaluate.evaluate_runs(find_runs([tmp_path]), spec(episodes=1), workers=1)
    assert [sorted(t["seed"].unique()) for t in tables] == [[0], [4, 5]]


def test_numpy_policy_round_trip_by_hand(tmp_path):
    arrays = policy_arrays(obs_dim=4, act_dim=2, seed=3, hidden=5, rank=2)
    save(tmp_path / "p.npz", arrays)
    policy = load(tmp_path / "p.npz")
    obs = np.random.default_rng(0).normal(size=(6, 4)).astype(np.float32)
    h = np.maximum(obs @ arrays["l0_w"] + arrays["l0_b"], 0)
    h = np.maximum(h @ arrays["l1_w1"] @ arrays["l1_w2"] + arrays["l1_b"], 0)
    expected = np.tanh(h @ arrays["mean_w"] + arrays["mean_b"])
    assert policy(obs) == pytest.approx(expected, abs=1e-6)
    assert policy(obs[0]).shape == (2,)
    # 4·5+5 (dense) + 5·2+2·5+5 (bottleneck) + 5·2+2 (head) = 62
    assert policy.n_params() == 62
    assert int(arrays["n_params_full"]) == 4 * 5 + 5 + 2 * 5 * 5 + 5 + 5 * 2 + 2


def test_export_copies_the_policy_and_counts_parameters(tmp_path):
    run = load_run(write_run(tmp_path, "r", seeds=(0, 1), algo="sac-fixed-rank", rank=4))
    done = export_policy(run, 1, tmp_path / "out" / "policy.npz")
    source = policy_file(run.path, 1)
    assert done.out.read_bytes() == source.read_bytes()
    obs = np.ones(11, np.float32)
    assert np.array_equal(load(done.out)(obs), load(source)(obs))
    assert (done.obs_dim, done.act_dim, done.step) == (11, 3, 10_000)
    assert done.n_params < done.n_params_full and 0 < done.kept < 1
    with pytest.raises(UsageError, match="is a folder"):
        export_policy(run, 1, tmp_path)


# ----------------------------------------------------------------------------- any task
def write_task_run(root, name, task, dims, params, **kwargs):
    """A synthetic run of a task `synthetic_runs` does not know (`dims`: obs, act sizes)."""
    import synthetic_runs

    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(synthetic_runs.DIMS, task, dims)
        patch.setitem(synthetic_runs.PARAMS, task, params)
        return load_run(write_run(root, name, task=task, **kwargs))


CHEETAH_PARAMS = {"mass_scale": 1.0, "friction_scale": 1.0}


@pytest.fixture(scope="module")
def cheetah(tmp_path_factory):
    return write_task_run(
        tmp_path_factory.mktemp("hc"), "sac", "HalfCheetah-v5", (17, 6), CHEETAH_PARAMS,
        algo="sac", seeds=(0,),
    )  # fmt: skip


def test_a_gymnasium_task_sweeps_generic_and_addressed_parameters(cheetah):
    s = spec(
        sweeps=["body:torso.mass=4:9:2"], holds=["friction_scale=0.5"], episodes=1, max_steps=5
    )
    units = evaluate.plan([cheetah], s)
    assert [u.label for u in units] == [
        "nominal:body:torso.mass=4,friction_scale=0.5",
        "nominal:body:torso.mass=9,friction_scale=0.5",
    ]
    (table,) = evaluate.tables([cheetah], units, workers=1)
    assert list(table["p_body:torso.mass"]) == [4.0, 9.0]
    assert set(table["p_friction_scale"]) == {0.5} and set(table["length"]) == {5}
    # the model's elements are checked before any episode, in one line naming them
    with pytest.raises(UsageError) as err:
        evaluate.plan([cheetah], spec(sweeps=["body:nothing.mass=4:9:2"]))
    assert "unknown body 'nothing'" in str(err.value) and "bthigh" in str(err.value)
    with pytest.raises(UsageError, match="implausible value 0.01 for body:torso.mass"):
        evaluate.plan([cheetah], spec(sweeps=["body:torso.mass=0.01,1"]))
    with pytest.raises(UsageError, match="unknown parameter 'torso_length' of task HalfCheetah"):
        evaluate.plan([cheetah], spec(sweeps=["torso_length=0.3,0.4"]))


def test_a_paper_task_sweeps_addressed_parameters_under_consistent_physics(run, tmp_path):
    units = evaluate.plan([run], spec(sweeps=["body:torso.mass=2,4"], episodes=1))
    assert [dict(u.point) for u in units[::2]] == [
        {"body:torso.mass": 2.0},
        {"body:torso.mass": 4.0},
    ]
    ompo = load_run(write_run(tmp_path, "ompo", seeds=(0,), extra_config={"physics": "ompo"}))
    assert dict(evaluate.plan([ompo], spec(sweeps=["mass_scale=1,2"]))[0].env)["physics"] == "ompo"
    with pytest.raises(UsageError) as err:
        evaluate.plan([ompo], spec(sweeps=["body:torso.mass=2,4"]))
    assert "needs physics 'consistent'" in str(err.value) and "\n" not in str(err.value)


def test_a_users_own_xml_and_module_are_the_runs(tmp_path):
    """The run's env-kwargs and env-module make its evaluation envs: a body only the run's XML
    has is found, and the episodes run on the user's registered class."""
    import user_env

    xml = tmp_path / "bot.xml"
    xml.write_text(user_env.XML.replace('name="ball"', 'name="puck"'))
    config = {"env_module": "user_env", "env_kwargs": f"xml_file={xml}"}
    bot = write_task_run(
        tmp_path, "bot", user_env.ENV_ID, (4, 2), {"mass_scale": 1.0}, algo="sac", seeds=(0, 1),
        extra_config=config,
    )  # fmt: skip
    s = spec(sweeps=["body:puck.mass=0.5,2"], holds=["joint:slide_x.damping=1"], max_steps=3)
    units = evaluate.plan([bot], s)
    assert dict(units[0].env) == {"physics": "consistent", "model_version": "v5", **config}
    (table,) = evaluate.tables([bot], units, workers=1)
    assert len(table) == 2 * 2 * 2 and set(table["length"]) == {3}
    assert sorted(set(table["p_body:puck.mass"])) == [0.5, 2.0]
    with pytest.raises(UsageError, match="unknown body 'ball'"):
        evaluate.plan([bot], spec(sweeps=["body:ball.mass=0.5,2"]))
    # another run of the same id on another XML is checked on its own model
    plain = tmp_path / "plain.xml"
    plain.write_text(user_env.XML)
    other = write_task_run(
        tmp_path, "other", user_env.ENV_ID, (4, 2), {"mass_scale": 1.0}, algo="adarl",
        seeds=(0,), extra_config={**config, "env_kwargs": f"xml_file={plain}"},
    )  # fmt: skip
    with pytest.raises(UsageError, match="unknown body 'puck'"):
        evaluate.plan([bot, other], s)
    s = spec(episodes=1, max_steps=3)
    path = evaluate.write_evaluation(evaluate.tables([bot], evaluate.plan([bot], s))[0],
                                     tmp_path / "e.csv", s, bot)  # fmt: skip
    meta = json.loads(path.with_suffix(".json").read_text())
    assert (meta["task"], meta["env_module"], meta["env_kwargs"]) == (
        user_env.ENV_ID,
        "user_env",
        f"xml_file={xml}",
    )


def test_a_task_with_fixed_dynamics_evaluates_nominal_only(tmp_path):
    pendulum = write_task_run(tmp_path, "p", "Pendulum-v1", (3, 1), {}, algo="sac", seeds=(0,))
    (table,) = evaluate.evaluate_runs([pendulum], spec(episodes=1, max_steps=4), workers=1)
    assert len(table) == 1 and table["length"].iloc[0] == 4
    with pytest.raises(UsageError, match=r"allowed: \(none: fixed dynamics\)"):
        evaluate.plan([pendulum], spec(sweeps=["mass_scale=1,2"]))
    with pytest.raises(UsageError, match="has fixed dynamics"):
        evaluate.plan([pendulum], spec(dynamics="uniform"))


V5 = [
    "Ant-v5", "HalfCheetah-v5", "Hopper-v5", "Humanoid-v5", "HumanoidStandup-v5",
    "InvertedDoublePendulum-v5", "InvertedPendulum-v5", "Pusher-v5", "Reacher-v5", "Swimmer-v5",
    "Walker2d-v5",
]  # fmt: skip


@pytest.mark.parametrize("gym_id", V5)
def test_every_gymnasium_mujoco_task_evaluates_on_a_grid(tmp_path, gym_id):
    """A generic and an addressed parameter (the model's first body's mass, read with MuJoCo)."""
    import gymnasium
    import mujoco

    env = gymnasium.make(gym_id)
    model, dims = env.unwrapped.model, (env.observation_space.shape[0], env.action_space.shape[0])
    env.close()
    body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, 1)
    mass = float(model.body_mass[1])
    run = write_task_run(tmp_path, "r", gym_id, dims, {"mass_scale": 1.0}, algo="sac", seeds=(0,))
    s = spec(sweeps=[f"body:{body}.mass={mass / 2:g},{mass * 2:g}"], holds=["damping_scale=2"],
             episodes=1, max_steps=3)  # fmt: skip
    (table,) = evaluate.evaluate_runs([run], s, workers=1)
    assert list(table[f"p_body:{body}.mass"]) == [float(f"{mass / 2:g}"), float(f"{mass * 2:g}")]
    assert set(table["p_damping_scale"]) == {2.0} and (table["length"] <= 3).all()
    assert np.isfinite(table["return"]).all()
