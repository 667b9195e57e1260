"""`adarl evaluate RUN_DIR…`: run deterministic episodes of every seed's saved policy under
nominal, fixed or swept dynamics, and store them as `RUN_DIR/evaluations/<name>.csv`.

    adarl evaluate runs/hopper-adarl                                  # nominal, 10 episodes
    adarl evaluate runs/hopper-adarl --sweep torso_length=0.2..0.6:9 --hold foot_length=0.39
    adarl evaluate sweep-out/ --dynamics fixed:torso_length=0.5 --episodes 20
    adarl evaluate runs/ --suite m2td3-3d                             # a named robustness suite
    adarl evaluate runs/halfcheetah --sweep body:torso.mass=4..9:6    # an element of any model

See docs/evaluation.md.
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from adarl.cli.common import add_checkpoint_argument, add_env_module_argument, name_env_modules
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
        "sweep:P=LO..HI[:N],Q=V (sweep P, hold Q)",
    )
    parser.add_argument(
        "--sweep", action="append", default=[], metavar="P=LO..HI[:N]",
        help="sweep parameter P over N evenly spaced values from LO to HI (default N 9; "
        "P=LO:HI:N is the same, P=V1,V2,… lists them); repeat for a grid. "
        "P: a task parameter (adarl tasks TASK) or KIND:NAME.ATTR[i], e.g. body:torso.mass",
    )  # fmt: skip
    parser.add_argument(
        "--hold",
        action="append",
        default=[],
        metavar="P=V",
        help="hold parameter P at V (one value; a range is --sweep's)",
    )
    parser.add_argument(
        "--suite", default=None, metavar="NAME",
        help="a named robustness suite (m2td3-1d/2d/3d; rrls-1d/2d/3d, also on HalfCheetah-v5, "
        "InvertedPendulum-v5, HumanoidStandup-v5; paper; docs/evaluation.md): "
        "its grid, base dynamics and episodes; reports worst-case and average return",
    )  # fmt: skip
    parser.add_argument(
        "--episodes", type=int, default=None,
        help="episodes per seed and point (default 10, or the suite's)",
    )  # fmt: skip
    parser.add_argument(
        "--points", type=int, default=None, metavar="N",
        help="--suite only: N grid points per dimension instead of the suite's (a coarser grid "
        "over the same ranges, for a quicker look)",
    )  # fmt: skip
    add_checkpoint_argument(parser)
    add_env_module_argument(parser)
    parser.add_argument(
        "--workers", type=int, default=None, help="worker processes (default: all cores)"
    )
    parser.add_argument(
        "--backend", choices=("local", "ray"), default="local",
        help="--suite only: local process pool (default) or Ray",
    )  # fmt: skip
    parser.add_argument(
        "--address", default=None, metavar="HOST:PORT", help="--backend ray: a Ray cluster"
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
    if args.suite is not None:
        parts += ["--suite", args.suite]
    if args.dynamics != "nominal":
        parts += ["--dynamics", args.dynamics]
    for s in args.sweep:
        parts += ["--sweep", s]
    for h in args.hold:
        parts += ["--hold", h]
    if args.episodes is not None or args.suite is None:
        parts += ["--episodes", str(10 if args.episodes is None else args.episodes)]
    if getattr(args, "points", None) is not None:
        parts += ["--points", str(args.points)]
    if args.checkpoint is not None:
        parts += ["--checkpoint", str(args.checkpoint)]
    if args.eval_seed != EVAL_SEED:
        parts += ["--eval-seed", str(args.eval_seed)]
    if args.max_episode_steps is not None:
        parts += ["--max-episode-steps", str(args.max_episode_steps)]
    if args.out:
        parts += ["--out", args.out]
    for module in getattr(args, "env_module", []):
        parts += ["--env-module", module]
    return shlex.join(parts)


def run(args: argparse.Namespace) -> int:
    from adarl.evaluation.evaluate import (
        EvalSpec,
        check_not_smaller,
        default_output,
        plan,
        summarise,
        write_evaluation,
    )
    from adarl.evaluation.evaluate import tables as evaluate_tables
    from adarl.files import check_writable_file
    from adarl.results.runs import find_runs
    from adarl.runs.folder import check_run_output
    from adarl.runs.layout import evaluation_sidecar

    name_env_modules(args)
    if args.suite is not None:
        return run_suite_command(args)
    if args.backend != "local" or args.address:
        raise UsageError("--backend and --address apply to --suite evaluations; add --suite NAME")
    if args.points is not None:
        raise UsageError("--points applies to --suite evaluations; add --suite NAME")
    if args.episodes is None:
        args.episodes = 10
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
    units = plan(runs, spec)  # every check, before evaluating, which takes long
    for index, run_ in enumerate(runs):
        path = Path(args.out) if args.out else default_output(run_, spec)
        check_run_output(path)  # before the probe: no link of a run folder is written through
        check_writable_file(path)
        check_writable_file(evaluation_sidecar(path), "--out's JSON sidecar")
        check_not_smaller(path, sum(u.episodes for u in units if u.run_index == index))
    command = command_line(args)
    tables = evaluate_tables(runs, units, workers=args.workers)
    for run_, table in zip(runs, tables):
        path = Path(args.out) if args.out else default_output(run_, spec)
        write_evaluation(table, path, spec, run_, command)
        print(f"{run_.path} ({run_.task}, {run_.label}): {len(table)} episodes -> {path}")
        for row in summarise(table).itertuples():
            std = "" if row.seeds < 2 else f" ± {row.std:.1f}"
            print(f"  {row.dynamics}: {row.mean:.1f}{std} over {row.seeds} seed(s)")
    return 0


def run_suite_command(args: argparse.Namespace) -> int:
    """`adarl evaluate RUN… --suite NAME`: check everything, evaluate the grid, write per run."""
    import pandas as pd

    from adarl.evaluation import suites
    from adarl.evaluation.evaluate import check_not_smaller
    from adarl.evaluation.evaluate import tables as evaluate_tables
    from adarl.files import check_writable_file
    from adarl.results.runs import find_runs
    from adarl.runs.folder import check_run_output
    from adarl.runs.layout import EVALUATIONS_DIR, evaluation_sidecar

    mixed = [
        flag
        for flag, given in (
            ("--sweep", args.sweep),
            ("--hold", args.hold),
            ("--dynamics", args.dynamics != "nominal"),
            ("--out", args.out),
        )
        if given
    ]
    if mixed:
        raise UsageError(
            f"--suite {args.suite} fixes the grid and the output; allowed: --suite without "
            f"{', '.join(mixed)}"
        )
    if args.suite not in suites.SUITES:  # before looking at any run folder
        suites.get_suite(args.suite, "")
    if args.points is not None and args.points < 2:
        raise UsageError(f"--points must be ≥ 2, got {args.points}")
    if args.episodes is not None and args.episodes < 1:
        raise UsageError(f"--episodes must be ≥ 1, got {args.episodes}")
    if args.max_episode_steps is not None and args.max_episode_steps < 1:
        raise UsageError(f"--max-episode-steps must be ≥ 1, got {args.max_episode_steps}")
    runs = find_runs(args.run_dirs)
    options = dict(
        checkpoint=args.checkpoint, eval_seed=args.eval_seed, max_steps=args.max_episode_steps
    )
    units = suites.plan_suite(runs, args.suite, args.episodes, args.points, **options)  # checks
    stem = suites.file_name(args.suite, args.checkpoint)
    for index, run_ in enumerate(runs):
        episodes_path = run_.path / EVALUATIONS_DIR / f"{stem}.csv"
        check_run_output(run_.path)
        check_writable_file(episodes_path)
        check_writable_file(evaluation_sidecar(episodes_path), "the suite's JSON sidecar")
        check_writable_file(suites.summary_path(run_, args.suite, args.checkpoint))
        check_not_smaller(episodes_path, sum(u.episodes for u in units if u.run_index == index))
    tables = evaluate_tables(  # the units planned above: `suites.run_suite` would plan again
        runs, units, args.workers, args.backend, args.address, not args.no_progress,
        desc=f"suite {args.suite}",
    )  # fmt: skip
    command = command_line(args)
    for run_, table in zip(runs, tables):
        _, summary_path = suites.write_suite(
            table, run_, args.suite, args.episodes, command=command, points=args.points, **options
        )
        summary = pd.read_csv(summary_path)
        print(f"{run_.path} ({run_.task}, {run_.label}): suite {args.suite} -> {summary_path}")
        print(f"  {suites.format_summary(summary)}")
    return 0
