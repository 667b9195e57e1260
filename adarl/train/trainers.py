"""Which learner the one training loop (`adarl.train.loop`) trains each algorithm with: its
config class -> its `Learner` class, and `train`, which trains any config. Apart from
`adarl.algos.registry` because the learners import JAX and sit a layer above the algorithms;
`adarl.train.launch` (the path of `adarl train` and of the sweep worker) imports this only when it
trains.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

from adarl.algos import registry
from adarl.algos.rnac_config import RNACConfig
from adarl.algos.sac_config import SACConfig
from adarl.train import loop
from adarl.train.device_learner import DeviceSACLearner
from adarl.train.learner import Learner
from adarl.train.rnac_learner import RNACLearner
from adarl.train.sac_learner import SACLearner

LEARNERS: dict[type, Callable[..., Learner]] = {
    SACConfig: SACLearner,
    RNACConfig: RNACLearner,
}
# `--backend device` (SACConfig.backend): every seed vmapped on the MJX task
DEVICE_LEARNERS: dict[type, Callable[..., Learner]] = {SACConfig: DeviceSACLearner}


def make_learner(config) -> Learner:
    """The learner of `config`: its config class's, on the backend it names."""
    if getattr(config, "backend", "host") == "device":
        return DEVICE_LEARNERS[type(config)](config)
    return LEARNERS[type(config)](config)


def train(
    config, run_dir: str | Path, resume: bool = False, progress: bool = True, command: str = ""
) -> Path:
    """Train (or resume) a run of `config` into `run_dir` with its learner (`loop.train`)."""
    return loop.train(make_learner, config, run_dir, resume, progress, command)


def trainer(algo: str) -> Callable:
    """`train(config, run_dir, resume, progress, command)` with the learner of the registry's
    algorithm `algo`."""
    registry.get(algo)  # an unknown name: a one-line error
    return functools.partial(loop.train, make_learner)
