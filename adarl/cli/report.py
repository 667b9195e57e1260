"""`adarl report RUN_DIR… --out REPORT_DIR`: tables, statistics and figures for any set of run
folders (several algorithms, tasks, seeds; a sweep's output folder works as it is).

See docs/evaluation.md for what each table and figure shows.
"""

from __future__ import annotations

import argparse
import shlex

from adarl.cli.common import add_env_module_argument, name_env_modules

HELP = "write tables, rliable statistics and figures for a set of runs into one report folder"
DESCRIPTION = (
    "Write tables, statistics and figures for a set of runs into one report folder. A seed's "
    "score is the mean of its last --last-k evaluations (the final checkpoint's is shown "
    "beside it). Per-task means and differences get Student-t (Welch) intervals and exact "
    "permutation p-values; every comparison also gives the smallest difference a two-sided "
    "t-test detects with 80% power at the seeds at hand and the seeds per arm a 300-point "
    "difference would need. Aggregates over tasks and seeds (IQM, probability of improvement, "
    "profiles) use rliable's stratified bootstrap. See docs/evaluation.md."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "run_dirs", nargs="+", metavar="RUN_DIR",
        help="run folders, or folders holding them; or earlier reports (or their "
        "tables/scores.csv) to recompute Table 1 and the statistics from their per-seed scores",
    )  # fmt: skip
    parser.add_argument("--out", required=True, metavar="REPORT_DIR", help="report folder")
    parser.add_argument(
        "--bootstrap-reps", type=int, default=10_000, help="bootstrap resamples (default 10000)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the bootstrap (default 0)")
    parser.add_argument(
        "--skip-incomplete", action="store_true",
        help="leave out runs without a complete checkpoint instead of failing",
    )  # fmt: skip
    parser.add_argument(
        "--best-checkpoint", default="final", metavar="final|best",
        help="score the algorithms that keep a best policy (RNAC) at their final checkpoint "
        "(default), or at their best by evaluation, as RNAC's original reports",
    )  # fmt: skip
    parser.add_argument(
        "--contrast", action="append", default=[], metavar="FIELD[=REFERENCE]",
        help="also tabulate each value of a config field minus REFERENCE (default: the first "
        "value in sorted order) among runs equal in all else, with Welch t intervals, exact "
        "permutation p-values and power; repeatable",
    )  # fmt: skip
    add_env_module_argument(parser)
    parser.add_argument(
        "--last-k", type=int, default=5, metavar="K",
        help="a seed's score: the mean of its last K evaluations logged during training "
        "(eval.csv, nominal dynamics; each the mean of its episodes); fewer if it has fewer. "
        "The final checkpoint's score is shown beside it (default 5)",
    )  # fmt: skip


def command_line(args: argparse.Namespace) -> str:
    parts = ["adarl", "report", *args.run_dirs, "--out", args.out]
    if args.bootstrap_reps != 10_000:
        parts += ["--bootstrap-reps", str(args.bootstrap_reps)]
    if args.seed:
        parts += ["--seed", str(args.seed)]
    if args.skip_incomplete:
        parts.append("--skip-incomplete")
    if args.best_checkpoint != "final":
        parts += ["--best-checkpoint", args.best_checkpoint]
    for contrast in args.contrast:
        parts += ["--contrast", contrast]
    if args.last_k != 5:
        parts += ["--last-k", str(args.last_k)]
    for module in args.env_module:
        parts += ["--env-module", module]
    return shlex.join(parts)


def run(args: argparse.Namespace) -> int:
    from adarl.files import check_writable_dir
    from adarl.report.build import build_report
    from adarl.report.common import ReportOptions
    from adarl.runs.folder import check_run_output

    name_env_modules(args)
    check_run_output(args.out)  # a report into a run folder: never through a link there
    check_writable_dir(args.out)  # before reading any run
    options = ReportOptions(
        bootstrap_reps=args.bootstrap_reps,
        seed=args.seed,
        skip_incomplete=args.skip_incomplete,
        command=command_line(args),
        best_checkpoint=args.best_checkpoint,
        contrasts=tuple(args.contrast),
        last_k=args.last_k,
    )
    out = build_report(args.run_dirs, args.out, options)
    print(f"report written to {out}/index.md")
    return 0
