"""The algorithms' maths: `sac` (the SAC family: SAC, AdaRL, fixed-rank, Parseval, sparse) and
`rnac`, each a config, networks, losses and a jitted update. `registry` names them (config
class, defaults, presets, trainer); the training loops live in `adarl/train`."""

from __future__ import annotations

_FROM_REGISTRY = ("ALGOS", "SAC_FAMILY", "TASK_DEFAULTS")


def __getattr__(name: str):
    # the registry imports the maths (JAX); importing `adarl.algos` alone stays light
    if name in _FROM_REGISTRY:
        from adarl.algos import registry

        return getattr(registry, name)
    raise AttributeError(f"module 'adarl.algos' has no attribute {name!r}")
