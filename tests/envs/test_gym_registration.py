"""Gymnasium ids (`adarl/Hopper-v0` ...), RRLS-style parameters, and the SB3 script in docs."""

import re
from pathlib import Path

import gymnasium
import numpy as np
import pytest

import adarl  # noqa: F401  (registers the ids)
from adarl.envs import get_task, make, parse_dynamics
from adarl.envs.registration import IDS, TaskEnv
from adarl.errors import UsageError

DOCS = Path(__file__).resolve().parents[2] / "docs" / "envs.md"


def test_ids_registered():
    assert set(IDS) == {
        "adarl/Hopper-v0",
        "adarl/Walker2d-v0",
        "adarl/Ant-v0",
        "adarl/Humanoid-v0",
    }
    for env_id, task in IDS.items():
        spec = gymnasium.spec(env_id)
        assert spec.kwargs == {"task": task} and spec.max_episode_steps == 1000


@pytest.mark.parametrize("env_id", sorted(IDS))
def test_make_takes_make_options(env_id):
    task = IDS[env_id]
    env = gymnasium.make(
        env_id, dynamics="ompo", physics="ompo", model_version="v4", mass_scale=1.1
    )
    assert isinstance(env.unwrapped, TaskEnv)
    obs, info = env.reset(seed=0)
    assert obs.shape == (get_task(task, "v4").obs_dim,)
    expected = parse_dynamics("ompo", task).with_overrides(mass_scale=1.1).params_for_episode(0)
    assert info["dynamics"] == expected and info["episode_index"] == 0
    assert env.unwrapped.env.physics == "ompo" and env.unwrapped.task.version == "v4"
    env.close()


def test_same_trajectory_as_adarl_make():
    ours = make("hopper", "paper", seed=3)
    theirs = gymnasium.make("adarl/Hopper-v0", dynamics="paper", seed=3)
    rng = np.random.default_rng(0)
    for _ in range(3):
        a, b = ours.reset(), theirs.reset()
        assert np.array_equal(a[0], b[0]) and a[1]["dynamics"] == b[1]["dynamics"]
        for _ in range(30):
            act = rng.uniform(-1, 1, 3).astype(np.float32)
            x, y = ours.step(act), theirs.step(act)
            assert np.array_equal(x[0], y[0]) and x[1:4] == y[1:4]
            if x[2] or x[3]:
                break


def test_time_limit_is_gymnasium_s():
    env = gymnasium.make("adarl/Hopper-v0", dynamics="nominal", max_episode_steps=5)
    env.reset(seed=0)
    steps = [env.step(np.zeros(3, np.float32)) for _ in range(5)]
    assert [s[3] for s in steps] == [False] * 4 + [True]


def test_reset_options_hold_parameters():
    env = gymnasium.make("adarl/Hopper-v0", dynamics="paper")
    _, info = env.reset(seed=0, options={"torso_length": 0.5, "foot_length": 0.3})
    assert info["dynamics"]["torso_length"] == 0.5 and info["dynamics"]["foot_length"] == 0.3
    assert env.unwrapped.get_params() == info["dynamics"]
    _, _, _, _, step_info = env.step(env.action_space.sample())
    assert step_info["dynamics"] == info["dynamics"]
    assert step_info["dynamics"] is not info["dynamics"]  # a new dict per call
    # held for later episodes; parameters not named follow the schedule (here: none left)
    _, info = env.reset(options={"torso_length": 0.45})
    assert (info["dynamics"]["torso_length"], info["dynamics"]["foot_length"]) == (0.45, 0.3)
    _, info = env.reset()
    assert info["episode_index"] == 2 and info["dynamics"]["torso_length"] == 0.45
    env.unwrapped.clear_params()
    _, info = env.reset()
    assert info["dynamics"] == parse_dynamics("paper", "hopper").params_for_episode(3)


def test_get_and_set_params():
    env = gymnasium.make("adarl/Walker2d-v0", dynamics="nominal")
    raw = env.unwrapped
    before = raw.get_params()  # before the first reset: what the first episode uses
    _, info = env.reset(seed=1)
    assert before == info["dynamics"] == parse_dynamics("nominal", "walker2d").centroid()
    raw.set_params(torso_length=0.3)
    assert raw.get_params()["torso_length"] == 0.3  # at once, as RRLS
    _, _, _, _, info = env.step(env.action_space.sample())
    assert info["dynamics"]["torso_length"] == 0.3
    assert raw.env.unwrapped.model.geom_size[1, 1] == pytest.approx(0.3)  # torso capsule
    raw.set_params({"foot_length": 0.12, "mass_scale": 1.2})
    _, info = env.reset()
    assert {k: info["dynamics"][k] for k in ("torso_length", "foot_length", "mass_scale")} == {
        "torso_length": 0.3,
        "foot_length": 0.12,
        "mass_scale": 1.2,
    }
    got = raw.get_params()
    got["torso_length"] = 9.0  # a copy
    assert raw.get_params()["torso_length"] == 0.3


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda e: e.reset(options={"torso": 0.5}), "unknown hopper parameter 'torso'"),
        (lambda e: e.reset(options={"gravity": 9.0}), "unknown hopper parameter 'gravity'"),
        (lambda e: e.reset(options={"torso_length": -1}), "bad value -1 for torso_length"),
        (lambda e: e.reset(options={"torso_length": "long"}), "bad value 'long'"),
        (lambda e: e.reset(options={"torso_length": 50.0}), "implausible value 50"),
        (lambda e: e.reset(options=[0.5]), "bad parameters [0.5]"),
        (lambda e: e.unwrapped.set_params([0.5]), "bad parameters [0.5]"),
        (lambda e: e.unwrapped.set_params(foot_length=float("nan")), "bad value nan"),
    ],
)
def test_bad_parameters(call, message):
    env = gymnasium.make("adarl/Hopper-v0", dynamics="paper")
    env.reset(seed=0)
    before = env.unwrapped.get_params()
    with pytest.raises(UsageError) as err:
        call(env)
    assert message in str(err.value) and "\n" not in str(err.value)
    assert env.unwrapped.get_params() == before  # nothing changed


