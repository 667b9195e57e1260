"""The run folder as a whole (docs/run-format.md): its config.yaml, written once and read back
with the format-version check, starting a new run (refusing a non-empty folder), opening one to
resume (newest intact checkpoint, checked against the config) and finishing it (DONE).

Every command that reads runs (`train --resume`, `ranks`, `evaluate`, `report`, `play`,
`export`, the sweeps) reads config.yaml through `load_config`.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import shlex
import sys
from pathlib import Path

import yaml

from adarl import __version__
from adarl.errors import UsageError
from adarl.files import (
    UnreadableFile,
    atomic_write_text,
    check_writable_dir,
    probe_writable,
    read_text,
    read_yaml,
    refuse_links,
)
from adarl.runs.checkpoints import config_record, load_latest_intact
from adarl.runs.layout import (
    CHECKPOINT_DIR,
    CONFIG_FILE,
    DONE_FILE,
    EPISODES_CSV,
    EVAL_CSV,
    LOCK_FILE,
    RUN_FORMAT_VERSION,
    TRAIN_CSV,
)
from adarl.runs.lock import RunLock, lock_holder, refuse_non_empty
from adarl.runs.provenance import check_resume_numerics, write_environment

#: config fields a run may change between its checkpoint and a resume (the others are the run)
RESUMABLE_EDITS = (
    "checkpoint_before_truncation",
    "total_steps",
    "on_divergence",
    "keep_checkpoints",
    "checkpoint_every",
    "log_every",
    "eval_every",
    "eval_episodes",
    "eval_dynamics",
    "eager_candidates",  # RNAC: the same transitions, computed another way
)


# ---------------------------------------------------------------------------- config.yaml
def config_values(config) -> dict:
    """`config`'s fields as config.yaml holds them (tuples as lists)."""
    return {
        k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(config).items()
    }


def config_yaml(config, extra: dict | None = None) -> str:
    """`config`'s fields then `extra`, as YAML."""
    return yaml.safe_dump({**config_values(config), **(extra or {})}, sort_keys=False)


def write_config(run_dir: Path, config, algo: str, command: str, fork: dict | None = None) -> None:
    """config.yaml of a new run: `algo`, every config field, the format and adarl versions, the
    command that started it and, for a fork, where it came from (`fork`, docs/run-format.md)."""
    values = {} if hasattr(config, "algo") else {"algo": algo}
    values.update(config_values(config))
    values.update(format_version=RUN_FORMAT_VERSION, adarl_version=__version__)
    values["command"] = command or " ".join(sys.argv)
    if fork is not None:
        values["fork"] = fork
    write_config_values(run_dir, values)


def write_config_values(run_dir: str | os.PathLike, values: dict) -> None:
    """config.yaml holding `values` in their order (`write_config` builds them for a trainer's
    config; the synthetic runs of tests/synthetic_runs.py give their own)."""
    atomic_write_text(Path(run_dir) / CONFIG_FILE, yaml.safe_dump(values, sort_keys=False))


