"""What a training run starts from, and the one path that starts it, shared by `adarl train` and
the sweeps' worker (which only parse their input and call `train`):

* `New`: a new run of an algorithm, its preset and the config fields given as flags (field ->
  text as typed), resolved as every config is (`registry.resolve_config`);
* `ForkOf`: a new run from another run's checkpoint at `at`, with `changes` (`adarl.train.fork`);
* `Resume`: a run continued from its newest complete checkpoint.

Each is also the `adarl train` flags that start the same run (`argv`, what a run records as its
command and a sweep shows) and a JSON record (`record`, `from_record`: how a sweep hands a unit
to its worker). Importing this module imports no JAX; `train` does.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from adarl.errors import UsageError


def _flag(name: str) -> str:
    return f"--{name.replace('_', '-')}"


def _field_flags(fields: Mapping[str, str]) -> list[str]:
    return [word for name, text in fields.items() for word in (_flag(name), text)]


@dataclass(frozen=True)
class New:
    algo: str
    preset: str | None = None  # None: the algorithm's default preset
    flags: Mapping[str, str] = field(default_factory=dict, hash=False)  # field -> text as typed

    def config(self):
        """The config: defaults <- the algorithm <- per-task defaults <- preset <- flags."""
        from adarl.algos import registry

        algo = registry.get(self.algo).name
        return registry.resolve_config(algo, self.preset, dict(self.flags))

    def argv(self) -> tuple[str, ...]:
        preset = ["--preset", self.preset] if self.preset else []
        return ("--algo", self.algo, *preset, *_field_flags(self.flags))


@dataclass(frozen=True)
class ForkOf:
    parent: str  # its run folder (in a sweep's unit: the parent unit's id, `Unit.start_in`)
    at: str | int  # a checkpoint step, or `first-truncation`
    changes: Mapping[str, str] = field(default_factory=dict, hash=False)  # field -> text

    def argv(self) -> tuple[str, ...]:
        return ("--fork", str(self.parent), "--at", str(self.at), *_field_flags(self.changes))


@dataclass(frozen=True)
class Resume:
    run_dir: str

    def argv(self) -> tuple[str, ...]:
        return ("--resume", str(self.run_dir))


@dataclass(frozen=True)
class Tracking:
    """Weights & Biases mirroring (`adarl.runs.tracking`), as `adarl train --track` takes it."""

    enabled: bool = False
    project: str | None = None
    entity: str | None = None
    group: str | None = None

    def argv(self) -> tuple[str, ...]:
        named = {"project": self.project, "entity": self.entity, "group": self.group}
        words = [w for k, v in named.items() if v is not None for w in (f"--wandb-{k}", v)]
        return ("--track", *words) if self.enabled else tuple(words)

    def check(self) -> None:
        """A one-line UsageError for a --wandb-* flag without --track."""
        named = (("project", self.project), ("entity", self.entity), ("group", self.group))
        for name, value in named:
            if value is not None and not self.enabled:
                raise UsageError(f"--wandb-{name} is for --track")


def record(start: New | ForkOf) -> dict:
    """`start` as JSON: `{"algo", "preset", "flags"}`, or `{"fork": {"from", "at", "changes"}}`."""
    if isinstance(start, ForkOf):
        return {"fork": {"from": str(start.parent), "at": start.at, "changes": dict(start.changes)}}
    return {"algo": start.algo, "preset": start.preset, "flags": dict(start.flags)}


def from_record(data: dict) -> New | ForkOf:
    """The inverse of `record`."""
    if "fork" in data:
        fork = data["fork"]
        return ForkOf(fork["from"], fork["at"], dict(fork["changes"]))
    return New(data["algo"], data.get("preset"), dict(data.get("flags", {})))


def default_run_dir(task: str, algo: str) -> Path:
    """runs/<task>-<algo>-<time>."""
    return Path("runs") / f"{task}-{algo}-{time.strftime('%Y%m%d-%H%M%S')}"


def train(
    start: New | ForkOf | Resume,
    out: str | Path | None,
    command: str,
    progress: bool = True,
    tracking: Tracking = Tracking(),
) -> Path:
    """Train the run `start` describes into `out` (default `default_run_dir`; a `Resume` trains
    in its own folder), recording `command`; returns its folder. A fork is checked, then
    written, then trains as a resumed run; the tracking flags are checked before a fork's
    folder is written. Bad input is a one-line UsageError."""
    from adarl.runs import folder
    from adarl.runs import tracking as wandb
    from adarl.train import fork

    planned = None
    if isinstance(start, Resume):
        run_dir = Path(start.run_dir)
        algo, config = folder.config_from_run(run_dir)
    elif isinstance(start, ForkOf):
        planned = fork.prepare(start.parent, start.at, start.changes)
        run_dir = Path(out) if out else default_run_dir(planned.config.task, planned.algo)
    else:
        from adarl.algos import registry

        algo, config = registry.get(start.algo).name, start.config()
        run_dir = Path(out) if out else default_run_dir(getattr(config, "task", "task"), algo)
    tracking.check()
    if planned is not None:
        fork.write(planned, run_dir, command)
        algo, config = folder.config_from_run(run_dir)
    from adarl.train.trainers import trainer

    with wandb.tracked(
        tracking.enabled,
        run_dir,
        config,
        project=tracking.project,
        entity=tracking.entity,
        group=tracking.group,
        command=command,
    ):
        trainer(algo)(config, run_dir, not isinstance(start, New), progress, command)
    return run_dir
