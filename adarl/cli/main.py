"""`adarl` entry point.

Each command is a module in `adarl.cli` exposing `HELP` (one line; `DESCRIPTION`, if any, for its
`--help`), `add_arguments(parser)` and `run(args) -> int`. The modules import only the standard
library and light adarl modules at their top; JAX, MuJoCo, Gymnasium, pandas and matplotlib are
imported inside `run` (or `add_arguments`) where a command needs them, and `main` adds the
arguments of the one command it was given only, so `adarl --version`, `--help` and usage errors
answer in well under a second (tests/cli/test_startup.py).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterable

from adarl import __version__
from adarl.cli import evaluate, export, play, ranks, report, sweep, tasks, theory, train
from adarl.cli.common import add_common_arguments
from adarl.errors import REPORTED, failure
from adarl.runtime import check_process_environment, configure_xla

COMMANDS = {
    "train": train,
    "tasks": tasks,
    "ranks": ranks,
    "evaluate": evaluate,
    "report": report,
    "play": play,
    "export": export,
    "sweep": sweep,
    "theory": theory,
}


class OneLineParser(argparse.ArgumentParser):
    """argparse parser whose errors are a single line on stderr and exit code 2."""

    def error(self, message):  # noqa: D102
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser(commands: Iterable[str] | None = None) -> argparse.ArgumentParser:
    """The `adarl` parser, with the arguments of `commands` (default: every command); the others
    are listed by name and help line only (their `add_arguments` may import more)."""
    filled = set(COMMANDS) if commands is None else set(commands)
    parser = OneLineParser(
        prog="adarl",
        description="AdaRL: rank-adaptive SAC for robust RL under model uncertainty.",
    )
    parser.add_argument("--version", action="version", version=f"adarl {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    for name, module in COMMANDS.items():
        description = getattr(module, "DESCRIPTION", module.HELP)
        # conflicts resolve: a command may bring its own --help (adarl train --algo X --help)
        p = sub.add_parser(
            name, help=module.HELP, description=description, conflict_handler="resolve"
        )
        if name in filled:
            module.add_arguments(p)
            add_common_arguments(p)
            p.set_defaults(_run=module.run)
    return parser


def _command_in(argv: list[str]) -> str | None:
    """The command `argv` names: its first word that is not an option (`adarl` itself takes no
    option with a value), if it is a command."""
    word = next((a for a in argv if not a.startswith("-")), None)
    return word if word in COMMANDS else None


def main(argv: list[str] | None = None) -> int:
    # One XLA thread per computation and one CPU device per core (override by setting XLA_FLAGS
    # yourself): see adarl.runtime.
    configure_xla()
    # Reuse compiled updates across runs (a fresh compile of the SAC update takes 5-20 s).
    os.environ.setdefault(
        "JAX_COMPILATION_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "adarl", "jax")
    )
    argv = sys.argv[1:] if argv is None else list(argv)
    named = _command_in(argv)
    parser = build_parser([named] if named else [])
    args = parser.parse_args(argv)
    if getattr(args, "command", None) and args.command != named:  # not the word we guessed
        parser = build_parser()
        args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    try:
        check_process_environment(args.command)  # MUJOCO_GL, JAX_PLATFORMS, XLA_FLAGS
        return int(args._run(args) or 0)
    except REPORTED as exc:
        code, message = failure(f"adarl {args.command}", exc)
        print(message, file=sys.stderr)
        return code


if __name__ == "__main__":
    sys.exit(main())
