"""Every file and folder name of a run folder (docs/run-format.md), and the small helpers that
build or parse them. Nothing else in adarl spells these names."""

from __future__ import annotations

import os
import re
from pathlib import Path

#: The run format this adarl writes and reads (config.yaml and every checkpoint's meta.json).
RUN_FORMAT_VERSION = 1

# ---------------------------------------------------------------------------- the run folder
CONFIG_FILE = "config.yaml"  # the resolved config, `algo`, versions, `command`
ENVIRONMENT_FILE = "environment.json"  # what produced the run (adarl.runs.provenance)
DONE_FILE = "DONE"  # written last, holds the final step
LOCK_FILE = ".lock"  # holds the PID of the process writing the run (flock, adarl.runs.lock)
EPISODES_CSV = "episodes.csv"
TRAIN_CSV = "train.csv"
EVAL_CSV = "eval.csv"
TRUNCATIONS_CSV = "truncations.csv"  # algorithms that truncate ranks
TB_DIR = "tb"  # TensorBoard events
SPECTRA_DIR = "spectra"  # singular values at each truncation, step_<n>.npz
EVALUATIONS_DIR = "evaluations"  # `adarl evaluate` results
SUITES_DIR = "suites"  # `adarl evaluate --suite` summaries
REPORT_DIR = "report"  # the report `adarl train` writes at the end

# ---------------------------------------------------------------------------- checkpoints
CHECKPOINT_DIR = "checkpoints"  # checkpoints/step_<n>/
PRE_TRUNCATION = "pre_truncation"
# checkpoints taken just before a truncation (fork points): kept, never rotated or resumed from
PRE_TRUNCATION_DIR = f"{CHECKPOINT_DIR}/{PRE_TRUNCATION}"
ARRAYS_FILE = "arrays.npz"
META_FILE = "meta.json"  # written last: a checkpoint folder without it is incomplete
STEP_PREFIX = "step_"
DAMAGED_PREFIX = "damaged_"  # a checkpoint that failed to load is renamed damaged_step_<n>
POLICY_PATTERN = re.compile(r"^policy_seed_(\d+)\.npz$")
#: a column per physical parameter of the task in episodes.csv and evaluation tables: p_<name>
PARAM_PREFIX = "p_"
#: a column per bottleneck layer in train.csv: rank_<layer> (actor_1, q1_1, …)
RANK_PREFIX = "rank_"


def step_name(step: int) -> str:
    """`step_<step, 12 digits>`: a checkpoint folder's name and a spectra file's stem."""
    return f"{STEP_PREFIX}{step:012d}"


def checkpoint_step(checkpoint: Path) -> int:
    """The step of a checkpoint folder `step_<n>`."""
    return int(checkpoint.name.split("_")[1])


def spectrum_file(step: int) -> str:
    return f"{step_name(step)}.npz"


def policy_file_name(seed: int) -> str:
    """A seed's policy file in a checkpoint (adarl.policy format)."""
    return f"policy_seed_{seed}.npz"


def best_policy_file_name(seed: int) -> str:
    """A seed's best policy so far, kept in each checkpoint by algorithms that keep one."""
    return f"best_policy_seed_{seed}.npz"


def is_run(path: str | os.PathLike) -> bool:
    """Whether `path` is a run folder (holds config.yaml)."""
    return (Path(path) / CONFIG_FILE).is_file()


def param_column(name: str) -> str:
    """The column of physical parameter `name` (episodes.csv, evaluation tables)."""
    return PARAM_PREFIX + name


def param_columns(columns) -> list[str]:
    """The parameter columns among `columns`, in their order."""
    return [c for c in columns if c.startswith(PARAM_PREFIX)]


def param_name(column: str) -> str:
    """The parameter a `param_column` holds."""
    return column.removeprefix(PARAM_PREFIX)


def rank_column(layer: str) -> str:
    """train.csv's column of bottleneck `layer`'s rank."""
    return RANK_PREFIX + layer


def rank_columns(columns) -> list[str]:
    """The rank columns among `columns`, in their order."""
    return [c for c in columns if c.startswith(RANK_PREFIX)]


def rank_layer(column: str) -> str:
    """The layer a `rank_column` holds."""
    return column.removeprefix(RANK_PREFIX)


def evaluation_sidecar(path: str | os.PathLike) -> Path:
    """The JSON sidecar beside an evaluation CSV (same stem), written after it: an evaluation
    whose sidecar is missing is incomplete."""
    return Path(path).with_suffix(".json")
