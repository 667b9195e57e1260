"""adarl/runs/npz.py: a checkpoint's arrays.npz is what np.savez writes, byte for byte in every
member, without joining a `Stacked` value in memory; reading it back memory-maps the large
uncompressed members and reads the rest, the values equal either way."""

import tracemalloc
import zipfile

import numpy as np
import pytest

from adarl.runs import npz


def _arrays(rng):
    rows = rng.standard_normal((3, 500, 7)).astype(np.float32)
    return rows, {
        "state/actor/w": rng.standard_normal((3, 4, 5)),
        "buffer/obs": rows,
        "buffer/done": rng.random((3, 500)) < 0.1,
        "buffer/ptr": np.array([5, 6, 7], np.int32),
        "empty": np.zeros((3, 0, 7), np.float32),
        "scalar": np.float64(2.5),
    }


def test_written_members_are_np_savez_bytes_with_stacked_values_joined_in_the_file(tmp_path):
    rows, arrays = _arrays(np.random.default_rng(0))
    np.savez(tmp_path / "ref.npz", **arrays)
    # the buffer given as one part per lane, the middle one not contiguous
    middle = np.asfortranarray(rows[1:2])
    assert not middle.flags.c_contiguous
    ours = {**arrays, "buffer/obs": npz.Stacked([rows[:1], middle, rows[2:]])}
    with open(tmp_path / "ours.npz", "wb") as f:
        npz.write(f, ours)
    with zipfile.ZipFile(tmp_path / "ref.npz") as a, zipfile.ZipFile(tmp_path / "ours.npz") as b:
        assert a.namelist() == b.namelist()
        for name in a.namelist():
            assert a.read(name) == b.read(name), name
    with np.load(tmp_path / "ours.npz") as z:
        np.testing.assert_array_equal(z["buffer/obs"], rows)


def test_stacked_refuses_parts_that_do_not_join():
    with pytest.raises(ValueError, match="differ"):
        npz.Stacked([np.zeros((1, 3)), np.zeros((1, 4))])
    with pytest.raises(ValueError, match="differ"):
        npz.Stacked([np.zeros((1, 3)), np.zeros((1, 3), np.int32)])
    np.testing.assert_array_equal(
        np.asarray(npz.Stacked([np.ones((1, 2)), np.zeros((2, 2))])), [[1, 1], [0, 0], [0, 0]]
    )


def test_large_stored_members_are_memory_mapped_and_the_rest_read(tmp_path):
    rows, arrays = _arrays(np.random.default_rng(1))
    with open(tmp_path / "a.npz", "wb") as f:
        npz.write(f, arrays)
    read = npz.read(tmp_path / "a.npz", mmap_from=rows.nbytes)
    assert list(read) == list(arrays)
    for key, value in arrays.items():
        np.testing.assert_array_equal(read[key], value, err_msg=key)
        assert read[key].dtype == np.asarray(value).dtype, key
    assert isinstance(read["buffer/obs"], np.memmap) and not read["buffer/obs"].flags.writeable
    assert not any(isinstance(v, np.memmap) for k, v in read.items() if k != "buffer/obs")
    everything = npz.read(tmp_path / "a.npz", mmap_from=1)  # the empty one cannot be mapped
    assert isinstance(everything["state/actor/w"], np.memmap)
    assert not isinstance(everything["empty"], np.memmap)


def test_compressed_members_are_read_whatever_their_size(tmp_path):
    rows, arrays = _arrays(np.random.default_rng(2))
    np.savez_compressed(tmp_path / "c.npz", **arrays)
    read = npz.read(tmp_path / "c.npz", mmap_from=1)
    assert not any(isinstance(v, np.memmap) for v in read.values())
    np.testing.assert_array_equal(read["buffer/obs"], rows)


def test_a_stacked_buffer_is_written_and_read_without_a_joined_copy(tmp_path):
    lanes = [np.full((1, 2_000_000, 5), k, np.float32) for k in range(4)]  # 4 x 40 MB
    total = sum(p.nbytes for p in lanes)
    tracemalloc.start()
    try:
        with open(tmp_path / "big.npz", "wb") as f:
            npz.write(f, {"buffer/obs": npz.Stacked(lanes)})
        _, written_peak = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        read = npz.read(tmp_path / "big.npz", mmap_from=1 << 20)
        lane = np.array(read["buffer/obs"][2:3])  # one lane's rows, as a learner takes them
        _, read_peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # np.savez of the joined array would hold all 160 MB at once; each lane is 40 MB
    assert written_peak < total / 8, written_peak
    assert read_peak < total / 3, read_peak
    np.testing.assert_array_equal(lane, lanes[2])
