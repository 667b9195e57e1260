"""`adarl sweep SWEEP.yaml|PRESET`: tasks × algorithms × seed groups in one command, on a local
process pool or a Ray cluster; re-running the same command resumes it. See docs/sweeps.md."""

from __future__ import annotations

import argparse
import os
import shlex
import textwrap
from pathlib import Path

from adarl.cli.common import add_env_module_argument, name_env_modules
from adarl.errors import UsageError

HELP = "run a sweep (tasks x algorithms x seeds) from a YAML file or preset, locally or on Ray"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from adarl.sweeps.spec import list_presets

    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    presets = textwrap.fill(
        "presets: " + ", ".join(list_presets()), 78, subsequent_indent="  ", break_on_hyphens=False
    )
    parser.epilog = (
        f"{presets}\n"
        "examples:\n"
        "  adarl sweep smoke --dry-run\n"
        "  adarl sweep paper-hopper-small                 # again after a crash: resumes\n"
        "  adarl sweep my-sweep.yaml --out sweeps/mine --workers 2\n"
        "  adarl sweep paper-table1 --backend ray --address HEAD:6379\n"
        "then: adarl report SWEEP_DIR --out REPORT_DIR"
    )
    parser.add_argument("spec", metavar="SWEEP.yaml|PRESET", help="a sweep file or a preset name")
    parser.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="sweep folder (default sweeps/<name>); re-running resumes it",
    )
    parser.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="local process pool (default) or Ray",
    )
    parser.add_argument(
        "--address",
        default=None,
        metavar="ADDR",
        help="Ray cluster (HOST:PORT, ray://HOST:PORT or auto); "
        "default: start a local Ray instance",
    )
    parser.add_argument(
        "--workers",
        type=_positive,
        default=None,
        metavar="N",
        help="units trained at once (default: cores / cpus_per_unit)",
    )
    parser.add_argument(
        "--max-retries",
        type=_non_negative,
        default=2,
        metavar="K",
        help="retries of a crashed unit per invocation (default 2)",
    )
    parser.add_argument(
        "--progress-every",
        type=float,
        default=60.0,
        metavar="SECONDS",
        help="seconds between progress lines of running units (default 60)",
    )
    parser.add_argument(
        "--track",
        action="store_true",
        help="every unit mirrors its TensorBoard scalars and config to Weights & Biases, "
        "grouped by the sweep's name (pip install 'adarl[track]')",
    )
    parser.add_argument("--wandb-project", default=None, help="W&B project (default adarl)")
    parser.add_argument("--wandb-entity", default=None, help="W&B entity (team or user)")
    parser.add_argument(
        "--dry-run",
        action="store_true",
        help="check the file and list the units and what each would do; run nothing (and "
        "import no env-module the file names unless --env-module names it)",
    )
    add_env_module_argument(parser)


def _positive(text: str) -> int:
    value = _int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expects an integer ≥ 1, got {text!r}")
    return value


def _non_negative(text: str) -> int:
    value = _int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expects an integer ≥ 0, got {text!r}")
    return value


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects an integer, got {text!r}") from None


def command_line(args: argparse.Namespace, out: Path) -> str:
    """The command that resumes this sweep (what the manifest records)."""
    parts = ["adarl", "sweep", args.spec, "--out", str(out), "--backend", args.backend]
    if args.address:
        parts += ["--address", args.address]
    if args.workers:
        parts += ["--workers", str(args.workers)]
    if args.track:
        parts.append("--track")
    for name in ("wandb_project", "wandb_entity"):
        if getattr(args, name):
            parts += [f"--{name.replace('_', '-')}", getattr(args, name)]
    return shlex.join([*parts, "--max-retries", str(args.max_retries)])


def tracking_env(environ) -> dict[str, str]:
    """The W&B settings of this shell (WANDB_MODE, WANDB_DIR, ...) for the units, which may run
    on other nodes; not WANDB_API_KEY, which would travel in every Ray task's arguments: log in
    on each node instead."""
    return {k: v for k, v in environ.items() if k.startswith("WANDB_") and k != "WANDB_API_KEY"}


def tracking_flags(args: argparse.Namespace, sweep_name: str) -> tuple[str, ...]:
    """The `adarl train` flags that mirror every unit to W&B (none without --track); a one-line
    UsageError if wandb is missing or a --wandb-* flag comes without --track."""
    from adarl.runs import tracking

    given = [n for n in ("wandb_project", "wandb_entity") if getattr(args, n) is not None]
    if not args.track:
        if given:
            raise UsageError(f"--{given[0].replace('_', '-')} is for --track")
        return ()
    tracking.import_wandb()
    flags = ["--track", "--wandb-group", sweep_name]
    for name in given:
        flags += [f"--{name.replace('_', '-')}", getattr(args, name)]
    return tuple(flags)


def run(args: argparse.Namespace) -> int:
    from adarl.executor import default_workers
    from adarl.files import check_writable_dir
    from adarl.sweeps import spec

    if not args.progress_every > 0:  # NaN too; inf: never
        raise UsageError(f"--progress-every must be seconds > 0, got {args.progress_every:g}")
    if args.address and args.backend != "ray":  # as `adarl evaluate --suite`
        raise UsageError(
            f"--address is for --backend ray, got --address {args.address} with --backend "
            f"{args.backend}; allowed: --backend ray --address HOST:PORT, or no --address"
        )
    name_env_modules(args)
    sweep = spec.load(args.spec, run=not args.dry_run)  # a dry run imports only what you name
    from adarl.sweeps import manifest, runner  # after the spec: a bad name answers at once
    from adarl.sweeps.job import start_executor

    out = Path(args.out) if args.out else Path("sweeps") / sweep.name
    check_writable_dir(out)  # a dry run too: it promises what a real one would do
    runner.check_not_a_run_folder(out)
    manifest.check_compatible(manifest.read(out), sweep, out)
    runner.check_existing_runs(sweep, out)
    train_extra = tracking_flags(args, sweep.name)
    if args.dry_run:
        where = (
            f"Ray ({args.address or 'a local instance'})"
            if args.backend == "ray"
            else f"{args.workers or default_workers(sweep.cpus_per_unit)} local workers"
        )
        print(runner.plan_text(sweep, out, where))
        print(_estimate_line(sweep, out, args, None))
        return 0
    options = runner.Options(
        max_retries=args.max_retries,
        progress_every=float("inf") if args.no_progress else args.progress_every,
        command=command_line(args, out),
        train_extra=train_extra,
        train_env=tracking_env(os.environ) if train_extra else {},
    )
    with start_executor(args.backend, args.address, args.workers, sweep.cpus_per_unit) as pool:
        print(_estimate_line(sweep, out, args, pool.slots), flush=True)
        return runner.run_sweep(sweep, out, pool, options)


def _estimate_line(sweep, out: Path, args: argparse.Namespace, slots: int | None) -> str:
    """The estimated wall time, for the backend's slots (`None`: a dry run, which starts none)."""
    from adarl.executor import default_workers
    from adarl.sweeps import estimate

    cores = default_workers(1)
    cluster = args.backend == "ray" and args.address
    if slots is None:
        slots = args.workers or default_workers(sweep.cpus_per_unit)
    where = "on this machine"
    if cluster:
        where = (
            "if run on this machine (a cluster's CPUs are known once it is joined)"
            if args.dry_run
            else "on the cluster, if its CPUs are as fast as this machine's"
        )
    found = estimate.for_sweep(sweep, out, slots, None if cluster and not args.dry_run else cores)
    return estimate.describe(found, where)
