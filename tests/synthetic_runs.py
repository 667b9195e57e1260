"""Synthetic run folders in the documented layout (docs/run-format.md), a test fixture (tests
import it by name, bench/suites.py by path) that also lets one try the report without training,
from a clone with `tests/` on the path (`PYTHONPATH=tests python`):

    from synthetic_runs import write_run
    write_run("demo", "adarl-hopper", algo="adarl", task="hopper")
    write_run("demo", "sac-hopper", algo="sac", task="hopper", quality=0.8)
    # adarl report demo --out demo-report

Returns, ranks and spectra are made-up but shaped like real logs; the policy files are small
random networks in the `adarl.policy` format (they run in the real environments). Everything in
the run folder is written by the run format's own writers (`adarl.runs`).
"""

from __future__ import annotations

import json
import os
import zlib
from collections.abc import Callable, Sequence
from io import BytesIO
from pathlib import Path

import numpy as np
import pandas as pd

from adarl.algos import registry
from adarl.files import atomic_write_bytes
from adarl.policy import file_arrays, to_bytes
from adarl.runs import checkpoints, folder
from adarl.runs.layout import (
    EPISODES_CSV,
    EVAL_CSV,
    EVALUATIONS_DIR,
    RUN_FORMAT_VERSION,
    SPECTRA_DIR,
    TRAIN_CSV,
    TRUNCATIONS_CSV,
    policy_file_name,
    spectrum_file,
)
from adarl.runs.logs import EVAL_COLUMNS, CsvLog, episode_columns

DIMS = {
    "hopper": (11, 3),
    "walker2d": (17, 6),
    "ant": (105, 8),
    "humanoid": (348, 17),
    "InvertedPendulum-v5": (4, 1),  # a task that is not the paper's (also with a user's XML)
}
PARAMS = {
    "hopper": {"torso_length": 0.4, "foot_length": 0.39},
    "walker2d": {"torso_length": 0.2, "foot_length": 0.1},
    "ant": {"gravity": 14.715, "wind": 1.0},
    "humanoid": {"gravity": 14.715, "wind": 1.0},
    "InvertedPendulum-v5": {"mass_scale": 1.0, "gravity": 9.81},
}
LAYERS = ("actor_1", "q1_1", "q2_1")
TRUNCATION_COLUMNS = ["step", "seed", "layer", "old_rank", "proposed_rank", "new_rank"]
WIDTH = 64
POLICY_HIDDEN = 16


def policy_arrays(
    obs_dim: int, act_dim: int, seed: int = 0, hidden: int = POLICY_HIDDEN, rank: int | None = None
) -> dict[str, np.ndarray]:
    """A random deterministic policy: dense → (bottleneck of `rank` | dense) → tanh head."""
    rng = np.random.default_rng(seed)

    def w(*shape):
        return (rng.standard_normal(shape) / np.sqrt(shape[0])).astype(np.float32)

    dense0 = ("dense", w(obs_dim, hidden), np.zeros(hidden, np.float32))
    mean = (w(hidden, act_dim), np.zeros(act_dim, np.float32))
    if rank is None:
        second = ("dense", w(hidden, hidden), np.zeros(hidden, np.float32))
    else:
        second = ("bottleneck", w(hidden, rank), w(rank, hidden), np.zeros(hidden, np.float32))
    ones = np.ones(act_dim, np.float32)
    return file_arrays([dense0, second], mean, -ones, ones, "relu", n_params_full=rank is not None)


def _rank_path(seed: int, n_truncations: int, rule: str, rng) -> list[int]:
    ranks, r = [WIDTH], WIDTH
    for k in range(n_truncations):
        if rule == "ratio":
            proposed = r if k else int(40 + 4 * rng.random())
        else:
            proposed = int(max(6, round(WIDTH * 0.45 ** (k + 1) + 6 + rng.integers(0, 3))))
        r = max(1, min(r, proposed))
        ranks.append(r)
    return ranks


