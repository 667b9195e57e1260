"""Forks: a new run that starts from another run's exact state at one of its checkpoints, with
some settings changed (`adarl train --fork RUN_DIR --at STEP --out NEW [--field value ...]`).

Why: AdaRL's schedule-matched control must differ from AdaRL in nothing but the components a
truncation removes. Forking an AdaRL run at the checkpoint it keeps just before its first
truncation (`checkpoints/pre_truncation/step_N`) with `--apply-cuts false` gives that control:
both arms share the whole prefix bit for bit (replay buffer, RNG streams, optimiser and
environment states), and the prefix is trained once. A fork that changes nothing continues
exactly as its parent did (tests/train/test_fork.py).

The child is a complete run folder (docs/run-format.md): the parent's CSV rows up to STEP (so its
curves start at 0), the parent's spectra of the truncations before the fork point, the checkpoint
it starts from as its own first checkpoint (with the child's config), `config.yaml` with a `fork`
record (`from`, `step`, `checkpoint`, `changed`) and `environment.json` with the same record and
the parent's environment. It then trains as a resumed run does. Only the fields in `FORKABLE`
may change; a field that fixes what was already trained (task, networks, seeds, buffer, …) is a
one-line UsageError, as are a missing checkpoint and RNAC runs.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from adarl.algos.sac_config import SAC_FAMILY, SACConfig
from adarl.errors import UsageError
from adarl.files import atomic_write_bytes
from adarl.runs import checkpoints, folder
from adarl.runs.layout import (
    ARRAYS_FILE,
    META_FILE,
    PRE_TRUNCATION,
    PRE_TRUNCATION_DIR,
    SPECTRA_DIR,
    STEP_PREFIX,
    checkpoint_step,
)
from adarl.runs.lock import RunLock
from adarl.runs.provenance import write_environment

# Config fields a fork may change: what the truncations from the fork point on do, the budget and
# the learning-rate schedule, and how the run is evaluated, logged and checkpointed. Everything
# else (task, dynamics, networks, seeds, buffer, SAC's hyperparameters, …) made the state the
# fork starts from.
FORKABLE = (
    "apply_cuts",
    "rank_rule",
    "beta",
    "retain_tolerance",
    "retain_samples",
    "truncate_every",
    "total_steps",
    "lr_schedule",
    "warmup_steps",
    "lr_min_ratio",
    "schedule_first_iteration",
    "eval_every",
    "eval_episodes",
    "eval_dynamics",
    "log_every",
    "checkpoint_every",
    "keep_checkpoints",
    "checkpoint_before_truncation",
    "on_divergence",
)
FIRST_TRUNCATION = "first-truncation"  # --at: the parent's first truncation step
# AdaRL and its control: `apply_cuts` decides which of the two a fork is
CONTROL_PAIR = {True: "adarl", False: "adarl-control"}


@dataclass(frozen=True)
class Fork:
    """A checked fork, not yet written: what the child starts from and trains."""

    parent: Path
    step: int
    checkpoint: Path  # the parent's checkpoint folder it starts from
    algo: str
    config: SACConfig  # the child's
    record: dict  # config.yaml's `fork`


def prepare(parent: str | Path, at: str | int, changes: Mapping[str, object]) -> Fork:
    """Check a fork of run `parent` at `at` (a step, or `first-truncation`) with `changes`
    (field -> value, or text as typed) without writing anything; one-line UsageErrors."""
    parent = Path(parent).resolve()
    algo, before = folder.config_from_run(parent)
    if not isinstance(before, SACConfig):
        raise UsageError(
            f"{parent} is a {algo} run; forks are for the SAC family ({', '.join(SAC_FAMILY)})"
        )
    config, changed = forked_config(algo, before, changes)
    from adarl.envs import check_dynamics

    for label in config.eval_dynamics:  # checked now: the learner would find it after the write
        check_dynamics(label, config.task, **config.env_options())
    step = fork_step(before, at)
    points = fork_points(parent)
    if step not in points:
        raise UsageError(
            f"{parent} has no checkpoint at step {step}; fork points: {describe_points(points)}"
        )
    checkpoint = points[step]
    pre = checkpoint.parent.name == PRE_TRUNCATION
    if config.total_steps < step or (config.total_steps == step and not pre):
        raise UsageError(
            f"total-steps {config.total_steps} leaves nothing to train after the fork at step "
            f"{step}; give --total-steps > {step}"
        )
    record = {
        "from": str(parent),
        "step": step,
        "checkpoint": PRE_TRUNCATION if pre else "end_of_chunk",
        "changed": changed,
    }
    return Fork(parent, step, checkpoint, config.algo, config, record)


def fork_step(config, at: str | int) -> int:
    """`at` as an environment step: a number, or `first-truncation` (the first step at which a
    run of `config` truncates)."""
    from adarl.algos import schedule

    text = str(at).strip().replace("_", "-")
    if text == FIRST_TRUNCATION:
        steps = schedule.truncation_steps(config)
        if not steps:
            raise UsageError(
                f"--at {FIRST_TRUNCATION}: a {config.algo} run of {config.total_steps} steps with "
                f"truncate-every {config.truncate_every} never truncates"
            )
        return steps[0]
    try:
        return int(str(at).replace("_", ""))
    except ValueError:
        raise UsageError(f"--at expects a step or {FIRST_TRUNCATION}, got {at!r}") from None


def fork_points(run_dir: Path) -> dict[int, Path]:
    """Every step a run can be forked at -> its checkpoint folder; at a step with both, the
    pre-truncation checkpoint (the state before that step's truncation)."""
    points = {checkpoint_step(p): p for p in checkpoints.checkpoint_dirs(run_dir)}
    points.update(
        {checkpoint_step(p): p for p in checkpoints.checkpoint_dirs(run_dir, PRE_TRUNCATION_DIR)}
    )
    return dict(sorted(points.items()))


def _points_with_logs(run_dir: Path) -> dict[int, Path]:
    """The fork points whose checkpoints' CSV offsets the parent's logs still reach."""
    sizes = {}
    fit = {}
    for step, path in fork_points(run_dir).items():
        try:
            meta = checkpoints.read_meta(path)
            checkpoints.check_csv_offsets(path, meta)
            offsets = checkpoints.csv_offsets(meta)
        except (UsageError, KeyError, AttributeError):
            continue
        for name in offsets:
            if name not in sizes:
                log = run_dir / name
                sizes[name] = log.stat().st_size if log.is_file() else 0
        if all(sizes[name] >= offset for name, offset in offsets.items()):
            fit[step] = path
    return fit


def describe_points(points: Mapping[int, Path]) -> str:
    """`950 (pre-truncation), 1000, 1500`, or `none`."""
    pre = PRE_TRUNCATION
    return (
        ", ".join(
            f"{s}{' (pre-truncation)' if p.parent.name == pre else ''}" for s, p in points.items()
        )
        or "none"
    )


def forked_config(algo: str, parent, changes: Mapping[str, object]):
    """(child config, changed) for `changes` (field -> value, or text as typed) to the config
    `parent` of an `algo` run; `changed` maps each field that differs to {from, to}. Turning
    `apply_cuts` off (on) makes an AdaRL run its control (the control AdaRL)."""
    from adarl.algos import registry
    from adarl.algos.flags import field_value, type_text

    hints = typing.get_type_hints(type(parent))
    values = {}
    for name, value in changes.items():
        flag = f"--{name.replace('_', '-')}"
        if name not in hints:
            raise UsageError(f"{flag} does not apply to --algo {algo}")
        if name not in FORKABLE:
            allowed = ", ".join(f"--{f.replace('_', '-')}" for f in FORKABLE)
            raise UsageError(
                f"{flag} cannot change at a fork: it shaped the state the fork starts from; "
                f"fields that may change: {allowed}"
            )
        values[name] = field_value(name, value, type_text(hints[name]))
    if "apply_cuts" in values and algo in CONTROL_PAIR.values():
        values["algo"] = CONTROL_PAIR[bool(values["apply_cuts"])]
    child = dataclasses.replace(parent, **values).validate()
    registry.get(child.algo)
    then, now = checkpoints.config_record(parent), checkpoints.config_record(child)
    changed = {k: {"from": then[k], "to": now[k]} for k in now if then.get(k) != now[k]}
    return child, changed


def check_forkable(parent, child) -> dict:
    """The fields in which config `child` differs from `parent` ({from, to}), in `FORKABLE`'s
    order (a sweep's fork arguments follow it, whatever the config class's field order), or a
    one-line UsageError naming the first one a fork cannot change (the sweeps check their fork
    units with it)."""
    then, now = checkpoints.config_record(parent), checkpoints.config_record(child)
    changed = {k: {"from": then.get(k), "to": now[k]} for k in now if then.get(k) != now[k]}
    if "algo" in changed and set(CONTROL_PAIR.values()) != {then["algo"], now["algo"]}:
        raise UsageError(
            f"a fork keeps its parent's algorithm ({then['algo']}); only adarl and "
            "adarl-control fork into each other (apply-cuts)"
        )
    for name in changed:
        if name not in (*FORKABLE, "algo"):
            raise UsageError(
                f"{name} differs ({then.get(name)!r} in the parent, {now[name]!r} in the fork) "
                "but cannot change at a fork"
            )
    order = (*FORKABLE, "algo")
    return dict(sorted(changed.items(), key=lambda item: order.index(item[0])))


def write(fork: Fork, out: Path, command: str) -> None:
    """Create the child run folder `out` (new or empty): CSV rows up to the fork point,
    spectra before it, environment.json, config.yaml, then its first checkpoint (last, and
    atomic: a fork folder without a checkpoint is incomplete, which `--resume` refuses and the
    sweeps' worker makes again)."""
    out = Path(out)
    folder.check_new_run_dir(out)
    arrays, meta = checkpoints.load_checkpoint(fork.checkpoint)
    if int(meta["step"]) != fork.step:
        raise UsageError(f"checkpoint {fork.checkpoint} is of step {meta['step']}, not {fork.step}")
    _, parent_config = folder.config_from_run(fork.parent)
    folder.check_resume_config(fork.parent, meta, parent_config)  # the checkpoint is of this run
    logs = {}  # read and checked whole before the first write (a retry must find `out` empty)
    for name, offset in checkpoints.csv_offsets(meta).items():
        source = fork.parent / name
        data = source.read_bytes()[:offset] if source.exists() else b""
        if len(data) < offset:
            fit = _points_with_logs(fork.parent)
            instead = (
                f"fork at a step whose rows are all there: {describe_points(fit)}"
                if fit
                else f"restore {source} (no fork point has all its rows)"
            )
            raise UsageError(
                f"{source} is shorter ({len(data)} bytes) than its checkpoint at step "
                f"{fork.step} says ({offset}); {instead}"
            )
        logs[name] = data
    from adarl.runs.provenance import read_environment

    parent_env = {"parent_environment": read_environment(fork.parent)}
    with RunLock(out) as lock:
        lock.acquire(new=True)
        for name, data in logs.items():
            atomic_write_bytes(out / name, data)
        pre = fork.record["checkpoint"] == PRE_TRUNCATION
        for spectrum in sorted((fork.parent / SPECTRA_DIR).glob(f"{STEP_PREFIX}*.npz")):
            step = int(spectrum.stem.split("_")[1])
            if step < fork.step or (step == fork.step and not pre):
                atomic_write_bytes(out / SPECTRA_DIR / spectrum.name, spectrum.read_bytes())
        write_environment(out, {"fork": {**fork.record, **parent_env}})
        folder.write_config(out, fork.config, fork.algo, command, fork=fork.record)
        files = {
            p.name: p.read_bytes()
            for p in sorted(fork.checkpoint.iterdir())
            if p.name not in (ARRAYS_FILE, META_FILE)
        }
        meta = {k: v for k, v in meta.items() if k != "arrays_sha256"}
        meta.update(algo=fork.algo, config=checkpoints.config_record(fork.config), fork=fork.record)
        checkpoints.save_checkpoint(
            out, fork.step, arrays, meta, keep=fork.config.keep_checkpoints, files=files
        )
