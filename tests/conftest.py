"""Shared test settings: the CLI's XLA flags (`adarl.runtime`: one thread per computation, one
CPU device per core), a persistent compilation cache shared by the tests and the CLI
subprocesses they start, a headless matplotlib backend, and a bound on the memory maps that
compiled XLA executables hold in this long-lived process."""

import gc
import os
import sys
import tempfile

import pytest

from adarl.runtime import configure_xla

configure_xla()
os.environ.setdefault(
    "JAX_COMPILATION_CACHE_DIR", os.path.join(tempfile.gettempdir(), "adarl-test-jax-cache")
)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
os.environ.setdefault("MPLBACKEND", "Agg")

# Every XLA:CPU executable holds its own memory maps, and JAX keeps the executables of every
# function and shape a test compiled. The suite compiles thousands in one process: past the
# kernel's vm.max_map_count (65,530) XLA crashes (SIGSEGV or SIGABRT) in the next compilation.
MAPS_BEFORE_CLEARING = 20_000


def memory_maps() -> int:
    """This process's number of memory maps (0 where /proc is not available)."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return 0


@pytest.fixture(autouse=True)
def bounded_executables():
    yield
    if "jax" in sys.modules and memory_maps() > MAPS_BEFORE_CLEARING:
        sys.modules["jax"].clear_caches()
        gc.collect()
