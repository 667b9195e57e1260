"""Output paths are checked before anything is written."""

import os

import pytest

from adarl.errors import UsageError
from adarl.files import check_writable_dir, check_writable_file


def test_output_folders_are_checked_before_anything_is_written(tmp_path, monkeypatch):
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(UsageError, match="is a file"):
        check_writable_dir(afile)
    with pytest.raises(UsageError, match="is a file, not a folder"):
        check_writable_dir(afile / "run")
    with pytest.raises(UsageError, match="is a file, not a folder"):
        check_writable_file(afile / "x.csv")
    check_writable_dir(tmp_path / "new" / "run")  # creatable
    assert not (tmp_path / "new").exists()
    monkeypatch.setattr(os, "access", lambda *a, **k: False)  # as a read-only file system
    with pytest.raises(UsageError, match="is not writable"):
        check_writable_dir(tmp_path / "new" / "run")
