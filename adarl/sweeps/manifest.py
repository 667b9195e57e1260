"""The sweep's manifest: `SWEEP_DIR/manifest.json`, the state of every unit.

Only the sweep process writes it, and always whole, to a temp file that is then renamed into
place (`adarl.files.atomic_write_json`), so a kill at any moment leaves the previous or the
next version, never a torn file. It records, per unit: what it trains (the `adarl train` flags),
its status (queued, running, done, failed), the attempts made so far (over every invocation),
the last exit status and error, where it ran, and its last known step.

The run folders stay the truth about results: a unit whose folder has `DONE` is done, whatever
the manifest says, and one that is not is queued again when the sweep is re-run.
"""

from __future__ import annotations

import time
from pathlib import Path

from adarl.errors import UsageError
from adarl.files import UnreadableFile, atomic_write_json, read_json
from adarl.sweeps.spec import Sweep

FILE = "manifest.json"
FORMAT_VERSION = 1
STATUSES = ("queued", "running", "done", "failed")


def read(out: Path) -> dict | None:
    """The manifest in `out`, or None if there is none."""
    path = Path(out) / FILE
    if not path.exists():
        return None
    try:
        data = read_json(path)
    except UnreadableFile as exc:
        raise UsageError(f"{exc}; move it away to start the sweep's bookkeeping afresh") from None
    if not isinstance(data, dict) or data.get("format_version") != FORMAT_VERSION:
        raise UsageError(f"{path} is not a sweep manifest of format {FORMAT_VERSION}")
    units = data.get("units", {})
    if not isinstance(units, dict):
        raise UsageError(
            f"{path} field 'units' is a {type(units).__name__}; allowed: an object of unit "
            "records; move the file away to start the sweep's bookkeeping afresh"
        )
    for uid, record in units.items():
        if not isinstance(record, dict) or record.get("status") not in STATUSES:
            raise UsageError(
                f"{path} unit {uid!r} is not a unit record (a status of {', '.join(STATUSES)}); "
                "move the file away to start the sweep's bookkeeping afresh"
            )
    return data


def check_compatible(data: dict | None, sweep: Sweep, out: Path) -> None:
    """A one-line UsageError if `out` holds a sweep whose units train something else under the
    same folders (re-running must never mix two configurations in one run folder)."""
    if data is None:
        return
    old = data.get("units", {})
    for unit in sweep.units:
        if unit.id in old and list(old[unit.id].get("train_args", [])) != list(unit.train_args):
            raise UsageError(
                f"{out} holds a different sweep: unit {unit.id} was started with other "
                f"settings; choose another --out"
            )


class Manifest:
    def __init__(self, path: Path, data: dict):
        self.path = path
        self.data = data
        self.dirty = True

    @classmethod
    def open(cls, out: Path, sweep: Sweep, command: str) -> Manifest:
        """The manifest of `out` with this sweep's units added (existing records kept)."""
        data = read(out)
        check_compatible(data, sweep, out)
        now = _now()
        data = data or {"format_version": FORMAT_VERSION, "created": now, "units": {}}
        data.update(name=sweep.name, source=sweep.source, command=command, updated=now)
        for unit in sweep.units:
            record = data["units"].setdefault(unit.id, {"status": "queued", "attempts": 0})
            record.update(
                task=unit.task,
                algo=unit.algo,
                label=unit.label,
                seeds=list(unit.seeds),
                total_steps=unit.total_steps,
                train_args=list(unit.train_args),
                run_dir=unit.id,
                log=f"logs/{unit.flat_id}.log",
            )
        return cls(Path(out) / FILE, data)

    def unit(self, uid: str) -> dict:
        return self.data["units"][uid]

    def update(self, uid: str, **fields) -> None:
        if "status" in fields and fields["status"] not in STATUSES:
            raise ValueError(f"unknown unit status {fields['status']!r}")
        self.data["units"][uid].update(fields)
        self.dirty = True

    def save(self) -> None:
        if self.dirty:
            self.data["updated"] = _now()
            atomic_write_json(self.path, self.data)
            self.dirty = False


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")