def write_run(
    root: str | os.PathLike,
    name: str,
    *,
    algo: str = "adarl",
    task: str = "hopper",
    seeds: Sequence[int] = (0, 1, 2),
    total_steps: int = 10_000,
    dynamics: str = "paper",
    quality: float = 1.0,
    rank: int | None = None,
    rank_rule: str = "energy",
    n_evals: int = 5,
    n_truncations: int = 3,
    checkpoint: bool = True,
    done: bool = True,
    extra_config: dict | None = None,
    eval_returns: Callable[[int, int, int], float] | None = None,
    length: int = 1000,
) -> Path:
    """Write a small valid run folder `root/name` and return its path.

    `quality` scales the synthetic returns (final nominal return ≈ 1000·quality per seed, plus
    seed noise), or `eval_returns(step, seed, episode)` gives each nominal evaluation's return
    (episodes of `length` steps); `algo="adarl"` adds truncations, spectra and a shrinking rank;
    `sac-fixed-rank` needs `rank`.
    """
    run = Path(root) / name
    run.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(zlib.crc32(f"{name}/{algo}/{task}".encode()))
    seeds = list(seeds)
    obs_dim, act_dim = DIMS[task]
    adaptive = registry.role(algo, "adapts_rank")
    config = {
        "algo": algo,
        "task": task,
        "dynamics": dynamics,
        "seeds": seeds,
        "total_steps": total_steps,
        "eval_every": total_steps // n_evals,
        "format_version": RUN_FORMAT_VERSION,
        "adarl_version": "0.1.0",
        "command": f"adarl train --algo {algo} --task {task} --seeds {seeds[0]}-{seeds[-1]} "
        f"--total-steps {total_steps} --out {run}",
    }
    if adaptive:
        config["rank_rule"] = rank_rule
    if rank is not None:
        config["rank"] = rank
    config.update(extra_config or {})
    folder.write_config_values(run, config)

    eval_steps = [total_steps * (k + 1) // n_evals for k in range(n_evals)]
    seed_quality = {s: quality * (1.0 + 0.05 * rng.standard_normal()) for s in seeds}
    rows = [
        {"step": step, "seed": s, "dynamics": "nominal", "episode": e,
         "return": 1000.0 * seed_quality[s] * step / total_steps + 10.0 * rng.standard_normal(),
         "length": length}
        for step in eval_steps for s in seeds for e in range(2)
    ]  # fmt: skip
    if eval_returns is not None:
        rows = [{**row, "return": eval_returns(row["step"], row["seed"], row["episode"])}
                for row in rows]  # fmt: skip
    _write_csv(run / EVAL_CSV, EVAL_COLUMNS, rows)

    params = PARAMS[task]
    episodes = [
        {"step": 200 * (i + 1), "seed": s, "episode": i,
         "return": 900.0 * seed_quality[s] * (i + 1) / 50 + 20 * rng.standard_normal(), "length": 200,
         **{f"p_{p}": v for p, v in params.items()}}
        for s in seeds for i in range(min(50, total_steps // 200))
    ]  # fmt: skip
    _write_csv(run / EPISODES_CSV, episode_columns(params), episodes)

    truncation_steps = [total_steps * (k + 1) // (n_truncations + 1) for k in range(n_truncations)]
    rank_paths = {
        (s, layer): _rank_path(s, n_truncations, rank_rule, rng) for s in seeds for layer in LAYERS
    }
    train = []
    for step in range(total_steps // 20, total_steps + 1, total_steps // 20):
        for s in seeds:
            row = {"step": step, "seed": s, "steps_per_s": 500.0, "loss_q": 1.0, "loss_pi": -1.0,
                   "alpha": 0.2, "entropy": -3.0, "q_mean": 50.0, "lr": 3e-3}  # fmt: skip
            if adaptive:
                k = sum(step >= t for t in truncation_steps)
                row.update({f"rank_{layer}": rank_paths[(s, layer)][k] for layer in LAYERS})
            elif rank is not None:
                row.update({f"rank_{layer}": rank for layer in LAYERS})
            train.append(row)
    _write_csv(run / TRAIN_CSV, list(train[0]), train)

    if adaptive:
        trunc = [
            {"step": t, "seed": s, "layer": layer, "old_rank": rank_paths[(s, layer)][k],
             "proposed_rank": rank_paths[(s, layer)][k + 1], "new_rank": rank_paths[(s, layer)][k + 1]}
            for k, t in enumerate(truncation_steps) for s in seeds for layer in LAYERS
        ]  # fmt: skip
        _write_csv(run / TRUNCATIONS_CSV, TRUNCATION_COLUMNS, trunc)
        for k, t in enumerate(truncation_steps):
            decay = np.exp(-np.arange(WIDTH) / (8.0 / (k + 1)))
            layers = {
                layer: np.stack([decay * (1 + 0.1 * rng.random()) for _ in seeds])
                for layer in LAYERS
            }
            buf = BytesIO()
            np.savez(buf, seeds=np.array(seeds), **layers)
            atomic_write_bytes(run / SPECTRA_DIR / spectrum_file(t), buf.getvalue())

    if checkpoint:
        policies = {}
        for s in seeds:
            policy_rank = (
                rank if rank is not None else (rank_paths[(s, "actor_1")][-1] if adaptive else None)
            )
            if policy_rank is not None:
                policy_rank = min(policy_rank, POLICY_HIDDEN)
            arrays = policy_arrays(obs_dim, act_dim, s, rank=policy_rank)
            policies[policy_file_name(s)] = to_bytes(arrays)
        arrays = {"step": np.array(total_steps)}
        checkpoints.save_checkpoint(run, total_steps, arrays, {}, files=policies)
    if done:
        folder.finish(run, total_steps)
    return run


def _write_csv(path: Path, columns: list[str], rows: list[dict]) -> None:
    path.unlink(missing_ok=True)  # CsvLog appends to a log it finds
    log = CsvLog(path, columns)
    log.write(rows)
    log.close()


def write_sweep(
    run: str | os.PathLike,
    parameter: str,
    values: Sequence[float],
    *,
    hold: dict[str, float] | None = None,
    quality: float = 1.0,
    episodes: int = 2,
    returns: Callable[[float, int, int], float] | None = None,
) -> Path:
    """Write an `adarl evaluate --sweep` style result (CSV + JSON sidecar) into `run`; the
    returns are a bump around the parameter's default, or `returns(value, seed, episode)`."""
    from adarl.evaluation import grid

    run = Path(run)
    config = folder.load_config(run)
    seeds, step, task = config["seeds"], config["total_steps"], config["task"]
    hold = dict(hold or {})
    centre = PARAMS[task].get(parameter, float(np.mean(values)))
    rng = np.random.default_rng(len(values))
    rows = []
    for v in values:
        point = {parameter: float(v), **hold}
        label = grid.point_label("nominal", point)
        for s in seeds:
            for e in range(episodes):
                ret = (
                    1000 * quality * np.exp(-(((v - centre) / (0.5 * centre + 1e-9)) ** 2))
                    + 5 * rng.standard_normal()
                )
                ret = ret if returns is None else returns(float(v), s, e)
                rows.append({"step": step, "seed": s, "dynamics": label, "episode": e, "return": ret,
                             "length": 1000, **{f"p_{k}": val for k, val in point.items()}})  # fmt: skip
    axis = grid.Axis(parameter, tuple(float(v) for v in values), f"{parameter}=…")
    name = grid.evaluation_name("nominal", [axis], list(hold.items()))
    evaluations = run / EVALUATIONS_DIR
    evaluations.mkdir(exist_ok=True)
    pd.DataFrame(rows).to_csv(evaluations / f"{name}.csv", index=False)
    meta = {"name": name, "task": task, "dynamics": "nominal", "sweep": {parameter: list(axis.values)},
            "hold": hold, "episodes": episodes, "checkpoint_step": step, "final_checkpoint": True,
            "command": f"adarl evaluate {run} --sweep {parameter}=…"}  # fmt: skip
    (evaluations / f"{name}.json").write_text(json.dumps(meta))
    return evaluations / f"{name}.csv"
