"""Checks that stop a training run with one line: a run larger than the machine's memory
(before anything is written) and training that diverged (docs/reliability.md)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from adarl.errors import ON_DIVERGENCE, Diverged, UsageError
from adarl.runs.checkpoints import checkpoint_dirs

#: Resident memory of one environment of a run, rounded up from what 100 environments made and
#: reset in one process add to its resident set: 1.2 MB each for Hopper, 1.4 MB for Humanoid
#: (MuJoCo's model and data; the data's arena is reserved, not touched).
ENV_BYTES = 2 * 2**20


def gib(nbytes: int) -> str:
    return f"{nbytes / 2**30:,.1f} GiB"


def machine_memory() -> int | None:
    """The machine's physical memory in bytes; None where it is not knowable."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(nbytes: int, what: str, lower: str) -> None:
    """A one-line UsageError if `what` needs more bytes than the machine's physical memory;
    `lower` says what to lower (`lower --buffer-size or …`)."""
    total = machine_memory()
    if total is not None and nbytes > total:
        raise UsageError(
            f"{what} need {gib(nbytes)} but this machine has {gib(total)} of memory; {lower}"
        )


def check_training_memory(n_seeds: int, buffers: int, networks: int, lower: str) -> None:
    """The one memory check of a training run, made before its networks and all environments
    but the first exist: `buffers` (replay or rollout) and `networks` (parameters, target copies
    and Adam's moments, float32), in bytes over all seeds, and `ENV_BYTES` per seed's
    environment. A floor: what training adds (gradients, host copies, checkpoints) is left out."""
    envs = n_seeds * ENV_BYTES
    check_memory(
        buffers + networks + envs,
        f"{n_seeds} seed{'s' * (n_seeds > 1)} (buffers {gib(buffers)}, networks {gib(networks)}, "
        f"environments {gib(envs)})",
        lower,
    )


def nonfinite_seeds(seeds, values) -> list[int]:
    """The seeds whose `values` (one per seed, or per seed × anything, in the order of `seeds`)
    are not all finite."""
    values = np.asarray(values, dtype=np.float64).reshape(len(seeds), -1)
    return [int(s) for s, ok in zip(seeds, np.isfinite(values).all(axis=1)) if not ok]


def accelerator_memory() -> int | None:
    """The memory of JAX's default device in bytes where it is an accelerator; None on a CPU
    (the machine's memory is what counts there) or where the device does not say."""
    import jax

    device = jax.devices()[0]
    if device.platform == "cpu":
        return None
    return (device.memory_stats() or {}).get("bytes_limit")


def check_device_memory(n_seeds: int, buffers: int, networks: int, lower: str) -> None:
    """The device backend's memory check, before anything is allocated: its replay buffers and
    networks (bytes over all seeds) live in the accelerator's memory, which must hold them. A
    floor: the chunk's activations and XLA's workspace are left out."""
    total = accelerator_memory()
    if total is not None and buffers + networks > total:
        raise UsageError(
            f"{n_seeds} seed{'s' * (n_seeds > 1)} (buffers {gib(buffers)}, networks "
            f"{gib(networks)}) need {gib(buffers + networks)} but the accelerator has "
            f"{gib(total)} of memory; {lower}"
        )


class DivergenceWatch:
    """Non-finite losses, parameters and returns, per seed, checked at each logging point.

    `note(quantity, seeds)` records them; `check(step)` then stops the run with `Diverged` (exit
    code 3; no DONE; the last checkpoint stays the last good one) or, with `--on-divergence
    continue`, prints one warning line the first time and goes on.
    """

    def __init__(self, run_dir: str | os.PathLike, mode: str = "stop"):
        self.run_dir = Path(run_dir)
        self.mode = mode if mode in ON_DIVERGENCE else "stop"
        self.found: dict[str, list[int]] = {}
        self.warned = False

    def note(self, quantity: str, seeds) -> None:
        seeds = [int(s) for s in seeds]
        if seeds:
            known = self.found.setdefault(quantity, [])
            known.extend(s for s in seeds if s not in known)

    def note_values(self, quantity: str, seeds, values) -> None:
        """Note the seeds whose `values` (one per seed, or per seed × anything) are not all
        finite."""
        self.note(quantity, nonfinite_seeds(seeds, values))

    def check(self, step: int) -> None:
        if not self.found:
            return
        what = "; ".join(
            f"{q} (seed{'s' * (len(s) > 1)} {', '.join(map(str, sorted(s)))})"
            for q, s in self.found.items()
        )
        self.found = {}
        good = checkpoint_dirs(self.run_dir)
        kept = f"last good checkpoint {good[-1].name}" if good else "no checkpoint yet"
        if self.mode == "stop":
            raise Diverged(
                f"training diverged at step {step}: non-finite {what}; {kept} "
                "(--on-divergence continue keeps training)"
            )
        if not self.warned:
            print(
                f"adarl: warning: training diverged at step {step}: non-finite {what}; "
                "continuing (--on-divergence continue)",
                file=sys.stderr,
                flush=True,
            )
            self.warned = True


def check_logged_physics(run_dir: str | os.PathLike, task: str, dynamics: str) -> None:
    """On resume: a one-line UsageError when the run's episodes.csv shows a parameter varying
    that its dynamics spec, as this adarl reads it, holds fixed. The run was trained under
    another reading of the spec (before issue 62, a range on a task outside the paper's four also
    drew mass_scale and friction_scale), and resuming it would not continue what it trained."""
    import csv

    from adarl.envs import parse_dynamics
    from adarl.runs import layout

    path = Path(run_dir) / layout.EPISODES_CSV
    if not path.is_file():
        return
    seen: dict[str, set[str]] = {}
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            for column, value in row.items():
                if column and column.startswith(layout.PARAM_PREFIX) and value not in ("", None):
                    seen.setdefault(column, set()).add(value)
    if not seen:  # no physics logged (a plain env, or no episode yet): nothing to compare
        return
    varying = set(parse_dynamics(dynamics, task).sinusoids)
    for column, values in seen.items():
        name = column.removeprefix(layout.PARAM_PREFIX)
        if name not in varying and len(values) > 1:
            raise UsageError(
                f"{path} shows {name} varying over {len(values)} values, but the run's dynamics "
                f"{dynamics!r} holds it fixed in this adarl: the run was trained under an older "
                "reading of its spec; resume it with the adarl it started on, or start a new run"
            )


def model_record(config) -> dict:
    """environment.json's `model` for a new run of `config` (`adarl.envs.tasks.model_identity`;
    nothing for a task without an XML of its own)."""
    from adarl.envs.tasks import model_identity, task_of

    identity = model_identity(task_of(config)) if getattr(config, "task", None) else None
    return {"model": identity} if identity else {}


def check_run_model(run_dir: str | os.PathLike, config) -> None:
    """On resume: a one-line UsageError if the run's model (environment.json `model`) is not the
    one its config resolves to here (`adarl.envs.tasks.check_model`)."""
    from adarl.envs.tasks import check_model, task_of
    from adarl.runs.provenance import read_environment

    try:
        record = read_environment(run_dir) or {}
    except UsageError:
        return  # a damaged record is provenance's to report
    if getattr(config, "task", None) and record.get("model"):
        check_model(task_of(config), record["model"], f"run {run_dir}", "resuming")
