"""`adarl tasks` and `adarl sweep --dry-run` (a sweep with forks, whose steps are the schedule's
truncation steps) do their integer maths with `adarl.algos.schedule` and never import JAX."""

import subprocess
import sys

SCRIPT = """
import sys
from adarl.cli.main import main
assert main({argv!r}) == 0
assert "jax" not in sys.modules, sorted(m for m in sys.modules if m.startswith("adarl."))
"""


def _run(argv: list[str], cwd) -> None:
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT.format(argv=argv)],
        capture_output=True,
        text=True,
        cwd=cwd,
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]


def test_tasks_does_not_import_jax(tmp_path):
    _run(["tasks", "hopper"], tmp_path)


def test_a_sweep_dry_run_with_forks_does_not_import_jax(tmp_path):
    _run(["sweep", "mechanism-hopper", "--dry-run", "--out", str(tmp_path / "sweep")], tmp_path)


def test_the_schedule_module_does_not_import_jax():
    code = "import sys, adarl.algos.schedule; assert 'jax' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)