def test_bad_make_options():
    for kwargs, message in [
        ({"physics": "exact"}, "unknown physics 'exact'"),
        ({"model_version": "v3"}, "unknown model version 'v3'"),
        ({"dynamics": "sometimes"}, "unknown dynamics 'sometimes'"),
        ({"tilt": 1.0}, "unknown hopper parameter 'tilt'"),
    ]:
        with pytest.raises(UsageError, match=re.escape(message)):
            gymnasium.make("adarl/Hopper-v0", **kwargs)
    env = gymnasium.make("adarl/Hopper-v0", dynamics="default")
    with pytest.raises(UsageError, match="takes no values"):
        env.reset(options={"torso_length": 0.3})


def test_sb3_script_from_docs(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3")
    torch = pytest.importorskip("torch")
    text = DOCS.read_text()
    section = text[text.index("### Training with Stable-Baselines3") :]
    start = section.index("```python\n") + len("```python\n")
    script = section[start : section.index("\n```\n", start)]
    assert 'gymnasium.make("adarl/Hopper-v0", dynamics="paper")' in script
    assert "total_timesteps=1_000_000" in script
    assert "seed=0, verbose=1" in script
    # 300 steps, 50 gradient updates on one thread: the test exercises the plumbing, not learning
    script = script.replace("total_timesteps=1_000_000", "total_timesteps=300")
    script = script.replace("seed=0, verbose=1", "seed=0, verbose=0, learning_starts=250")
    monkeypatch.chdir(tmp_path)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        exec(compile(script, str(DOCS), "exec"), {"__name__": "__main__"})
    finally:
        torch.set_num_threads(threads)
    assert (tmp_path / "sac-adarl-hopper-paper.zip").is_file()


# ----------------------------------------------------------------------------- issue 38, class 3
@pytest.mark.parametrize("value", [True, False, np.bool_(True)])
def test_a_bool_is_not_a_length(value):
    env = gymnasium.make("adarl/Hopper-v0", dynamics="nominal")
    env.reset(seed=0)
    before = env.unwrapped.get_params()
    for call in (
        lambda: env.reset(options={"torso_length": value}),
        lambda: env.unwrapped.set_params(torso_length=value),
    ):
        with pytest.raises(UsageError, match=f"bad value {value!r} for torso_length; allowed"):
            call()
    assert env.unwrapped.get_params() == before
    with pytest.raises(UsageError, match="bad value True for foot_length"):
        gymnasium.make("adarl/Hopper-v0", foot_length=True)


def test_make_refuses_a_task_keyword_naming_another_task():
    with pytest.raises(UsageError) as err:
        gymnasium.make("adarl/Hopper-v0", task="walker2d")
    message = str(err.value)
    assert "takes no task='walker2d'" in message and '"adarl/Walker2d-v0"' in message, message
    assert "\n" not in message
    with pytest.raises(UsageError, match="takes no task='cheetah'.*adarl/Humanoid-v0"):
        gymnasium.make("adarl/Hopper-v0", task="cheetah")
    # the id's own task is no change: accepted, and the spec is as registered
    env = gymnasium.make("adarl/Hopper-v0", task="hopper")
    assert env.unwrapped.task.name == "hopper" and env.spec.kwargs["task"] == "hopper"


def test_the_dynamics_dict_reset_returns_is_the_callers():
    env = gymnasium.make("adarl/Hopper-v0", dynamics="paper")
    _, first = env.reset(seed=0)
    expected = parse_dynamics("paper", "hopper").params_for_episode(0)
    assert first["dynamics"] == expected
    first["dynamics"]["torso_length"] = 123.0
    first["dynamics"]["made_up"] = 1.0
    assert env.unwrapped.get_params() == expected  # the env's own values are untouched
    _, second = env.reset()
    assert second["dynamics"] == parse_dynamics("paper", "hopper").params_for_episode(1)
    assert second["dynamics"] is not first["dynamics"]
