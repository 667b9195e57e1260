"""Checkpoints (docs/reliability.md): checksums, the fallback to an older intact one, disk-full
errors, permissions."""

import errno
import hashlib
import json
import os
import stat

import numpy as np
import pytest

from adarl.errors import RunFailed, UsageError
from adarl.runs import checkpoints, npz
from adarl.runs.layout import checkpoint_step


def _save(run_dir, step, keep=3, value=0.0):
    arrays = {"w": np.full((3, 4), value, np.float32), "n": np.arange(5)}
    return checkpoints.save_checkpoint(run_dir, step, arrays, {"note": step}, keep=keep)


def _truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _flip_byte(path):
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def _garbage(path):
    path.write_bytes(b"not a zip file")


@pytest.mark.parametrize("damage", [_truncate, _flip_byte, _garbage])
def test_a_damaged_newest_checkpoint_falls_back_to_the_older_one(tmp_path, damage):
    _save(tmp_path, 100, value=1.0)
    newest = _save(tmp_path, 200, value=2.0)
    damage(newest / "arrays.npz")
    with pytest.raises(checkpoints.CheckpointDamaged):
        checkpoints.load_checkpoint(newest)
    lines = []
    path, arrays, meta = checkpoints.load_latest_intact(tmp_path, warn=lines.append)
    assert path.name == "step_000000000100" and meta["step"] == 100
    np.testing.assert_array_equal(arrays["w"], np.full((3, 4), 1.0, np.float32))
    assert len(lines) == 1 and "step_000000000200" in lines[0] and "\n" not in lines[0]
    # the damaged one is kept for inspection under another name, and never tried again
    assert [p.name for p in checkpoints.checkpoint_dirs(tmp_path)] == ["step_000000000100"]
    assert (tmp_path / "checkpoints" / "damaged_step_000000000200" / "arrays.npz").exists()


def test_no_intact_checkpoint_is_a_clear_usage_error(tmp_path):
    for step in (100, 200):
        _garbage(_save(tmp_path, step) / "arrays.npz")
    with pytest.raises(UsageError, match="no intact checkpoint") as err:
        checkpoints.load_latest_intact(tmp_path, warn=lambda line: None)
    assert "\n" not in str(err.value)
    assert len(checkpoints.checkpoint_dirs(tmp_path)) == 2  # nothing renamed: the error repeats
    assert checkpoints.load_latest_intact(tmp_path / "empty") is None  # no checkpoint at all: start


def test_a_failed_check_of_the_intact_checkpoint_renames_nothing(tmp_path):
    _save(tmp_path, 100)
    _garbage(_save(tmp_path, 200) / "arrays.npz")

    def config_error(path, arrays, meta):
        raise UsageError("config.yaml field 'seeds' is edited")

    with pytest.raises(UsageError, match="field 'seeds'"):
        checkpoints.load_latest_intact(tmp_path, warn=lambda line: None, check=config_error)
    assert len(checkpoints.checkpoint_dirs(tmp_path)) == 2  # validate first, rename after


def test_every_file_of_a_checkpoint_is_checksummed(tmp_path):
    policy = b"policy bytes"
    path = checkpoints.save_checkpoint(
        tmp_path, 100, {"w": np.zeros(2)}, {}, files={"policy_seed_0.npz": policy}
    )
    meta = json.loads((path / "meta.json").read_text())
    assert meta["files_sha256"] == {"policy_seed_0.npz": hashlib.sha256(policy).hexdigest()}
    (path / "policy_seed_0.npz").write_bytes(b"policy bytez")
    with pytest.raises(checkpoints.CheckpointDamaged, match="policy_seed_0.npz does not match"):
        checkpoints.load_checkpoint(path)
    with pytest.raises(checkpoints.CheckpointDamaged, match="policy_seed_0.npz does not match"):
        checkpoints.policy_files(path)
    (path / "policy_seed_0.npz").unlink()
    with pytest.raises(checkpoints.CheckpointDamaged, match="policy_seed_0.npz, listed in"):
        checkpoints.load_checkpoint(path)


def test_checksum_is_stored_and_old_checkpoints_without_one_still_load(tmp_path):
    path = _save(tmp_path, 100)
    meta = json.loads((path / "meta.json").read_text())
    assert meta["arrays_sha256"] == checkpoints.file_sha256(path / "arrays.npz")
    del meta["arrays_sha256"]  # as written before checksums
    (path / "meta.json").write_text(json.dumps(meta))
    arrays, _ = checkpoints.load_checkpoint(path)
    assert arrays["w"].shape == (3, 4)


def test_checkpoint_folders_are_readable_like_the_rest_of_the_run(tmp_path):
    old = os.umask(0o022)
    try:
        path = _save(tmp_path, 100)
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o755  # as any folder, not mkdtemp's 0700


def test_disk_full_during_a_checkpoint_is_one_line_and_keeps_the_previous(tmp_path, monkeypatch):
    previous = _save(tmp_path, 100, value=1.0)

    def full(file, arrays):  # the disk fills part way through arrays.npz
        file.write(b"PK\x03\x04")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(npz, "write", full)
    with pytest.raises(RunFailed) as err:
        _save(tmp_path, 200)
    message = str(err.value)
    assert "step_000000000200" in message and "No space left on device" in message
    assert err.value.exit_code == 1 and "\n" not in message
    monkeypatch.undo()
    assert checkpoints.checkpoint_dirs(tmp_path) == [previous]
    assert not list((tmp_path / "checkpoints").glob(".tmp_*"))
    arrays, _ = checkpoints.load_checkpoint(previous)
    np.testing.assert_array_equal(arrays["w"], np.full((3, 4), 1.0, np.float32))


def test_selecting_a_checkpoint_and_its_policy_files(tmp_path):
    from synthetic_runs import write_run

    run = write_run(tmp_path, "a", seeds=(3, 5), total_steps=400)
    ckpt = checkpoints.select_checkpoint(run)
    assert checkpoint_step(ckpt) == 400
    assert list(checkpoints.policy_files(ckpt)) == [3, 5]
    assert checkpoints.policy_file(run, 5).name == "policy_seed_5.npz"
    with pytest.raises(UsageError, match="has no seed 4; it has seeds: 3, 5"):
        checkpoints.policy_file(run, 4)
    with pytest.raises(UsageError, match="no checkpoint at step 7; it has: 400"):
        checkpoints.select_checkpoint(run, 7)
    bare = write_run(tmp_path, "b", checkpoint=False)
    with pytest.raises(UsageError, match="has no complete checkpoint"):
        checkpoints.select_checkpoint(bare)


def test_legacy_meta_keys():
    assert checkpoints.rng_states({"np_rngs": [1]}) == [1]
    assert checkpoints.rng_states({"rng_states": [2], "np_rngs": [1]}) == [2]
    offsets = checkpoints.csv_offsets({"csv_offsets": {"episodes": 3, "train.csv": 4}})
    assert offsets == {"episodes.csv": 3, "train.csv": 4}
