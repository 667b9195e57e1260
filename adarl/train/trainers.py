"""Which loop trains each algorithm: its config class -> `train(config, run_dir, resume=False,
progress=True, command="")`. Apart from `adarl.algos.registry` because the loops import JAX and
sit a layer above the algorithms; the CLI and the sweep worker import this only when they train.
"""

from __future__ import annotations

from collections.abc import Callable

from adarl.algos import registry
from adarl.algos.rnac_config import RNACConfig
from adarl.algos.sac_config import SACConfig
from adarl.train import rnac_loop, sac_loop

TRAINERS: dict[type, Callable] = {
    SACConfig: sac_loop.train,
    RNACConfig: rnac_loop.train,
}


def trainer(algo: str) -> Callable:
    """The `train` function of the registry's algorithm `algo`."""
    return TRAINERS[registry.get(algo).config_class]
