"""adarl: AdaRL (Adaptive Rank Representation) soft actor-critic and baselines for robust RL
under model uncertainty on MuJoCo tasks with episode-varying dynamics."""

__version__ = "0.1.0"

from adarl.envs.registration import register_envs as _register_envs  # noqa: E402

_register_envs()  # gymnasium.make("adarl/Hopper-v0", ...); Gymnasium 1.x loads no plugins
