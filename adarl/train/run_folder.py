"""Everything about a run folder (docs/run-format.md), for the training loops and for every
command that reads runs (`ranks`, `evaluate`, `report`, `play`, `export`, the sweeps).

A run folder holds `config.yaml` (the resolved config plus `algo`, `format_version`,
`adarl_version`, `command`), the CSV logs, TensorBoard files in `tb/` and `checkpoints/step_<n>/`
(`arrays.npz`, `meta.json`, policy files). This module creates a new run (refusing a non-empty
folder), opens one to resume (newest intact checkpoint, damaged ones set aside), writes and reads
`config.yaml`, and defines the pieces both loops write alike: the checkpoint's `meta.json` keys,
the environment-state codec, the CSV columns and the TensorBoard tags. The low-level writers
(atomic files, the lock, checksums, CSV and TensorBoard writers) are in `adarl.train.io`.

Runs written before this module (run format 1 as the SAC and RNAC loops wrote it separately)
still load: `rng_states` and `env_state` read the old keys and encodings.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import yaml

from adarl import __version__
from adarl.errors import UsageError
from adarl.train import io
from adarl.train.io import (  # noqa: F401  (the run-folder API, re-exported)
    CHECKPOINT_DIR,
    PRE_TRUNCATION_DIR,
    RUN_FORMAT_VERSION,
    check_resume_config,
    checkpoint_dirs,
    config_record,
    latest_checkpoint,
    load_checkpoint,
    load_latest_intact,
    save_checkpoint,
)

CONFIG_FILE = "config.yaml"
DONE_FILE = "DONE"

# ---------------------------------------------------------------------------- CSV logs
EPISODES_CSV, TRAIN_CSV, EVAL_CSV = "episodes.csv", "train.csv", "eval.csv"
# episodes.csv: then one column p_<name> per physical parameter of the task
EPISODE_COLUMNS = ["step", "seed", "episode", "return", "length"]
EVAL_COLUMNS = ["step", "seed", "dynamics", "episode", "return", "length"]


def episode_columns(param_names) -> list[str]:
    return [*EPISODE_COLUMNS, *(f"p_{p}" for p in param_names)]


# ---------------------------------------------------------------------------- TensorBoard tags
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


def tb_episode_return(seed: int) -> str:
    return f"episode/return/seed{seed}"


def tb_train(name: str, seed: int) -> str:
    """A training metric (a train.csv column)."""
    return f"train/{name}/seed{seed}"


def tb_eval_return(dynamics: str, seed: int) -> str:
    """The mean evaluation return under `dynamics`."""
    return f"eval/{dynamics}/return/seed{seed}"


# ---------------------------------------------------------------------------- config.yaml
def config_yaml(config, extra: dict | None = None) -> str:
    """`config`'s fields (tuples as lists) then `extra`, as YAML."""
    values = {
        k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(config).items()
    }
    values.update(extra or {})
    return yaml.safe_dump(values, sort_keys=False)


def write_config(run_dir: Path, config, algo: str, command: str, fork: dict | None = None) -> None:
    """config.yaml of a new run: `algo`, every config field, the format and adarl versions, the
    command that started it and, for a fork, where it came from (`fork`, docs/run-format.md)."""
    record = {"format_version": RUN_FORMAT_VERSION, "adarl_version": __version__}
    record["command"] = command or " ".join(sys.argv)
    if fork is not None:
        record["fork"] = fork
    text = config_yaml(config, record)
    if not hasattr(config, "algo"):
        text = yaml.safe_dump({"algo": algo}, sort_keys=False) + text
    io.atomic_write_text(Path(run_dir) / CONFIG_FILE, text)


