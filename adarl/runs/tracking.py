"""Optional experiment tracking with Weights & Biases: `adarl train --track` (the flag CleanRL and
rl-zoo3 use) mirrors every TensorBoard scalar of the run, under the same tag, to a W&B run whose
config is the run's config. Needs the `track` extra (`pip install 'adarl[track]'`).

The run folder stays the record: W&B is a mirror, written as the TensorBoard events are
(`adarl.runs.logs.Scalars` calls `log`), and never read back. Each scalar is logged with its
environment step as `global_step`, the x-axis of every chart, so that W&B's own step counter never
has to follow the run's steps (a resumed run logs the stretch since its checkpoint again, with the
same values). A resumed run continues the same W&B run: its id is derived from the run folder's
path and config. `WANDB_MODE=offline` writes the W&B run under `WANDB_DIR` (default `./wandb`)
for a later `wandb sync`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
from pathlib import Path

from adarl.errors import UsageError

INSTALL = "pip install 'adarl[track]'"
DEFAULT_PROJECT = "adarl"

_run = None  # the W&B run the scalars go to, while a tracked run trains


def import_wandb():
    """The wandb module, or a one-line UsageError saying what to install."""
    try:
        import wandb
    except ImportError:
        raise UsageError(
            f"--track needs Weights & Biases (the wandb package), which is not installed; "
            f"install it with: {INSTALL}"
        ) from None
    return wandb


def run_id(run_dir: Path, config) -> str:
    """A W&B run id that is the same for every resume of one run folder."""
    key = json.dumps([str(Path(run_dir).resolve()), config_dict(config)], sort_keys=True)
    return hashlib.sha256(key.encode()).hexdigest()[:16]


def config_dict(config) -> dict:
    return {
        k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(config).items()
    }


def log(step: int, scalars: dict[str, float]) -> None:
    """Mirror TensorBoard scalars at environment step `step` (nothing when not tracking)."""
    if _run is not None and scalars:
        _run.log({**scalars, "global_step": int(step)})


@contextlib.contextmanager
def tracked(
    enabled: bool,
    run_dir: Path,
    config,
    project: str | None = None,
    entity: str | None = None,
    group: str | None = None,
    command: str = "",
):
    """While the block trains, `log` sends to a W&B run for `run_dir`; a no-op unless
    `enabled`. Raises the one-line UsageError of `import_wandb` before anything is written."""
    global _run
    if not enabled:
        yield None
        return
    wandb = import_wandb()
    try:
        run = wandb.init(
            project=project or DEFAULT_PROJECT,
            entity=entity,
            group=group,
            name=Path(run_dir).name,
            id=run_id(run_dir, config),
            resume="allow",
            config={
                **config_dict(config),
                "run_dir": str(Path(run_dir).resolve()),
                "command": command,
            },
            settings=wandb.Settings(console="off"),  # the terminal output stays adarl's own
        )
    except wandb.errors.Error as exc:  # not logged in, an unknown entity, no network
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise UsageError(
            f"--track: Weights & Biases did not start a run: {message} "
            f"(or set WANDB_MODE=offline and `wandb sync` later)"
        ) from None
    run.define_metric("global_step")
    run.define_metric("*", step_metric="global_step")
    _run = run
    failed = True
    try:
        yield run
        failed = False
    finally:
        _run = None
        run.finish(exit_code=1 if failed else 0)
