"""The Python API (adarl.api) on synthetic run folders (tests/synthetic_runs.py): what `Run`,
`load_policy` and a resume from Python give, checked against the files the run wrote (read
here with pandas and the synthetic writer's own arrays), without training."""

import gymnasium
import numpy as np
import pandas as pd
import pytest
import synthetic_runs

import adarl
from adarl.api import Run


def test_final_ranks_are_the_last_logged_steps_mean_over_seeds(tmp_path):
    path = synthetic_runs.write_run(tmp_path, "run", algo="adarl", seeds=(0, 1, 2))
    train = pd.read_csv(path / "train.csv")
    last = train[train["step"] == train["step"].max()]
    first = train[train["step"] == train["step"].min()]
    expected = {layer: last[f"rank_{layer}"].mean() for layer in synthetic_runs.LAYERS}
    assert expected != {layer: first[f"rank_{layer}"].mean() for layer in synthetic_runs.LAYERS}
    got = Run(path, "adarl", None).final_ranks
    assert got.keys() == expected.keys()
    for layer, value in expected.items():
        assert got[layer] == pytest.approx(value, rel=1e-12)


def test_final_ranks_of_a_run_without_a_bottleneck_are_empty(tmp_path):
    path = synthetic_runs.write_run(tmp_path, "run", algo="sac", seeds=(0, 1))
    assert Run(path, "sac", None).final_ranks == {}


def test_load_policy_returns_the_seed_asked_for(tmp_path):
    path = synthetic_runs.write_run(tmp_path, "run", algo="sac", seeds=(0, 1, 2))
    obs_dim, act_dim = synthetic_runs.DIMS["hopper"]
    obs = np.linspace(-1, 1, obs_dim)
    actions = []
    for seed in (0, 1, 2):
        policy = adarl.load_policy(path, seed=seed)
        written = synthetic_runs.policy_arrays(obs_dim, act_dim, seed)
        for name in ("l0_w", "l1_w", "mean_w"):
            np.testing.assert_array_equal(policy.arrays[name], written[name])
        actions.append(policy(obs))
    assert not np.array_equal(actions[0], actions[1])
    with pytest.raises(adarl.UsageError, match="no seed 7"):
        adarl.load_policy(path, seed=7)


@pytest.fixture
def registered():
    """The `adarl-fn/` ids a test registers, removed from Gymnasium's registry after it."""
    before = set(gymnasium.registry)
    yield
    for env_id in set(gymnasium.registry) - before:
        del gymnasium.registry[env_id]


def test_resuming_with_another_env_fn_is_refused(tmp_path, registered):
    path = synthetic_runs.write_run(
        tmp_path, "run", algo="sac", seeds=(0,), done=False,
        extra_config={"task": "adarl-fn/PointBot-v0"},
    )  # fmt: skip
    before = sorted(p.relative_to(path) for p in path.rglob("*"))

    def other_robot():
        raise AssertionError("the env of a refused resume was made")

    # PointBot is registered in this process too: only the env_fn given can refuse the resume
    adarl.register_env_fn(other_robot, "PointBot")

    with pytest.raises(adarl.UsageError, match="trained on task 'adarl-fn/PointBot-v0'") as info:
        adarl.train(env_fn=other_robot, env_name="OtherBot", resume=path)
    assert "adarl-fn/OtherBot-v0" in str(info.value) and "\n" not in str(info.value)
    assert sorted(p.relative_to(path) for p in path.rglob("*")) == before
