"""adarl: AdaRL (Adaptive Rank Representation) soft actor-critic and baselines for robust RL
under model uncertainty on MuJoCo tasks with episode-varying dynamics."""

__version__ = "0.1.0"
