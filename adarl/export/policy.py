"""`adarl export`: copy one seed's deterministic policy out of a run as a plain NumPy file.

The file is the `adarl.policy` format that every trainer writes next to each checkpoint, so
exporting is a checked copy: it runs with `adarl.policy.load(path)(obs)` and NumPy alone.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from adarl.errors import UsageError
from adarl.files import atomic_write_bytes, check_writable_file
from adarl.policy import NumpyPolicy, load
from adarl.results.runs import Run
from adarl.runs.checkpoints import policy_file
from adarl.runs.folder import check_run_output
from adarl.runs.layout import checkpoint_step


@dataclass(frozen=True)
class Exported:
    source: Path
    out: Path
    step: int
    obs_dim: int
    act_dim: int
    n_params: int
    n_params_full: int

    @property
    def kept(self) -> float:
        """Fraction of the full-rank parameter count the exported policy keeps."""
        return self.n_params / self.n_params_full if self.n_params_full else 1.0


def policy_dims(policy: NumpyPolicy) -> tuple[int, int]:
    """(observation size, action size) of a policy file."""
    a = policy.arrays
    if policy.n_layers == 0:
        first = a["mean_w"]
    else:
        kind = str(a["l0_kind"])
        first = {"dense": a.get("l0_w"), "bottleneck": a.get("l0_w1"), "sparse": a.get("l0_d")}[
            kind
        ]
    return int(first.shape[0]), int(a["mean_w"].shape[1])


def export_policy(
    run: Run, seed: int, out: str | os.PathLike, checkpoint: int | None = None
) -> Exported:
    """Copy seed `seed`'s policy at the final (or chosen) checkpoint to `out` (atomically)."""
    out = Path(out)
    if out.is_dir():
        raise UsageError(f"--out {out} is a folder; give a file name such as policy.npz")
    check_run_output(out)
    check_writable_file(out)
    source = policy_file(run.path, seed, checkpoint)
    policy = load(source)  # a damaged file: a one-line UsageError naming it
    atomic_write_bytes(out, source.read_bytes())
    n = policy.n_params()
    obs_dim, act_dim = policy_dims(policy)
    return Exported(
        source=source,
        out=out,
        step=checkpoint_step(source.parent),
        obs_dim=obs_dim,
        act_dim=act_dim,
        n_params=n,
        n_params_full=policy.n_params_full(),
    )
