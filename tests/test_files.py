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
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]  # the probe is gone
    monkeypatch.setattr(os, "access", lambda *a, **k: True)  # what root is told about /proc
    with pytest.raises(UsageError, match="/proc is not writable"):
        check_writable_dir("/proc/new/run")
    with pytest.raises(UsageError, match="/proc is not writable"):
        check_writable_file("/proc/p.npz")


def test_a_read_only_folder_is_found_by_its_probe(tmp_path, monkeypatch):
    import errno
    import tempfile

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    with pytest.raises(UsageError, match=r"is not writable \(Read-only file system\)"):
        check_writable_dir(tmp_path / "run")
