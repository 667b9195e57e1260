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

    from adarl import files

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    monkeypatch.setattr(files, "temp_file", read_only)
    with pytest.raises(UsageError, match=r"is not writable \(Read-only file system\)"):
        check_writable_dir(tmp_path / "run")


@pytest.mark.parametrize(
    "umask, file_mode, dir_mode", [(0o077, 0o600, 0o700), (0o022, 0o644, 0o755)]
)
def test_every_file_and_folder_follows_the_umask(umask, file_mode, dir_mode, tmp_path, capsys):
    from adarl.cli.main import main
    from adarl.evaluation.synthetic import write_run

    old = os.umask(umask)
    try:  # a run folder (config, CSVs, checkpoints built in a temp folder), an export, a report
        run = write_run(tmp_path / "runs", "r", seeds=(0,))
        assert main(["export", str(run), "--out", str(tmp_path / "out" / "p.npz")]) == 0
        assert main(["report", str(tmp_path / "runs"), "--out", str(tmp_path / "report"),
                     "--bootstrap-reps", "10"]) == 0  # fmt: skip
    finally:
        os.umask(old)
    capsys.readouterr()
    made = list(tmp_path.rglob("*"))
    assert {"arrays.npz", "policy_seed_0.npz", "config.yaml", "p.npz", "index.md"} <= {
        p.name for p in made
    }
    for path in made:
        expected = dir_mode if path.is_dir() else file_mode
        assert path.stat().st_mode & 0o777 == expected, path
