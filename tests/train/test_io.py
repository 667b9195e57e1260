"""Run-folder I/O helpers that the trainer tests do not reach directly."""

import subprocess
import sys

PROBE = """
import importlib.util, sys, tempfile
from adarl.train.io import Scalars
writer = Scalars(tempfile.mkdtemp())
writer.write(1, {"x": 1.0})
writer.close()
assert "torch" not in sys.modules, "tensorboardX pulled torch in"
if importlib.util.find_spec("torch") is not None:
    import torch  # hidden only while tensorboardX was imported
print("ok")
"""


def test_tensorboard_writer_does_not_import_torch_but_leaves_it_importable():
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
