"""Which learner the one training loop (`adarl.train.loop`) trains each algorithm with: its
config class -> `train(config, run_dir, resume=False, progress=True, command="")`. Apart from
`adarl.algos.registry` because the learners import JAX and sit a layer above the algorithms; the
CLI and the sweep worker import this only when they train.
"""

from __future__ import annotations

from collections.abc import Callable

from adarl.algos import registry
from adarl.algos.rnac_config import RNACConfig
from adarl.algos.sac_config import SACConfig
from adarl.train import rnac_learner, sac_learner

TRAINERS: dict[type, Callable] = {
    SACConfig: sac_learner.train,
    RNACConfig: rnac_learner.train,
}


def trainer(algo: str) -> Callable:
    """The `train` function of the registry's algorithm `algo`."""
    return TRAINERS[registry.get(algo).config_class]
