"""The boundary between the one training loop (`adarl.train.loop`) and an algorithm's learner
(`adarl.train.sac_learner`, `adarl.train.rnac_learner`): the `Learner` protocol and what crosses
it. The loop drives a learner one way: it calls the learner, the learner returns values, and
nothing in a learner touches the loop, its logs or the run folder.

A step of the loop: `advance(step)` acts and learns up to the next step the loop must look at
and returns an `Advance`: that step, the episodes that finished on the way and the `Event`s due
there. The loop logs the episodes; at a `TRUNCATE` it keeps the pre-truncation checkpoint (a
fork point) and writes what `truncate(step)` returns (a `Truncation`: the spectra and the
truncations.csv rows); then the train.csv rows (`LOG`), the evaluation (`EVALUATE`) and the
checkpoint (`CHECKPOINT`). A run restored from a pre-truncation checkpoint starts at that step's
truncation (the loop reads the checkpoint's phase; the learner is not told).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


class Event(enum.Enum):
    """What is due at the step an `advance` ends at, in the order the loop does it."""

    TRUNCATE = "truncate"  # AdaRL's rank truncation (the schedule's truncation steps)
    LOG = "log"  # train.csv rows and the divergence watch (every `log_every`, and at the end)
    EVALUATE = "evaluate"  # every `eval_every`, and at the end
    CHECKPOINT = "checkpoint"  # every `checkpoint_every`, and at the end
    END = "end"  # the last step, `total_steps`


def due(config, step: int, truncate: bool = False) -> frozenset[Event]:
    """The events due at environment step `step` of a run of `config` (`truncate`: the
    learner's schedule truncates there)."""
    end = step == config.total_steps
    events = {Event.TRUNCATE} if truncate else set()
    for event, every in (
        (Event.LOG, config.log_every),
        (Event.EVALUATE, config.eval_every),
        (Event.CHECKPOINT, config.checkpoint_every),
    ):
        if step % every == 0 or end:
            events.add(event)
    return frozenset(events | ({Event.END} if end else set()))


@dataclass(frozen=True)
class Episode:
    """An episode of the seed at position `index` of the learner's seeds that ended at
    environment step `step`; `info` is the environment's last info (`episode_index`,
    `dynamics`)."""

    index: int
    step: int
    info: dict
    ret: float
    length: int


@dataclass
class Advance:
    """What an `advance` returns: the step reached, the episodes finished on the way (in the
    order they finished) and the events due at `step`."""

    step: int
    episodes: list[Episode] = field(default_factory=list)
    events: frozenset[Event] = frozenset()


@dataclass
class Truncation:
    """What a truncation returns for the loop to write: each layer's singular values, one row
    per seed (layout.SPECTRA_DIR/spectrum_<step>.npz), and the truncations.csv rows."""

    spectra: dict[str, np.ndarray]
    rows: list[dict]


class Learner(Protocol):
    """An algorithm's state and how it acts and learns, as the loop drives it."""

    algo: str
    config: object  # the algorithm's config (`total_steps`, `*_every`, `eval_dynamics`, …)
    seeds: list[int]
    env_options: dict  # `envs.make` keywords of its environments (evaluation too)
    train_columns: list[str]  # train.csv's columns
    # more CSV logs: file name -> the columns of a new file, then older column sets that a
    # resumed file keeps when its header has exactly those columns (e.g. truncations.csv)
    extra_logs: dict[str, tuple[list[str], ...]]

    def param_names(self) -> list[str]:
        """The physical parameters an episode records (episodes.csv's `p_<name>` columns): the
        names of its tasks' `dynamics_params` (adarl.envs.contract.Task)."""

    def close(self) -> None:
        """Close its environments (at the end of the run)."""

    def fresh(self) -> None:
        """The initial state; resets the environments."""

    def restore(self, arrays: dict, meta: dict) -> None:
        """The state of a checkpoint (`checkpoint_state`'s arrays, meta.json)."""

    def advance(self, step: int) -> Advance:
        """Act and learn from environment step `step` up to the next step the loop must look at."""

    def parameters_finite(self) -> bool:
        """Are all parameters and optimiser states finite (no pre-truncation checkpoint
        otherwise)?"""

    def truncate(self, step: int) -> Truncation:
        """The truncation due at `step` (only a learner whose advances return `TRUNCATE`; its
        config has `checkpoint_before_truncation`)."""

    def train_rows(self, step: int, steps_per_s: float) -> list[dict]:
        """train.csv rows since the last ones (may be empty)."""

    def policies(self) -> list[dict]:
        """Each seed's policy arrays (adarl.policy)."""

    def checkpoint_state(self) -> tuple[dict[str, np.ndarray], dict]:
        """Everything needed to continue exactly: arrays, and entries of meta.json (a learner
        that steps Gymnasium environments on the host adds its generators' and environments'
        states with `adarl.runs.checkpoints.host_meta`; `restore` gets them back in `meta`)."""

    def nonfinite(self, step: int) -> dict[str, list[int]]:
        """What is not finite at `step`: quantity (`"actor parameters"`, `"loss_q"`, …) -> the
        seeds where it is not (parameters, optimiser states, the latest update metrics, the
        current episodes' returns); only quantities with seeds. The loop's divergence watch
        stops or warns (`adarl.train.guards.nonfinite_seeds` helps build it)."""
