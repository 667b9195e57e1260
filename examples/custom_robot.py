"""AdaRL on a robot of your own: a small MuJoCo XML written here, a Gymnasium `MujocoEnv` class
for it, and `adarl.train(env_fn=...)` with the ball's mass and the floor's friction drawn anew
every episode (docs/envs.md, "Your own task").

    python examples/custom_robot.py [TOTAL_STEPS] [OUT]      # default 20000 steps, runs/pointbot

A ball pushed by two motors on a floor, rewarded for reaching (1, 1); 2 actions, so 2·d_a+1 = 5.
The run folder is an ordinary adarl run: `adarl report OUT --out OUT/report`, and resume it from
Python with `adarl.train(env_fn=make_robot, env_name="PointBot", resume=OUT)`.
"""

import sys
import tempfile
from pathlib import Path

import gymnasium
import numpy as np
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv

import adarl

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
XML_FILE = Path(tempfile.gettempdir()) / "adarl-pointbot.xml"


class PointBot(MujocoEnv):
    metadata = {
        "render_modes": ["human", "rgb_array", "depth_array", "rgbd_tuple"],
        "render_fps": 50,
    }

    def __init__(self, **kwargs):
        XML_FILE.write_text(XML)
        obs = gymnasium.spaces.Box(-np.inf, np.inf, (4,), np.float64)
        MujocoEnv.__init__(self, str(XML_FILE), 2, observation_space=obs, **kwargs)

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


def make_robot(**kwargs):
    return PointBot(**kwargs)


def main(total_steps: int = 20_000, out: str = "runs/pointbot") -> None:
    run = adarl.train(
        algo="adarl",
        env_fn=make_robot,
        env_name="PointBot",
        out=out,
        total_steps=total_steps,
        max_episode_steps=200,
        truncate_every=max(total_steps // 4, 1),
        eval_every=max(total_steps // 4, 1),
        checkpoint_every=max(total_steps // 2, 1),
        dynamics="uniform:body:ball.mass=0.5..2,geom:floor.friction=0.3..1.5",
        progress=True,
    )
    print(run.summary())
    print("final ranks:", run.final_ranks, "(2·d_a+1 = 5)")


if __name__ == "__main__":
    main(*(int(a) if i == 0 else a for i, a in enumerate(sys.argv[1:])))
