"""Checkpoints that survive SIGKILL: `checkpoints/step_<n>/` written atomically with a checksum,
read back with the fallback to an older intact one, the keys the loop writes to meta.json, and
choosing a checkpoint and its policy files for evaluation (docs/run-format.md,
docs/reliability.md).

Runs written before the loops shared this module (run format 1 as the SAC and RNAC loops wrote
it separately) still load: `rng_states` and `csv_offsets` read the old keys.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import sys
from pathlib import Path

import numpy as np

from adarl import __version__
from adarl.errors import UsageError, reason
from adarl.files import fs_errors, fsync_dir, json_default, read_json, temp_dir
from adarl.runs import codec, npz
from adarl.runs.layout import (
    ARRAYS_FILE,
    CHECKPOINT_DIR,
    DAMAGED_PREFIX,
    META_FILE,
    POLICY_PATTERN,
    RUN_FORMAT_VERSION,
    STEP_PREFIX,
    checkpoint_step,
    step_name,
)


class CheckpointDamaged(UsageError):
    """A checkpoint that cannot be read back (bad zip, short file, wrong checksum)."""


def checkpoint_dirs(run_dir: str | os.PathLike, folder: str = CHECKPOINT_DIR) -> list[Path]:
    """Complete checkpoints of a run, oldest first (a complete one has meta.json); `folder`
    PRE_TRUNCATION_DIR: the pre-truncation ones."""
    root = Path(run_dir) / folder
    if not root.is_dir():
        return []
    found = [p for p in root.iterdir() if p.is_dir() and p.name.startswith(STEP_PREFIX)]
    found = [p for p in found if (p / META_FILE).exists() and (p / ARRAYS_FILE).exists()]
    return sorted(found, key=checkpoint_step)


def save_checkpoint(
    run_dir: str | os.PathLike,
    step: int,
    arrays: dict[str, np.ndarray],
    meta: dict,
    keep: int = 2,
    files: dict[str, bytes] | None = None,
    folder: str = CHECKPOINT_DIR,
) -> Path:
    """Write `<folder>/step_<step>/` (default `checkpoints/`) atomically: a temp folder holding
    arrays.npz (`arrays`' values: arrays, or `adarl.runs.npz.Stacked` parts), the extra `files`
    (name -> bytes, e.g. policy files) and meta.json (written last, with the sha256 of
    arrays.npz and of every extra file) is renamed into place, then older checkpoints of that
    folder beyond `keep` go (0: none). An OSError becomes a one-line `RunFailed`; the
    checkpoints already there are left as they were."""
    root = Path(run_dir) / folder
    final = root / step_name(step)
    with fs_errors(final):
        root.mkdir(parents=True, exist_ok=True)
        tmp = temp_dir(root, prefix=f".tmp_{STEP_PREFIX}")
        try:
            with open(tmp / ARRAYS_FILE, "wb") as f:
                npz.write(f, arrays)  # np.savez's format, buffers never joined in memory
                f.flush()
                os.fsync(f.fileno())
            files_ = sorted((files or {}).items())
            for name, data in files_:
                with open(tmp / name, "wb") as f:
                    f.write(data)
                    f.flush()
                    os.fsync(f.fileno())
            meta = dict(
                meta,
                step=int(step),
                format_version=RUN_FORMAT_VERSION,
                adarl_version=__version__,
                arrays_sha256=file_sha256(tmp / ARRAYS_FILE),
                files_sha256={name: hashlib.sha256(data).hexdigest() for name, data in files_},
            )
            with open(tmp / META_FILE, "w", encoding="utf-8") as f:
                json.dump(meta, f, indent=1, sort_keys=True, default=json_default)
                f.flush()
                os.fsync(f.fileno())
            if final.exists():
                shutil.rmtree(final)
            os.replace(tmp, final)
            fsync_dir(root)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    for old in checkpoint_dirs(run_dir, folder)[:-keep] if keep > 0 else []:
        shutil.rmtree(old, ignore_errors=True)
    for stale in root.glob(f".tmp_{STEP_PREFIX}*"):  # left by a killed writer
        shutil.rmtree(stale, ignore_errors=True)
    return final


def file_sha256(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def checksums(meta: dict) -> dict[str, str]:
    """`{file name: sha256}` of every file of a checkpoint that its meta.json covers (none for
    checkpoints written before checksums; arrays.npz only for those written before the policy
    files were covered)."""
    found = dict(meta.get("files_sha256") or {})
    if meta.get("arrays_sha256") is not None:
        found[ARRAYS_FILE] = meta["arrays_sha256"]
    return found


def verify_checksums(path: Path, meta: dict, names=None) -> None:
    """`CheckpointDamaged` naming the first file of checkpoint `path` (of `names`, default all)
    that is missing or does not match its sha256 in meta.json."""
    for name, expected in checksums(meta).items():
        if names is not None and name not in names:
            continue
        if not (path / name).is_file():
            raise CheckpointDamaged(
                f"checkpoint {path} is damaged ({name}, listed in meta.json, is missing)"
            )
        if file_sha256(path / name) != expected:
            raise CheckpointDamaged(
                f"checkpoint {path} is damaged ({name} does not match its sha256 in meta.json)"
            )


def read_meta(path: Path) -> dict:
    """A checkpoint's meta.json; `CheckpointDamaged` (one line) if it cannot be read."""
    try:
        meta = read_json(path / META_FILE)
    except (OSError, ValueError) as exc:  # UnreadableFile is a ValueError
        raise CheckpointDamaged(f"checkpoint {path} is unreadable ({reason(exc)})") from exc
    if not isinstance(meta, dict):
        raise CheckpointDamaged(f"checkpoint {path} is unreadable ({META_FILE} is not an object)")
    return meta


def load_checkpoint(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict]:
    """Read one checkpoint folder. A damaged one (unreadable meta.json or arrays.npz, or a file
    not matching its checksum in meta.json: arrays.npz and the policy files) raises
    `CheckpointDamaged`, another format version a UsageError; both one line. Checkpoints written
    before checksums load without the check. Large arrays (the replay buffers) come back as
    read-only memory maps of arrays.npz (`adarl.runs.npz.read`)."""
    path = Path(path)
    try:
        meta = read_meta(path)
        verify_checksums(path, meta)
        arrays = npz.read(path / ARRAYS_FILE)  # the replay buffers memory-mapped
    except CheckpointDamaged:
        raise
    except Exception as exc:  # BadZipFile, EOFError, OSError, ValueError, …: all mean damaged
        raise CheckpointDamaged(f"checkpoint {path} is unreadable ({reason(exc)})") from exc
    check_csv_offsets(path, meta)
    if meta.get("format_version") != RUN_FORMAT_VERSION:
        raise UsageError(
            f"checkpoint {path} has format version {meta.get('format_version')!r}; "
            f"this adarl ({__version__}) reads version {RUN_FORMAT_VERSION}"
        )
    return arrays, meta


def latest_checkpoint(run_dir: str | os.PathLike) -> Path:
    found = checkpoint_dirs(run_dir)
    if not found:
        raise UsageError(f"run folder {run_dir} has no complete checkpoint")
    return found[-1]


def load_latest_intact(run_dir: str | os.PathLike, warn=None, check=None):
    """The newest checkpoint that loads: `(path, arrays, meta)`, or None if the run has none.

    Each damaged checkpoint is reported in one line (`warn`, default: stderr) and the next older
    one is tried; `check(path, arrays, meta)` (e.g. the config check of a resume) runs on the one
    found, and only if it passes are the damaged ones newer than it renamed `damaged_step_<n>`
    (kept for inspection, never loaded again). With none intact, a one-line UsageError and
    nothing renamed. Call it only while holding the run's lock.
    """
    warn = warn or (lambda line: print(line, file=sys.stderr, flush=True))
    found = checkpoint_dirs(run_dir)
    damaged = []
    for path in reversed(found):
        try:
            arrays, meta = load_checkpoint(path)
        except CheckpointDamaged as exc:
            warn(f"adarl: warning: {exc}; trying the next older checkpoint")
            damaged.append(path)
            continue
        if check is not None:
            check(path, arrays, meta)
        for bad in damaged:
            aside = bad.with_name(DAMAGED_PREFIX + bad.name)
            with fs_errors(aside):
                if aside.exists():
                    shutil.rmtree(aside)
                os.replace(bad, aside)
        return path, arrays, meta
    if found:
        raise UsageError(
            f"run folder {run_dir} has no intact checkpoint (all {len(found)} are damaged); "
            "start a new run"
        )
    return None


# ----------------------------------------------------------------------------- meta.json
def config_record(config) -> dict:
    """A config as checkpoints store it (`meta["config"]`): plain JSON values."""
    return json.loads(json.dumps(dataclasses.asdict(config), default=json_default))


def checkpoint_meta(algo: str, config, seeds, csv_offsets: dict) -> dict:
    """The keys the loop writes to every checkpoint's meta.json (then the learner's own, from its
    `checkpoint_state`, and the loop's `best`)."""
    return {
        "algo": algo,
        "seeds": [int(s) for s in seeds],
        "csv_offsets": csv_offsets,
        "config": config_record(config),
    }


def host_meta(rngs, envs, arrays: dict) -> dict:
    """meta.json's `rng_states` and `env_states` of a learner that steps Gymnasium environments
    on the host with a NumPy generator per seed: each generator's state and each environment's
    (`env.get_state()`; its arrays go into `arrays` as `env/<i>/…`)."""
    return {
        "rng_states": [rng.bit_generator.state for rng in rngs],
        "env_states": codec.encode_env_states(envs, arrays),
    }


def rng_states(meta: dict) -> list[dict]:
    """Each seed's NumPy generator state (`np_rngs` in SAC checkpoints of run format 1)."""
    return meta["rng_states"] if "rng_states" in meta else meta["np_rngs"]


def restore_rngs(meta: dict, seeds) -> list[np.random.Generator]:
    rngs = []
    for s, state in zip(seeds, rng_states(meta)):
        rng = np.random.default_rng(s)
        rng.bit_generator.state = state
        rngs.append(rng)
    return rngs


def check_csv_offsets(path: Path, meta: dict) -> None:
    """`CheckpointDamaged` unless meta.json's `csv_offsets` (if any) maps names to byte offsets:
    integers ≥ 0 (a negative one would cut a log from its end, a bool is no offset)."""
    offsets = meta.get("csv_offsets", {})
    if not isinstance(offsets, dict):
        raise CheckpointDamaged(
            f"checkpoint {path} is damaged (csv_offsets in {META_FILE} is not an object)"
        )
    for name, offset in offsets.items():
        if isinstance(offset, bool) or not isinstance(offset, int) or offset < 0:
            raise CheckpointDamaged(
                f"checkpoint {path} is damaged (csv_offsets[{name!r}] in {META_FILE} is "
                f"{offset!r}; allowed: a byte offset, an integer >= 0)"
            )


def csv_offsets(meta: dict) -> dict[str, int]:
    """Byte offsets of the CSV logs by file name (RNAC checkpoints of run format 1 wrote them
    without `.csv`)."""
    return {(k if k.endswith(".csv") else f"{k}.csv"): v for k, v in meta["csv_offsets"].items()}


# ----------------------------------------------------------------------------- for evaluation
def select_checkpoint(run_dir: str | os.PathLike, step: int | None = None) -> Path:
    """The final complete checkpoint of a run, or the one at `step`; `UsageError` otherwise."""
    found = checkpoint_dirs(run_dir)
    if not found:
        raise UsageError(
            f"run folder {run_dir} has no complete checkpoint (checkpoints/step_*/meta.json)"
        )
    if step is None:
        return found[-1]
    for checkpoint in found:
        if checkpoint_step(checkpoint) == step:
            return checkpoint
    steps = ", ".join(str(checkpoint_step(c)) for c in found)
    raise UsageError(f"run folder {run_dir} has no checkpoint at step {step}; it has: {steps}")


def policy_files(checkpoint: Path) -> dict[int, Path]:
    """`{seed: policy file}` of a checkpoint folder (`policy_seed_<s>.npz`), sorted by seed; a
    one-line `CheckpointDamaged` if one does not match its sha256 in meta.json."""
    found = {}
    for p in checkpoint.iterdir():
        m = POLICY_PATTERN.match(p.name)
        if m:
            found[int(m.group(1))] = p
    if not found:
        raise UsageError(f"checkpoint {checkpoint} holds no policy_seed_<s>.npz file")
    verify_checksums(checkpoint, read_meta(checkpoint), {p.name for p in found.values()})
    return dict(sorted(found.items()))


def policy_file(run_dir: str | os.PathLike, seed: int, step: int | None = None) -> Path:
    """The policy file of one seed at the final (or chosen) checkpoint."""
    files = policy_files(select_checkpoint(run_dir, step))
    if seed not in files:
        allowed = ", ".join(map(str, files))
        raise UsageError(f"run folder {run_dir} has no seed {seed}; it has seeds: {allowed}")
    return files[seed]
