"""Shared test settings: the CLI's XLA flags (`adarl.runtime`: one thread per computation, one
CPU device per core), a persistent compilation cache shared by the tests and the CLI
subprocesses they start (switched off, see below), and a headless matplotlib backend."""

import os
import tempfile

from adarl.runtime import configure_xla

configure_xla()
os.environ.setdefault(
    "JAX_COMPILATION_CACHE_DIR", os.path.join(tempfile.gettempdir(), "adarl-test-jax-cache")
)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
# Off for now: reading a cached executable back segfaulted inside JAX (compilation_cache
# get_executable_and_time, from sac_loop.maybe_truncate) in
# test_a_seed_gives_the_same_bits_alone_and_among_other_seeds after other tests of tests/train had
# filled the cache (2026-12-02; one lane per seed on two CPU devices). Not yet understood.
os.environ.setdefault("JAX_ENABLE_COMPILATION_CACHE", "false")
os.environ.setdefault("MPLBACKEND", "Agg")