def load_config(run_dir: str | Path) -> dict:
    """Read and check a run folder's config.yaml (one-line errors for anything wrong)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UsageError(f"run folder {run_dir} does not exist")
    path = run_dir / CONFIG_FILE
    if not path.exists():
        raise UsageError(f"{run_dir} is not a run folder (no config.yaml)")
    try:
        values = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise UsageError(f"{path} is not valid YAML ({exc.__class__.__name__})") from exc
    if not isinstance(values, dict):
        raise UsageError(f"{path} is not a run config")
    version = values.get("format_version")
    if version != RUN_FORMAT_VERSION:
        raise UsageError(
            f"{run_dir} was written with run format {version!r}; this adarl "
            f"({__version__}) reads format {RUN_FORMAT_VERSION}"
        )
    return values


def config_from_run(run_dir: str | Path):
    """(algo, config) a run folder was started with, checked against the algorithm registry."""
    from adarl.algos import registry

    values = load_config(run_dir)
    return registry.config_from_record(values, str(Path(run_dir) / CONFIG_FILE))


# ---------------------------------------------------------------------------- starting a run
def start_new(run_dir: Path, lock: io.RunLock, config, algo: str, command: str) -> None:
    """Create a new run: refuse a non-empty folder (one-line UsageError, nothing written), take
    the lock, write config.yaml and environment.json."""
    io.check_new_run_dir(run_dir)
    lock.acquire(new=True)
    write_config(run_dir, config, algo, command)
    io.write_environment(run_dir)


def open_to_resume(run_dir: Path, lock: io.RunLock, config):
    """Take the lock of a run to resume. Returns None if the run is complete (DONE; a line on
    stderr), else its newest intact checkpoint `(path, arrays, meta)` checked against `config`,
    or `(None, None, None)` if it was killed before its first one (start again)."""
    io.check_resume_dir(run_dir)
    lock.acquire(new=False)
    if (run_dir / DONE_FILE).exists():
        print(f"run {run_dir} is already complete", file=sys.stderr)
        return None
    loaded = io.load_latest_intact(run_dir)
    if loaded is None:
        return None, None, None
    check_resume_config(run_dir, loaded[2], config)
    return loaded


def finish(run_dir: Path, step: int) -> None:
    io.atomic_write_text(Path(run_dir) / DONE_FILE, f"{step}\n")


# ---------------------------------------------------------------------------- checkpoint meta
def checkpoint_meta(algo: str, config, seeds, rngs, env_states: list, csv_offsets: dict) -> dict:
    """The keys both loops write to meta.json (the loop adds its own, e.g. `best`)."""
    return {
        "algo": algo,
        "seeds": [int(s) for s in seeds],
        "rng_states": [rng.bit_generator.state for rng in rngs],
        "env_states": env_states,
        "csv_offsets": csv_offsets,
        "config": config_record(config),
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


def csv_offsets(meta: dict) -> dict[str, int]:
    """Byte offsets of the CSV logs by file name (RNAC checkpoints of run format 1 wrote them
    without `.csv`)."""
    return {(k if k.endswith(".csv") else f"{k}.csv"): v for k, v in meta["csv_offsets"].items()}


# ---------------------------------------------------------------------------- env-state codec
def encode_env_state(obj, arrays: dict, key: str):
    """Make an environment's `get_state()` JSON-able for meta.json: its arrays go to `arrays`
    (the checkpoint's arrays.npz) under `key/…`, exactly, and dicts and tuples keep their kind."""
    if isinstance(obj, np.ndarray):
        arrays[key] = obj
        return {"__array__": key}
    if isinstance(obj, dict):
        return {
            "__dict__": [[k, encode_env_state(v, arrays, f"{key}/{k}")] for k, v in obj.items()]
        }
    if isinstance(obj, list | tuple):
        items = [encode_env_state(v, arrays, f"{key}/{j}") for j, v in enumerate(obj)]
        return {"__tuple__": items} if isinstance(obj, tuple) else items
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def decode_env_state(obj, arrays: dict):
    """The inverse of `encode_env_state`; also reads the SAC loop's run-format-1 encoding
    (arrays inline as `{"__ndarray__": list, "dtype": …}`)."""
    if isinstance(obj, dict):
        if "__array__" in obj:
            return arrays[obj["__array__"]]
        if "__ndarray__" in obj:
            return np.asarray(obj["__ndarray__"], dtype=obj["dtype"])
        if "__dict__" in obj:
            return {k: decode_env_state(v, arrays) for k, v in obj["__dict__"]}
        if "__tuple__" in obj:
            return tuple(decode_env_state(v, arrays) for v in obj["__tuple__"])
        return {k: decode_env_state(v, arrays) for k, v in obj.items()}
    if isinstance(obj, list):
        return [decode_env_state(v, arrays) for v in obj]
    return obj


def encode_env_states(envs, arrays: dict) -> list:
    return [encode_env_state(env.get_state(), arrays, f"env/{i}") for i, env in enumerate(envs)]
