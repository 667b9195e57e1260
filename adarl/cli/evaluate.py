"""`adarl evaluate RUN_DIR…`: run deterministic episodes of every seed's saved policy under
nominal, fixed or swept dynamics, and store them as `RUN_DIR/evaluations/<name>.csv`.

    adarl evaluate runs/hopper-adarl                                  # nominal, 10 episodes
    adarl evaluate runs/hopper-adarl --sweep torso_length=0.2:0.6:9 --hold foot_length=0.39
    adarl evaluate sweep-out/ --dynamics fixed:torso_length=0.5 --episodes 20

See docs/evaluation.md.
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from adarl.cli.common import add_checkpoint_argument
from adarl.errors import UsageError

HELP = "evaluate every seed of a run under nominal, fixed or swept dynamics (CSV per run)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from adarl.evaluation.evaluate import EVAL_SEED

    parser.add_argument(
        "run_dirs", nargs="+", metavar="RUN_DIR", help="a run folder, or a folder of run folders"
    )
    parser.add_argument(
        "--dynamics",
        default="nominal",
        help="base dynamics: nominal (default), default, paper, fixed:P=V,…, or "
        "sweep:P=LO:HI:N,Q=V (sweep P, hold Q)",
    )
    parser.add_argument(
        "--sweep", action="append", default=[], metavar="P=LO:HI:N",
        help="sweep parameter P over N evenly spaced values (or P=V1,V2,…); repeat for a grid",
    )  # fmt: skip
    parser.add_argument(
        "--hold", action="append", default=[], metavar="P=V", help="hold parameter P at V"
    )
    parser.add_argument("--episodes", type=int, default=10, help="episodes per seed and point")
    add_checkpoint_argument(parser)
    parser.add_argument(
        "--workers", type=int, default=None, help="worker processes (default: all cores)"
    )
    parser.add_argument(
        "--out", default=None, metavar="CSV",
        help="output CSV (one run only; default RUN_DIR/evaluations/<name>.csv)",
    )  # fmt: skip
    parser.add_argument(
        "--eval-seed", type=int, default=EVAL_SEED,
        help=f"environment seed; episode k resets with seed+k (default {EVAL_SEED})",
    )  # fmt: skip
    parser.add_argument(
        "--max-episode-steps", type=int, default=None, help="cut episodes after this many steps"
    )


def command_line(args: argparse.Namespace) -> str:
    """The command, as a user would type it, that reproduces `args`."""
    from adarl.evaluation.evaluate import EVAL_SEED

    parts = ["adarl", "evaluate", *args.run_dirs]
    if args.dynamics != "nominal":
        parts += ["--dynamics", args.dynamics]
    for s in args.sweep:
        parts += ["--sweep", s]
    for h in args.hold:
        parts += ["--hold", h]
    parts += ["--episodes", str(args.episodes)]
    if args.checkpoint is not None:
        parts += ["--checkpoint", str(args.checkpoint)]
    if args.eval_seed != EVAL_SEED:
        parts += ["--eval-seed", str(args.eval_seed)]
    if args.max_episode_steps is not None:
        parts += ["--max-episode-steps", str(args.max_episode_steps)]
    if args.out:
        parts += ["--out", args.out]
    return shlex.join(parts)


def run(args: argparse.Namespace) -> int:
    from adarl.evaluation.evaluate import (
        EvalSpec,
        default_output,
        evaluate_runs,
        summarise,
        write_evaluation,
    )
    from adarl.evaluation.runs import find_runs
    from adarl.train.io import check_writable_file

    spec = EvalSpec.from_options(
        args.dynamics,
        args.sweep,
        args.hold,
        episodes=args.episodes,
        checkpoint=args.checkpoint,
        eval_seed=args.eval_seed,
        max_steps=args.max_episode_steps,
    )
    runs = find_runs(args.run_dirs)
    if args.out is not None:
        if len(runs) > 1:
            raise UsageError(f"--out names one CSV but {len(runs)} runs were found; leave it out")
        if Path(args.out).is_dir():
            raise UsageError(f"--out {args.out} is a folder; give a .csv file name")
    for run_ in runs:  # before evaluating, which takes long
        check_writable_file(Path(args.out) if args.out else default_output(run_, spec))
    command = command_line(args)
    tables = evaluate_runs(runs, spec, workers=args.workers)
    for run_, table in zip(runs, tables):
        path = Path(args.out) if args.out else default_output(run_, spec)
        write_evaluation(table, path, spec, run_, command)
        print(f"{run_.path} ({run_.task}, {run_.label}): {len(table)} episodes -> {path}")
        for row in summarise(table).itertuples():
            std = "" if row.seeds < 2 else f" ± {row.std:.1f}"
            print(f"  {row.dynamics}: {row.mean:.1f}{std} over {row.seeds} seed(s)")
    return 0
