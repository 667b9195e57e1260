"""`--env-kwargs` as adarl reads it (`adarl.envs.tasks.parse_env_kwargs`): values YAML will not
build, non-finite numbers and an `xml_file` that is not a regular file are one-line errors
before anything is made or written (issue 61 §6, §7); plain values still read as before."""

import os

import pytest

from adarl.envs.tasks import parse_env_kwargs
from adarl.errors import UsageError


def test_plain_values_read_as_yaml_and_json():
    assert parse_env_kwargs("frame_skip=5,reset_noise_scale=0.1,xml_file=a.xml") == {
        "frame_skip": 5, "reset_noise_scale": 0.1, "xml_file": "a.xml"
    }  # fmt: skip
    assert parse_env_kwargs('{"frame_skip": 5}') == {"frame_skip": 5}


@pytest.mark.parametrize(
    "text",
    ["x=!!python/object/apply:os.system [echo pwned]", "frame_skip=[1", "a=!!binary x"],
)
def test_values_yaml_will_not_build_are_one_line_errors(text):
    with pytest.raises(UsageError, match="bad env-kwargs value"):
        parse_env_kwargs(text)


@pytest.mark.parametrize("text", ["reset_noise_scale=.nan", "reset_noise_scale=.inf", '{"a": NaN}'])
def test_non_finite_numbers_are_refused(text):
    with pytest.raises(UsageError, match="allowed: a finite number"):
        parse_env_kwargs(text)


def test_an_xml_file_that_is_not_a_regular_file_is_refused(tmp_path):
    fifo = tmp_path / "robot.xml"
    os.mkfifo(fifo)
    with pytest.raises(UsageError, match="is not a regular file"):
        parse_env_kwargs(f"xml_file={fifo}")
    with pytest.raises(UsageError, match="is not a regular file"):
        parse_env_kwargs({"xml_file": str(tmp_path)})  # a folder
    regular = tmp_path / "ok.xml"
    regular.write_text("<mujoco/>")
    assert parse_env_kwargs(f"xml_file={regular}") == {"xml_file": str(regular)}


def _returns_42(**kwargs):
    return 42


def _needs_a_missing_package(**kwargs):
    raise ImportError("No module named 'box2d_that_is_not_installed'")


@pytest.mark.parametrize(
    ("entry_point", "needle"),
    [
        (_returns_42, r"returned 42 \(int\), not a Gymnasium env"),
        (_needs_a_missing_package, "cannot make env .*ImportError: No module named"),
        ("no_such_package_xyz.envs:Env", "cannot make env .*ModuleNotFoundError"),
    ],
)
def test_an_env_that_cannot_be_made_is_one_line_naming_the_task(entry_point, needle):
    # issue 61 §6: a missing dependency (CarRacing-v3 without Box2D), a missing entry point
    # and an entry point that is not an env were tracebacks
    import gymnasium

    from adarl.envs.tasks import get_task

    env_id = "adarltest/Broken-v0"
    gymnasium.register(env_id, entry_point=entry_point)
    try:
        with pytest.raises(UsageError, match=needle):
            get_task(env_id, env_kwargs={"x": 1})
    finally:
        del gymnasium.registry[env_id]


class _Env:
    """A tiny Gymnasium env whose reset/step can be made wrong, one way at a time."""

    def __init__(self, how="ok", **kwargs):
        import gymnasium
        import numpy as np

        self.how = how
        self.observation_space = gymnasium.spaces.Box(-1.0, 1.0, (3,), np.float64)
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def reset(self, seed=None, options=None):
        import numpy as np

        return np.zeros(2 if self.how == "reset-shape" else 3), {}

    def step(self, action):
        import numpy as np

        if self.how == "step-four":
            return np.zeros(3), 0.0, False, {}
        if self.how == "step-raises":
            raise RuntimeError("boom")
        return np.zeros(3), float("nan") if self.how == "nan-reward" else 0.0, False, False, {}

    def close(self):
        pass


def _env(how):
    import gymnasium

    class Env(_Env, gymnasium.Env):
        pass

    return Env(how)


@pytest.mark.parametrize(
    ("how", "needle"),
    [
        ("reset-shape", r"reset\(\) returned an observation of 2 numbers, but its observation space has 3"),
        ("step-four", r"step\(\) returned .*not Gymnasium's \(obs, reward"),
        ("step-raises", r"fails when reset and stepped once \(RuntimeError: boom\)"),
        ("nan-reward", r"step\(\) returned the reward nan"),
    ],
)  # fmt: skip
def test_an_env_that_breaks_gymnasiums_contract_is_one_line_before_training(how, needle):
    # issue 61 §6: a wrong observation shape or a bad step return were tracebacks from inside
    # adarl after the run folder was written; the env is now reset and stepped once when probed
    import gymnasium

    from adarl.envs.tasks import get_task

    env_id = "adarltest/Contract-v0"
    gymnasium.register(env_id, entry_point=lambda **kw: _env(how))
    try:
        with pytest.raises(UsageError, match=f"task '{env_id}': .*" + needle if "fails" not in needle else needle):  # fmt: skip
            get_task(env_id, env_kwargs={"x": 1})
    finally:
        del gymnasium.registry[env_id]
    gymnasium.register(env_id, entry_point=lambda **kw: _env("ok"))
    try:
        assert get_task(env_id, env_kwargs={"x": 2}).obs_dim == 3
    finally:
        del gymnasium.registry[env_id]


def test_render_mode_in_env_kwargs_is_refused():
    with pytest.raises(UsageError, match="adarl renders only in `adarl play`"):
        parse_env_kwargs("render_mode=human")
