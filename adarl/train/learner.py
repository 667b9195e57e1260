"""What the one training loop (`adarl.train.loop`) asks of a learner, and what a learner hands
back: the boundary between them runs one way.

The loop calls the learner; the learner never calls the loop, never writes a log or a file, and
never reads the loop's state. It returns what happened (`Advance`: the new step, the episodes
that finished, whether a truncation is due) and what a truncation produced (`Truncation`: the
spectra and the truncations.csv rows), and the loop writes them, takes the checkpoints and runs
the evaluations. A new algorithm is a class with these members (`Learner`); one that adapts
ranks also has `TruncatingLearner`'s. `adarl.train.sac_learner` and `adarl.train.rnac_learner`
are the two there are; adding an on-policy algorithm (PPO, say) is a learner like RNAC's
(docs/algorithms.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Episode:
    """An episode of the seed at position `index` that ended at environment step `step`."""

    index: int
    step: int
    info: dict  # the final step's info: `episode_index` and the episode's `dynamics`
    ret: float
    length: int


@dataclass(frozen=True)
class Advance:
    """What `Learner.advance` did: the step it reached (the end of an update chunk, a rollout
    step, …), the episodes that finished on the way, in the order they finished, and whether
    the learner's truncation is due at that step (`TruncatingLearner.truncate`)."""

    step: int
    episodes: list[Episode] = field(default_factory=list)
    truncation_due: bool = False


@dataclass(frozen=True)
class Truncation:
    """What a rank truncation produced, for the loop to write: each bottleneck's singular values
    per seed (`spectra/step_*.npz`) and the truncations.csv rows."""

    spectra: dict[str, np.ndarray]  # layer -> (n_seeds, width), zero-padded to the full width
    rows: list[dict]


class Learner(Protocol):
    """An algorithm's state and how it acts and learns, driven by the loop."""

    algo: str
    config: object  # the algorithm's config (an `adarl.algos.config.RunConfig`)
    seeds: Sequence[int]
    envs: list  # one environment per seed
    rngs: list[np.random.Generator]  # one NumPy generator per seed
    env_options: dict  # `envs.make` keywords of its environments (evaluation too)
    train_columns: list[str]  # train.csv's columns

    def extra_logs(self, run_dir: Path, resuming: bool) -> dict[str, list[str]]:
        """More CSV logs, file name -> columns (e.g. truncations.csv); `run_dir` only to read an
        existing log's header."""

    def fresh(self) -> None:
        """The initial state; resets the environments."""

    def restore(self, arrays: dict, meta: dict) -> None:
        """The state of a checkpoint."""

    def advance(self, step: int) -> Advance:
        """Act and learn from `step` up to the next step the loop must look at."""

    def train_rows(self, step: int, steps_per_s: float, watch) -> list[dict]:
        """train.csv rows since the last ones (may be empty)."""

    def policies(self) -> list[dict]:
        """Each seed's policy arrays (`adarl.policy`)."""

    def checkpoint_state(self) -> tuple[dict[str, np.ndarray], dict]:
        """Arrays and meta.json entries: everything else needed to continue exactly."""

    def note_divergence(self, watch, step: int) -> None:
        """Tell `watch` of non-finite parameters, optimiser states or metrics."""


class TruncatingLearner(Learner, Protocol):
    """A learner whose `advance` can report `truncation_due` (AdaRL's rank adaptation)."""

    def parameters_finite(self) -> bool:
        """Whether every parameter is finite (the loop checkpoints before a truncation only
        then)."""

    def truncate(self, step: int) -> Truncation:
        """Decompose and cut every bottleneck (and narrow them); return what the loop logs."""
