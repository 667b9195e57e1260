"""A user's own MuJoCo robot, as a user would bring it: an XML the test writes (`write_xml`) and
a `MujocoEnv` subclass registered as `adarltest/PointBot-v0` when this module is imported
(`--env-module user_env`). A ball pushed by two motors on a floor, rewarded for reaching (1, 1)."""

from pathlib import Path

import gymnasium
import numpy as np
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv

ENV_ID = "adarltest/PointBot-v0"
XML = """<mujoco model="pointbot">
  <option timestep="0.01"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1" friction="1 0.005 0.0001"/>
    <body name="ball" pos="0 0 0.1">
      <joint name="slide_x" type="slide" axis="1 0 0" damping="0.5"/>
      <joint name="slide_y" type="slide" axis="0 1 0" damping="0.5"/>
      <geom name="ball_geom" type="sphere" size="0.1" mass="1.0"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="push_x" joint="slide_x" gear="5" ctrlrange="-1 1"/>
    <motor name="push_y" joint="slide_y" gear="5" ctrlrange="-1 1"/>
  </actuator>
</mujoco>
"""


def write_xml(folder) -> Path:
    """The robot's XML in `folder`; its path."""
    path = Path(folder) / "pointbot.xml"
    path.write_text(XML)
    return path


class PointBot(MujocoEnv):
    metadata = {
        "render_modes": ["human", "rgb_array", "depth_array", "rgbd_tuple"],
        "render_fps": 50,
    }

    def __init__(self, xml_file: str, **kwargs):
        obs = gymnasium.spaces.Box(-np.inf, np.inf, (4,), np.float64)
        MujocoEnv.__init__(self, str(xml_file), 2, observation_space=obs, **kwargs)

    def step(self, action):
        self.do_simulation(action, self.frame_skip)
        reward = -float(np.linalg.norm(self.data.qpos - 1.0))
        return self._get_obs(), reward, False, False, {}

    def reset_model(self):
        qpos = self.init_qpos + self.np_random.uniform(-0.1, 0.1, self.model.nq)
        self.set_state(qpos, self.init_qvel)
        return self._get_obs()

    def _get_obs(self):
        return np.concatenate([self.data.qpos, self.data.qvel])


if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point=PointBot, max_episode_steps=100)


class Drift(gymnasium.Env):
    """A plain (not MuJoCo) continuous env whose state is not a `state` array: adarl trains and
    checkpoints it, and refuses to resume it (its position cannot be captured exactly)."""

    observation_space = gymnasium.spaces.Box(-10.0, 10.0, (1,), np.float64)
    action_space = gymnasium.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.position = float(self.np_random.uniform(-1, 1))
        return np.array([self.position]), {}

    def step(self, action):
        self.position = float(np.clip(self.position + 0.1 * float(action[0]), -10, 10))
        return np.array([self.position]), -abs(self.position), False, False, {}


DRIFT_ID = "adarltest/Drift-v0"
if DRIFT_ID not in gymnasium.registry:
    gymnasium.register(DRIFT_ID, entry_point=Drift, max_episode_steps=50)
