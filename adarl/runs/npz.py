"""A checkpoint's arrays.npz without a second copy of its replay buffers in memory.

The file is what `np.savez` writes (a zip of uncompressed `.npy` members; `np.load` reads it),
but a large array is never joined or read whole: `write` takes a `Stacked` value (one part per
lane, joined along axis 0 only in the file) and `read` memory-maps large uncompressed members,
so that a learner copies its buffers in seed by seed. Without this a checkpoint of replay
buffers of B bytes needs 2·B of memory while it is written or read (B of live buffers and B of
joined or loaded rows): 2 × 7.3 GB for five Humanoid seeds with 10⁶-row buffers, more than this
project's 24 GiB machines have with two such runs at once, hours into the runs
(bench/checkpoint_memory.py, docs/benchmarks.md).
"""

from __future__ import annotations

import struct
import zipfile
from pathlib import Path

import numpy as np

#: Members of at least this many bytes are memory-mapped by `read` (the replay buffers; a
#: network's arrays are far smaller).
MMAP_FROM = 64 << 20
_CHUNK = 16 << 20  # bytes written at a time (np.lib.format.write_array's buffer)
_LOCAL_HEADER = struct.Struct("<4s22xHH")  # signature, ..., file name length, extra length


class Stacked:
    """An array given as `parts` to be joined along axis 0 (a replay buffer: one part per
    lane), which `write` writes one part after another."""

    def __init__(self, parts) -> None:
        self.parts = list(parts)
        first = self.parts[0]
        if any(p.shape[1:] != first.shape[1:] or p.dtype != first.dtype for p in self.parts):
            raise ValueError("Stacked parts differ in dtype or in shape beyond axis 0")
        self.shape = (sum(p.shape[0] for p in self.parts), *first.shape[1:])
        self.dtype = first.dtype

    def __array__(self, dtype=None, copy=None) -> np.ndarray:  # joined, where a caller needs it
        joined = np.concatenate(self.parts)
        return joined if dtype is None else joined.astype(dtype)


def write(file, arrays: dict) -> None:
    """`np.savez(file, **arrays)`, with each `Stacked` value written part by part."""
    with zipfile.ZipFile(file, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
        for key, value in arrays.items():
            with zf.open(key + ".npy", "w", force_zip64=True) as out:
                if not isinstance(value, Stacked):
                    np.lib.format.write_array(out, np.asanyarray(value), allow_pickle=False)
                    continue
                header = {
                    "descr": np.lib.format.dtype_to_descr(value.dtype),
                    "fortran_order": False,
                    "shape": value.shape,
                }
                try:
                    np.lib.format.write_array_header_1_0(out, header)
                except ValueError:  # a header too long for format 1.0
                    np.lib.format.write_array_header_2_0(out, header)
                for part in value.parts:
                    data = memoryview(np.ascontiguousarray(part)).cast("B")
                    for start in range(0, data.nbytes, _CHUNK):
                        out.write(data[start : start + _CHUNK])


def read(path: str | Path, mmap_from: int | None = None) -> dict[str, np.ndarray]:
    """Every array of an .npz file by key; members of at least `mmap_from` bytes (default
    `MMAP_FROM`) stored uncompressed are read-only memory maps of the file, the rest arrays
    in memory (a compressed or unusual member too, whatever its size)."""
    mmap_from = MMAP_FROM if mmap_from is None else mmap_from
    arrays = {}
    with zipfile.ZipFile(path) as zf, open(path, "rb") as raw, np.load(path) as z:
        for info in zf.infolist():
            key = info.filename.removesuffix(".npy")
            mapped = None
            if info.compress_type == zipfile.ZIP_STORED and info.file_size >= mmap_from:
                mapped = _memmap(path, raw, info)
            arrays[key] = z[key] if mapped is None else mapped
    return arrays


def _memmap(path, raw, info: zipfile.ZipInfo) -> np.memmap | None:
    """The member `info` of the zip open as `raw`, memory-mapped; None where its .npy header
    is not one `np.lib.format` reads in format 1.0 or 2.0, or holds objects."""
    raw.seek(info.header_offset)
    signature, name_length, extra_length = _LOCAL_HEADER.unpack(raw.read(_LOCAL_HEADER.size))
    if signature != b"PK\x03\x04":
        return None
    raw.seek(info.header_offset + _LOCAL_HEADER.size + name_length + extra_length)
    version = np.lib.format.read_magic(raw)
    if version == (1, 0):
        shape, fortran_order, dtype = np.lib.format.read_array_header_1_0(raw)
    elif version == (2, 0):
        shape, fortran_order, dtype = np.lib.format.read_array_header_2_0(raw)
    else:
        return None
    if dtype.hasobject or 0 in shape:  # (an empty file region cannot be mapped)
        return None
    order = "F" if fortran_order else "C"
    return np.memmap(path, dtype=dtype, mode="r", offset=raw.tell(), shape=shape, order=order)
