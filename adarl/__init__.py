"""adarl: AdaRL (Adaptive Rank Representation) soft actor-critic and baselines for robust RL
under model uncertainty on MuJoCo tasks with episode-varying dynamics."""

__version__ = "0.1.0"

import sys as _sys  # noqa: E402


class _RegisterAfterGymnasium:
    """Registers adarl's Gymnasium ids (`gymnasium.make("adarl/Hopper-v0", ...)`; Gymnasium 1.x
    loads no plugins) right after Gymnasium is first imported, so that `import adarl` imports
    neither Gymnasium nor NumPy: `adarl --version` answers at once. A meta-path finder that
    finds `gymnasium` as the other finders do and runs `adarl.envs.registration` (which registers
    the ids as it loads) after the package's own code."""

    def find_spec(self, name, path=None, target=None):
        if name != "gymnasium":
            return None
        for finder in _sys.meta_path:
            find = getattr(finder, "find_spec", None) if finder is not self else None
            spec = find(name, path, target) if find else None
            if spec is not None:
                break
        else:
            return None
        if spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        exec_module = spec.loader.exec_module

        def exec_then_register(module):
            exec_module(module)
            if self in _sys.meta_path:
                _sys.meta_path.remove(self)
            import adarl.envs.registration  # noqa: F401  (mid-import if it imported Gymnasium)

        spec.loader.exec_module = exec_then_register
        return spec


if "gymnasium" in _sys.modules:
    import adarl.envs.registration  # noqa: E402, F401  (registers the ids as it loads)
elif not any(type(f).__name__ == "_RegisterAfterGymnasium" for f in _sys.meta_path):
    _sys.meta_path.insert(0, _RegisterAfterGymnasium())

#: The Python API (adarl.api), imported on first use so that `import adarl` stays light.
_API = {"evaluate", "report", "load_policy", "register_env_fn", "Run"}


def __getattr__(name):
    if name == "train":  # the package adarl.train, which is callable: adarl.api.train
        import importlib

        return importlib.import_module("adarl.train")
    if name in _API:
        import adarl.api

        return getattr(adarl.api, name)
    if name == "UsageError":
        from adarl.errors import UsageError

        return UsageError
    raise AttributeError(f"module 'adarl' has no attribute {name!r}")


def __dir__():
    """The module's names and the lazily imported API's (`dir(adarl)`, completion)."""
    return sorted({*globals(), "train", "UsageError", *_API})
