"""A run's logs: append-only CSVs that a resumed run truncates back to its last checkpoint, their
columns, and TensorBoard scalars (mirrored to W&B with `--track`, adarl.runs.tracking)."""

from __future__ import annotations

import csv
import io
import os
import sys
from pathlib import Path

import numpy as np

from adarl.errors import UsageError
from adarl.files import fs_errors, open_in_place, read_text
from adarl.runs import layout, tracking

# episodes.csv: then one column p_<name> per physical parameter of the task
EPISODE_COLUMNS = ["step", "seed", "episode", "return", "length"]
EVAL_COLUMNS = ["step", "seed", "dynamics", "episode", "return", "length"]


# the columns of run logs and evaluation tables that hold text; every other column holds numbers
TEXT_COLUMNS = frozenset({"dynamics", "layer", "decision"})
#: the largest run log `read_csv` reads (a 3M-step run's episodes.csv is a few MB)
MAX_CSV_BYTES = 1 << 30


def episode_columns(param_names) -> list[str]:
    return [*EPISODE_COLUMNS, *map(layout.param_column, param_names)]


def eval_rows(step: int, seed: int, dynamics: str, episodes: list[dict]) -> list[dict]:
    """eval.csv rows (`EVAL_COLUMNS`) of one seed's evaluation episodes (`run_episodes` output)."""
    return [
        {
            "step": step,
            "seed": seed,
            "dynamics": dynamics,
            "episode": r["episode"],
            "return": r["return"],
            "length": r["length"],
        }
        for r in episodes
    ]


# ----------------------------------------------------------------------------- CSV logs
class CsvLog:
    """Append-only CSV with a fixed header.

    Rows are flushed after each `write`; `offset()` is the file size, which a checkpoint records
    so that a resumed run can `truncate` away rows written after that checkpoint (and any half
    line a kill left behind).
    """

    def __init__(self, path: str | os.PathLike, columns: list[str]):
        self.path = Path(path)
        self.columns = list(columns)
        new = not self.path.exists() or self.path.stat().st_size == 0
        if not new:  # appending (a resumed run): keep the file's own column order
            with fs_errors(self.path, "read"), open(self.path, "rb") as f:
                head = f.readline(1 << 16)
            try:
                existing = next(csv.reader([head.decode("utf-8")]), [])
            except UnicodeDecodeError:
                raise UsageError(
                    f"{self.path} has a header that is not UTF-8 text; expected {self.columns}"
                ) from None
            if sorted(existing) != sorted(self.columns):
                raise UsageError(f"{self.path} has columns {existing}, expected {self.columns}")
            self.columns = existing
        with fs_errors(self.path):
            self._file = open_in_place(self.path, "a")
            self._writer = csv.DictWriter(self._file, fieldnames=self.columns, extrasaction="raise")
            if new:
                self._writer.writeheader()
                self._file.flush()

    def write(self, rows: dict | list[dict]) -> None:
        if isinstance(rows, dict):
            rows = [rows]
        with fs_errors(self.path):
            for row in rows:
                self._writer.writerow({k: _fmt(v) for k, v in row.items()})
            self._file.flush()

    def offset(self) -> int:
        with fs_errors(self.path):
            self._file.flush()
            return self._file.tell()

    def close(self) -> None:
        try:
            self._file.close()
        except OSError:  # a failed write already raised; rows not flushed then are lost anyway
            pass

    @staticmethod
    def truncate(path: str | os.PathLike, offset: int, warn=None) -> None:
        """Cut `path` back to `offset` bytes (the size recorded in a checkpoint).

        A log shorter than `offset` lost its tail after the checkpoint was written (a disk or a
        hand that cut it): its rows are gone and cannot be made again, so the resume says so in
        one line (`warn`, default stderr) and keeps the rows that are there, cut back to the
        last complete line (new rows must not continue a half one). A missing log is made anew
        by `CsvLog` (with its header)."""
        path = Path(path)
        size = path.stat().st_size if path.exists() else None
        if size is not None and size > offset:
            with fs_errors(path), open_in_place(path, "r+b") as f:
                f.truncate(offset)
        elif offset > 0 and (size is None or size < offset):
            warn = warn or (lambda line: print(line, file=sys.stderr, flush=True))
            kept = 0
            if size:
                with fs_errors(path), open_in_place(path, "r+b") as f:
                    kept = f.read().rfind(b"\n") + 1
                    f.truncate(kept)
            what = "is missing" if size is None else f"holds {size} bytes"
            warn(
                f"adarl: warning: {path} {what} but the checkpoint recorded {offset}: its last "
                f"rows were lost; resuming keeps the {kept} bytes there and logs on"
            )


def _fmt(v):
    if isinstance(v, float | np.floating):
        return f"{float(v):.6g}"
    if isinstance(v, np.integer):
        return int(v)
    return v


def read_csv(path: str | os.PathLike) -> list[dict]:
    """Read a run CSV, ignoring a trailing half-written line; one-line UsageError if it is not
    UTF-8 text."""
    text = read_text(path, max_bytes=MAX_CSV_BYTES)
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    return list(csv.DictReader(io.StringIO(text)))


# ----------------------------------------------------------------------------- TensorBoard
def tb_episode_return(seed: int) -> str:
    return f"episode/return/seed{seed}"


def tb_train(name: str, seed: int) -> str:
    """A training metric (a train.csv column)."""
    return f"train/{name}/seed{seed}"


def tb_eval_return(dynamics: str, seed: int) -> str:
    """The mean evaluation return under `dynamics`."""
    return f"eval/{dynamics}/return/seed{seed}"


def _summary_writer():
    """tensorboardX's SummaryWriter, imported without torch. tensorboardX imports torch when it
    is installed (the `bench` extra), only to accept torch tensors, which costs 1.5–2 s per
    process; torch is hidden during that import and importable again afterwards."""
    hide = "torch" not in sys.modules
    if hide:
        sys.modules["torch"] = None  # makes `import torch` raise ImportError
    try:
        from tensorboardX import SummaryWriter
    finally:
        if hide:
            del sys.modules["torch"]
    return SummaryWriter


class Scalars:
    """TensorBoard scalar writer; `purge_step` hides events past a resumed checkpoint."""

    def __init__(self, log_dir: str | os.PathLike, purge_step: int | None = None):
        self._writer = _summary_writer()(str(log_dir), purge_step=purge_step, flush_secs=30)

    def write(self, step: int, scalars: dict[str, float]) -> None:
        finite = {k: float(v) for k, v in scalars.items() if np.isfinite(v)}
        for name, value in finite.items():  # a non-finite one is the divergence watch's to report
            self._writer.add_scalar(name, value, int(step))
        tracking.log(step, finite)  # `adarl train --track`: the same scalars to W&B

    def close(self) -> None:
        try:
            self._writer.close()
        except OSError:  # TensorBoard events are a convenience; the CSVs are the record
            pass