def load_config(run_dir: str | os.PathLike) -> dict:
    """Read and check a run folder's config.yaml (one-line errors for anything wrong)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UsageError(f"run folder {run_dir} does not exist")
    path = run_dir / CONFIG_FILE
    if not path.exists():
        raise UsageError(f"{run_dir} is not a run folder (no config.yaml)")
    values = read_yaml(path)
    if not isinstance(values, dict):
        raise UsageError(f"{path} is not a run config")
    version = values.get("format_version")
    if isinstance(version, int) and version > RUN_FORMAT_VERSION:
        raise UsageError(
            f"run folder {run_dir} was written in run format {version} by a newer adarl; this "
            f"adarl ({__version__}) reads format {RUN_FORMAT_VERSION}: upgrade adarl to read it"
        )
    if version != RUN_FORMAT_VERSION:
        raise UsageError(
            f"{run_dir} was written with run format {version!r}; this adarl "
            f"({__version__}) reads format {RUN_FORMAT_VERSION}"
        )
    return values


def config_from_run(run_dir: str | os.PathLike):
    """(algo, config) a run folder was started with, checked against the algorithm registry
    (`registry.config_from_record`: its env-module must be one the user named)."""
    from adarl.algos import registry

    values = load_config(run_dir)
    return registry.config_from_record(values, str(Path(run_dir) / CONFIG_FILE))


def check_resume_config(run_dir: str | os.PathLike, meta: dict, config) -> None:
    """A one-line UsageError naming the first field of config.yaml that differs from the config
    the checkpoint was written with (fields in `RESUMABLE_EDITS` may differ). Checkpoints
    written before the config was recorded are checked on their seeds only."""
    now = config_record(config)
    then = meta.get("config")
    if then is None:
        then = {"seeds": meta["seeds"]} if "seeds" in meta else {}
    check_complete_config(run_dir, then)
    for name, value in then.items():
        if name in RESUMABLE_EDITS or name not in now or now[name] == value:
            continue
        raise UsageError(
            f"{Path(run_dir) / CONFIG_FILE} field {name!r} is {now[name]!r} but the run's "
            f"checkpoint was written with {value!r}; put it back to resume, or start a new run"
        )


def check_complete_config(run_dir: str | os.PathLike, recorded: dict | None = None) -> None:
    """A one-line UsageError naming the first config field that the run's checkpoint recorded
    (`recorded`, its meta.json `config`; None: a run without a checkpoint, written by this adarl,
    so every field of its algorithm) but that its config.yaml lacks: a resume fills in no
    default (a deleted `total_steps:` line would train to the default budget). Fields a run
    written before they existed lacks are not in its checkpoint's record, and keep their
    defaults. A retired field's value that adarl no longer trains is refused here too
    (`registry.check_resumable`): every resume and fork comes through here. A field of
    `registry.ADDED_FIELDS` that config.yaml lacks keeps the value older runs meant, also when
    a checkpoint written since (by a resume on newer code) records that value."""
    from adarl.algos import registry

    values = load_config(run_dir)
    path = Path(run_dir) / CONFIG_FILE
    registry.check_resumable(values, str(path))
    names = registry.field_names(registry.record_algo(values, str(path))) - {"algo"}
    known = recorded is not None
    for name, value in (recorded if known else dict.fromkeys(sorted(names))).items():
        if name in registry.ADDED_FIELDS and (not known or value == registry.ADDED_FIELDS[name]):
            continue  # older run folders lack it and mean its value then
        if name not in values and name in names:
            line = f"`{name}: {json.dumps(value)}`" if known else f"its {name}: line"
            raise UsageError(
                f"{path} has no field {name!r} (the run was written with it; a resume fills in "
                f"no default): put back {line} and run adarl train --resume {run_dir}"
            )


# ---------------------------------------------------------------------------- starting a run
def check_new_run_dir(run_dir: str | os.PathLike) -> None:
    """A new run's folder: writable and absent or empty (a lock file aside: a run killed before
    writing anything leaves one), else a one-line UsageError."""
    run_dir = Path(run_dir)
    refuse_links(run_dir)  # a lock-only folder is taken: its .lock, too, is written in place
    check_writable_dir(run_dir)
    holder = lock_holder(run_dir)
    if holder:
        raise UsageError(
            f"run folder {run_dir} is being written by another adarl process (pid {holder}); "
            "choose another --out"
        )
    if run_dir.is_dir() and any(p.name != LOCK_FILE for p in run_dir.iterdir()):
        if not (run_dir / CONFIG_FILE).exists():  # --resume cannot take it either
            raise UsageError(
                f"run folder {run_dir} already exists and is not empty but holds no run (no "
                f"{CONFIG_FILE}): "
                f"choose another --out, or remove it (rm -r {run_dir}) and run this again"
            )
        if interrupted_fork(run_dir):
            raise UsageError(
                f"run folder {run_dir} holds a fork interrupted while being made (no "
                f"checkpoint; --resume cannot take it): {remake_fork(run_dir)}"
            )
    refuse_non_empty(run_dir)


def check_run_output(path: str | os.PathLike) -> None:
    """If `path` (a file or folder about to be written: an evaluation, a suite's summary, a
    report) lies in a run folder, a one-line UsageError naming any symbolic link in that run
    folder (`refuse_links`), as training checks its own folder: nothing is written through one."""
    path = Path(os.path.abspath(path))
    for folder in (path, *path.parents):
        if (folder / CONFIG_FILE).is_file():
            refuse_links(folder)
            return


def interrupted_fork(run_dir: Path) -> bool:
    """A fork killed while being made: config.yaml with a `fork` record, no checkpoint (its
    first checkpoint is written last)."""
    from adarl.runs.checkpoints import checkpoint_dirs

    try:
        fork = load_config(run_dir).get("fork")
    except UsageError:
        return False
    return bool(fork) and not checkpoint_dirs(run_dir)


def remake_fork(run_dir: Path) -> str:
    """How to make an interrupted fork again: remove it, then its recorded `adarl train --fork`
    command (or the one its `fork` record describes)."""
    values = load_config(run_dir)
    command = str(values.get("command") or "")
    if not (command.startswith("adarl train ") and "--fork" in command):
        fork = values.get("fork") or {}
        words = ["adarl", "train", "--fork", str(fork.get("from")), "--at", str(fork.get("step"))]
        for name, change in (fork.get("changed") or {}).items():
            if name != "algo" and isinstance(change, dict):
                words += [f"--{name.replace('_', '-')}", _flag_text(change.get("to"))]
        command = shlex.join([*words, "--out", str(run_dir)])
    return f"remove it and fork again: rm -r {shlex.quote(str(run_dir))} && {command}"


def _flag_text(value) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, list | tuple):
        return ",".join(map(str, value))
    return str(value)


def check_resume_dir(run_dir: str | os.PathLike) -> None:
    """A run folder to resume: it exists, holds config.yaml and no symbolic link, and can be
    written."""
    run_dir = Path(run_dir)
    if not (run_dir / CONFIG_FILE).exists():
        raise UsageError(f"{run_dir} is not a run folder (no config.yaml)")
    refuse_links(run_dir)
    why = probe_writable(run_dir)
    if why is not None:
        raise UsageError(f"run folder {run_dir} is not writable ({why})")


def start_new(
    run_dir: Path, lock: RunLock, config, algo: str, command: str, extra: dict | None = None
) -> None:
    """Create a new run: refuse a non-empty folder (one-line UsageError, nothing written), take
    the lock, write config.yaml and environment.json (with `extra`, e.g. the task's `model`)."""
    check_new_run_dir(run_dir)
    lock.acquire(new=True)
    write_config(run_dir, config, algo, command)
    write_environment(run_dir, extra)


def lock_to_resume(run_dir: Path, lock: RunLock) -> bool:
    """Take the lock of a run to resume; False (and a line on stderr) if it is complete (DONE).
    A one-line UsageError if this process's numeric settings differ from the run's
    (`provenance.check_resume_numerics`)."""
    check_resume_dir(run_dir)
    lock.acquire(new=False)
    if (run_dir / DONE_FILE).exists():
        print(f"run {run_dir} is already complete", file=sys.stderr)
        return False
    check_resume_numerics(run_dir)  # x64, precision, platform: before anything is read or written
    return True


def newest_to_resume(run_dir: Path, config):
    """The newest intact checkpoint `(path, arrays, meta)` of a locked run, checked against
    `config` before any damaged newer one is renamed, or `(None, None, None)` if it was killed
    before its first one (start again; refused for a fork, whose first checkpoint is written
    last, and if its CSVs show that checkpoints were lost)."""
    loaded = load_latest_intact(
        run_dir, check=lambda path, arrays, meta: check_resume_config(run_dir, meta, config)
    )
    if loaded is None:
        check_complete_config(run_dir)
        if load_config(run_dir).get("fork"):  # a fork's first checkpoint is written last
            raise UsageError(
                f"fork {run_dir} was interrupted while being made (no checkpoint): "
                f"{remake_fork(run_dir)}"
            )
        refuse_lost_checkpoints(run_dir, config)
        return None, None, None
    return loaded


def refuse_lost_checkpoints(run_dir: Path, config) -> None:
    """A run without a checkpoint restarts from step 0 and cuts its CSVs back to their headers,
    which is right only if it was killed before its first checkpoint. CSV rows past the first
    checkpoint's step mean checkpoints were written and are gone (a deleted `checkpoints/`):
    a one-line UsageError instead of discarding those rows."""
    first = min(config.checkpoint_every, config.total_steps)
    for name in (EPISODES_CSV, TRAIN_CSV, EVAL_CSV):
        last = last_logged_step(run_dir / name)
        if last is not None and last > first:
            raise UsageError(
                f"run folder {run_dir} has no checkpoint but {name} has rows up to step {last} "
                f"(past the first checkpoint, step {first}): its {CHECKPOINT_DIR}/ was deleted? "
                "resuming would discard those rows; start a new run with another --out"
            )


def last_logged_step(path: Path) -> int | None:
    """The largest `step` of a CSV log (None: no file or no readable row)."""
    if not path.is_file():
        return None
    steps = []
    with open(path, encoding="utf-8", errors="replace", newline="") as f:
        for row in csv.DictReader(f):
            try:
                steps.append(int(float(row.get("step") or "")))
            except ValueError:
                continue
    return max(steps, default=None)


def finish(run_dir: Path, step: int) -> None:
    atomic_write_text(Path(run_dir) / DONE_FILE, f"{step}\n")


def done_step(run_dir: str | os.PathLike) -> int | None:
    """The final step recorded in DONE (-1 if it holds no step: not a finite number, not UTF-8
    text, too large), or None while the run is unfinished."""
    done = Path(run_dir) / DONE_FILE
    if not os.path.lexists(done):
        return None
    try:
        text = read_text(done, max_bytes=4096).strip()
        return int(float(text.split()[0])) if text else -1
    except (UnreadableFile, ValueError, OverflowError):  # OverflowError: "inf"
        return -1
