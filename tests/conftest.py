"""Shared test settings: one XLA thread (faster for these small networks on 2 cores) and a
headless matplotlib backend."""

import os

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")
os.environ.setdefault("MPLBACKEND", "Agg")
