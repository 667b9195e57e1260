"""The training loop and the learners. The package is also what `adarl.train(...)` calls: the
Python API's `adarl.api.train` (a module cannot be called, so this one's class is swapped for a
callable one; `import adarl.train.loop` and `adarl.train(algo=..., task=...)` both work)."""

import sys
import types


class _CallableModule(types.ModuleType):
    def __call__(self, *args, **kwargs):
        from adarl.api import train

        return train(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
