"""`adarl` entry point.

Each command is a module in `adarl.cli` exposing `HELP` (one line; `DESCRIPTION`, if any, for its
`--help`), `add_arguments(parser)` and `run(args) -> int`. Modules keep heavy imports (JAX,
MuJoCo) inside `run` so `adarl --help` is fast.
"""

from __future__ import annotations

import argparse
import os
import sys

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


def build_parser() -> argparse.ArgumentParser:
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
        module.add_arguments(p)
        add_common_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    # One XLA thread per computation and one CPU device per core (override by setting XLA_FLAGS
    # yourself): see adarl.runtime.
    configure_xla()
    # Reuse compiled updates across runs (a fresh compile of the SAC update takes 5-20 s).
    os.environ.setdefault(
        "JAX_COMPILATION_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "adarl", "jax")
    )
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
