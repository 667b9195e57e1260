"""The suite's per-test timeout (pyproject.toml, pytest-timeout) really stops an in-process test
that hangs: one that took SIGTERM as a stop request (adarl's StopSignals, so `timeout` does not
end it) and then waits in C, in the SVD of a matrix holding inf, which does not return on this
jaxlib (issue 55). Run in a child pytest with the project's settings and a 10 s timeout."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

HANGING_TEST = """
import os
import signal

from adarl.train.loop import StopSignals


def test_hangs_in_c_after_taking_sigterm():
    with StopSignals() as stop:
        os.kill(os.getpid(), signal.SIGTERM)  # what `timeout` sends: a request, not an end
        assert stop.received == signal.SIGTERM
        import jax.numpy as jnp

        matrix = jnp.ones((4, 3)).at[0, 0].set(jnp.inf)
        jnp.linalg.svd(matrix).S.block_until_ready()  # never returns
"""


def test_the_suite_has_a_timeout_that_stops_a_hung_in_process_test(tmp_path):
    settings = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]
    options = settings["ini_options"]
    assert 600 < int(options["timeout"]) <= 1800  # above the slowest test's own 600 s wait
    (tmp_path / "test_hang.py").write_text(HANGING_TEST)
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "test_hang.py", "-c", str(ROOT / "pyproject.toml")]
        + ["--rootdir", str(tmp_path), "-p", "no:cacheprovider", "-o", "timeout=10"]
        + ["-o", "addopts="],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=240,  # a timeout that does not stop it fails here instead of hanging
    )
    assert done.returncode != 0
    assert "Timeout" in done.stdout + done.stderr, (done.stdout + done.stderr)[-3000:]
