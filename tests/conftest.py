"""Shared test settings: the CLI's XLA flags (`adarl.runtime`: one thread per computation, one
CPU device per core), a persistent compilation cache shared by the tests and the CLI
subprocesses they start, and a headless matplotlib backend."""

import os
import tempfile

from adarl.runtime import configure_xla

configure_xla()
os.environ.setdefault(
    "JAX_COMPILATION_CACHE_DIR", os.path.join(tempfile.gettempdir(), "adarl-test-jax-cache")
)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
os.environ.setdefault("MPLBACKEND", "Agg")
