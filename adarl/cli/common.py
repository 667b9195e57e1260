"""Arguments shared by several commands, defined once."""

from __future__ import annotations

import argparse


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags every command takes (`adarl.cli.main` adds them to each)."""
    parser.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bars or periodic progress lines",
    )


def add_checkpoint_argument(parser: argparse.ArgumentParser) -> None:
    """`--checkpoint STEP` of the commands that read a run's policies (evaluate, play, export)."""
    parser.add_argument(
        "--checkpoint",
        type=int,
        default=None,
        metavar="STEP",
        help="checkpoint step (default: final)",
    )


def add_env_module_argument(parser: argparse.ArgumentParser) -> None:
    """`--env-module PKG` of the commands that read runs (evaluate, report, play) or a sweep
    file: the modules adarl may import, which a run or a file alone never makes it import."""
    parser.add_argument(
        "--env-module", action="append", default=[], metavar="PKG",
        help="import PKG (found as python -m finds it) where a run or file names it: the "
        "module that registers a Gymnasium id of yours; adarl imports none you do not name "
        "(repeat for several)",
    )  # fmt: skip


def name_env_modules(args: argparse.Namespace) -> None:
    """Let adarl import the modules `--env-module` names (`adarl.envs.tasks.name_env_module`)."""
    from adarl.envs.tasks import name_env_module

    name_env_module(*args.env_module)
