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
