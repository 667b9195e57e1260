"""The one evaluation engine: running evaluation units (one seed's policy at one grid point,
`adarl.evaluation.evaluate.Unit`) in parallel, with a progress bar, on adarl's executor
(`adarl.executor`: a pool of spawned local processes, or Ray). `adarl evaluate` and `adarl
evaluate --suite` both run through it. Results come back in the order of the units whatever the
backend and the number of workers, so the files written do not depend on them; policies are
NumPy files, so a worker never imports JAX.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from adarl import executor
from adarl.runtime import available_cores


def run_unit(unit) -> list[dict]:
    """Run one unit's episodes; rows carry `step, seed, dynamics` in front and a column per
    physical parameter (`layout.param_column`) at the end."""
    from adarl.envs.rollout import run_episodes
    from adarl.envs.tasks import name_env_module
    from adarl.policy import load
    from adarl.runs import layout

    # a unit's env-module was named where it was planned (`evaluate.run_env_options`): this
    # process may be a fresh worker that knows only the unit
    name_env_module(dict(unit.env).get("env_module", ""))
    policy = load(unit.policy_path)
    rows = run_episodes(
        policy,
        unit.task,
        unit.dynamics,
        unit.episodes,
        unit.eval_seed,
        max_steps=unit.max_steps,
        **dict(unit.point),
        **dict(unit.env),
    )
    head = {"step": unit.step, "seed": unit.seed, "dynamics": unit.label}
    out = []
    for row in rows:
        params = {layout.param_column(n): v for n, v in row.pop("params").items()}
        out.append({**head, **row, **params})
    return out


def run_units(
    units: Sequence,
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    progress: bool = True,
    desc: str = "evaluate",
) -> list[list[dict]]:
    """Each unit's episode rows (`run_unit`), in the order of `units`.

    `backend`: `local` (a `spawn` process pool of `workers`, default all cores; one worker runs
    in this process) or `ray` (one Ray task per unit, on a local Ray instance of `workers` CPUs
    or on the cluster at `address`)."""
    workers = available_cores() if workers is None else workers
    if backend == "local" and workers >= 1:
        workers = min(workers, max(len(units), 1))
    with executor.start(backend, workers, address) as pool:
        bar = _progress(len(units), desc, progress)
        try:
            return executor.run_in_order(pool, run_unit, units, lambda: _tick(bar))
        finally:
            if bar is not None:
                bar.close()


def _progress(total: int, desc: str, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="unit", dynamic_ncols=True, file=sys.stderr)


def _tick(bar) -> None:
    if bar is not None:
        bar.update()
