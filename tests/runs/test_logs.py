"""The run's logs: CSV write errors, and the TensorBoard writer's import."""

import errno
import os
import subprocess
import sys

import pytest

from adarl.errors import RunFailed
from adarl.runs.logs import CsvLog

PROBE = """
import importlib.util, sys, tempfile
from adarl.runs.logs import Scalars
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


def test_csv_write_error_is_one_line_naming_the_file(tmp_path, monkeypatch):
    log = CsvLog(tmp_path / "train.csv", ["step", "x"])

    def full():
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(log._file, "flush", full)
    with pytest.raises(RunFailed, match=r"train\.csv: No space left on device"):
        log.write({"step": 1, "x": 2.0})
    log.close()  # after a failed write, closing does not raise again
