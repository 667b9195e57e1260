"""`adarl train`: train any algorithm on any task, several seeds in one process, or resume a run."""

from __future__ import annotations

import argparse
import dataclasses
import shlex
import sys
import time
from pathlib import Path

from adarl.errors import UsageError

HELP = "train an algorithm (AdaRL, SAC baselines, RNAC) on a task, or resume a run"
REPORT_PRESETS = ("quickstart",)  # presets whose runs end with a report in RUN_DIR/report
DEFAULT_ALGO = "adarl"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The run flags and every config field of every algorithm as a flag (`--algo` may come
    after them); `--help` lists the fields of the algorithm `--algo` names before it. A parser
    with a help flag must resolve conflicts (`adarl.cli.main`'s do): this one replaces it."""
    from adarl.algos import registry

    _add_run_arguments(parser)
    seen = {"algo"}
    for cls in registry.config_classes():
        for f in dataclasses.fields(cls):
            if f.name not in seen:
                seen.add(f.name)
                parser.add_argument(
                    _flag(f.name), dest=f"cfg_{f.name}", default=None, help=argparse.SUPPRESS
                )
    if parser.add_help:  # argparse's --help, replaced (the parser resolves conflicts)
        parser.add_argument(
            "-h", "--help", action=_AlgoHelp, nargs=0, help="show this help message and exit"
        )


def _add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """The flags that are not config fields."""
    from adarl.algos import registry

    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = (
        "examples:\n"
        "  adarl train --preset quickstart\n"
        "  adarl train --algo adarl --task walker2d --seeds 0-4 --truncate-every 700000\n"
        "  adarl train --algo sac-fixed-rank --rank 7 --task hopper\n"
        "  adarl train --resume runs/hopper-adarl-20261121-120000\n"
        "  adarl train --fork runs/hopper-adarl-20261121-120000 --at first-truncation "
        "--apply-cuts false --out runs/hopper-control\n"
        "Every config field is a flag (--field-name VALUE); tuples take commas (--seeds 0,2,4 or "
        "0-4).\nadarl train --algo ALGO --help lists ALGO's fields with its defaults.\n"
        "On a task other than hopper, walker2d, ant and humanoid (whose settings are the "
        "paper's), what\nneither a flag nor --preset sets follows --total-steps: d_t "
        "(--truncate-every) = total-steps / 5\ngradient steps (four cuts) and the random-action "
        "warm-up (--start-steps) = 5% of total-steps,\nat most 10,000. The run's start line and "
        "summary say the values; config.yaml records them."
    )
    parser.add_argument(
        "--algo", default=None, help=", ".join(registry.ALGOS) + f" (default {DEFAULT_ALGO})"
    )
    parser.add_argument(
        "--preset",
        default=None,
        help="named settings applied before the flags (e.g. paper, quickstart, smoke)",
    )
    parser.add_argument(
        "--out", default=None, help="run folder (default runs/<task>-<algo>-<time>)"
    )
    parser.add_argument(
        "--resume",
        default=None,
        metavar="RUN_DIR",
        help="continue a run from its newest complete checkpoint (a run of a Gymnasium id "
        "that a module of yours registers: add --env-module PKG, which adarl imports only when "
        "you name it)",
    )
    parser.add_argument(
        "--fork",
        default=None,
        metavar="RUN_DIR",
        help="start a new run (--out) from RUN_DIR's exact state at --at STEP, with the fields "
        "given as flags changed (docs/run-format.md: forks)",
    )
    parser.add_argument(
        "--at",
        default=None,
        metavar="STEP",
        help="with --fork: the step of a checkpoint of RUN_DIR (its pre-truncation checkpoint "
        "where it has one), or first-truncation",
    )
    parser.add_argument(
        "--report", action=argparse.BooleanOptionalAction, default=None,
        help="write `adarl report` into RUN_DIR/report when training ends "
        f"(default: on with --preset {' or '.join(REPORT_PRESETS)}, else off)",
    )  # fmt: skip
    track = parser.add_argument_group("experiment tracking (pip install 'adarl[track]')")
    track.add_argument(
        "--track",
        action="store_true",
        help="mirror the TensorBoard scalars and the config to Weights & Biases",
    )
    track.add_argument("--wandb-project", default=None, help="W&B project (default adarl)")
    track.add_argument("--wandb-entity", default=None, help="W&B entity (team or user)")
    track.add_argument("--wandb-group", default=None, help="W&B group (adarl sweep: its name)")


class _AlgoHelp(argparse.Action):
    """`--help`: the run flags, then the config fields of `--algo` (given before it; default
    adarl) with that algorithm's defaults."""

    def __call__(self, parser, namespace, values, option_string=None):
        from adarl.algos import registry
        from adarl.cli.common import add_common_arguments

        try:
            algo = registry.get(namespace.algo or DEFAULT_ALGO).name
        except UsageError as exc:
            parser.error(str(exc))
        page = argparse.ArgumentParser(prog=parser.prog, description=parser.description)
        _add_run_arguments(page)
        add_common_arguments(page)
        add_config_fields(page, algo)
        page.print_help()
        parser.exit()


def add_config_fields(parser: argparse.ArgumentParser, algo: str) -> None:
    """`algo`'s config fields as flags, each with its meaning and its default as the registry
    resolves it (the default preset, then the per-task budgets)."""
    from adarl.algos import registry

    entry = registry.get(algo)
    defaults = registry.resolve_config(algo, check=False)
    meanings = registry.field_help(entry.config_class)
    group = parser.add_argument_group(
        f"config fields of --algo {algo} (defaults: preset {entry.default_preset})"
    )
    for f in dataclasses.fields(entry.config_class):
        if f.name == "algo":
            continue
        meaning = meanings.get(f.name, "")
        default = _value_text(getattr(defaults, f.name))
        rule = entry.budget_rules.get(f.name)
        per_task = [
            f"on {'other tasks' if task == registry.OTHER_TASKS else task}: "
            f"{_value_text(fields[f.name])}"
            for task, fields in entry.task_defaults.items()
            if f.name in fields and not (rule and task == registry.OTHER_TASKS)
        ]
        if rule:  # issue 62: the field follows --total-steps on other tasks
            per_task.append(f"on other tasks: {rule.text}")
        default += f" ({'; '.join(per_task)})" if per_task else ""
        group.add_argument(
            _flag(f.name),
            dest=f"cfg_{f.name}",
            default=None,
            metavar=_metavar(f),
            help=((f"{meaning}; " if meaning else "") + f"default: {default}").replace("%", "%%"),
        )


def _flag(name: str) -> str:
    return f"--{name.replace('_', '-')}"


def _metavar(f) -> str:
    return str(f.type).replace("typing.", "").upper().split("[")[0].replace(" | NONE", "")


def _value_text(value) -> str:
    return ",".join(map(str, value)) if isinstance(value, tuple) else str(value)


def flags_from_args(args: argparse.Namespace) -> dict[str, str]:
    """The config fields given as flags: field name -> the text typed."""
    return {
        key[4:]: text
        for key, text in vars(args).items()
        if key.startswith("cfg_") and text is not None
    }


def start_from_args(args: argparse.Namespace):
    """What `args` asks to train (`adarl.train.launch`): `--fork`, `--resume`, or a new run of
    `--algo` with `--preset` and the config fields given as flags; a one-line UsageError for
    flags that do not go together."""
    from adarl.algos import registry
    from adarl.envs.tasks import name_env_module
    from adarl.train import fork, launch

    name_env_module(args.cfg_env_module or "")  # the one module a run may import: yours
    if args.at is not None and not args.fork:
        raise UsageError("--at is for --fork RUN_DIR")
    if args.fork:
        for given, what in (
            (args.resume, "--resume"),
            (args.preset, "--preset"),
            (args.algo, "--algo"),
        ):
            if given:
                raise UsageError(
                    f"--fork takes its settings from RUN_DIR; drop {what} and give only the "
                    "fields that change (--apply-cuts false turns AdaRL into its control)"
                )
        if args.at is None:
            raise UsageError(
                f"--fork needs --at STEP (a checkpoint step, or {fork.FIRST_TRUNCATION})"
            )
        return launch.ForkOf(args.fork, args.at, flags_from_args(args))
    if args.resume:
        given = [name for name in flags_from_args(args) if name != "env_module"]
        if given or args.preset or args.out:
            extra = given[0].replace("_", "-") if given else ("preset" if args.preset else "out")
            raise UsageError(f"--resume continues a run with its own settings; drop --{extra}")
        return launch.Resume(args.resume)
    algo = registry.get(args.algo or DEFAULT_ALGO).name
    return launch.New(algo, args.preset, flags_from_args(args))


def build_config(args: argparse.Namespace):
    """(algo, config) of the new run `args` asks for: defaults <- the algorithm <- per-task
    defaults <- --preset <- flags."""
    start = start_from_args(args)
    return start.algo, start.config()


def run(args: argparse.Namespace) -> int:
    from adarl.runs import folder
    from adarl.train import launch

    command = "adarl train " + shlex.join(sys.argv[2:]) if len(sys.argv) > 1 else "adarl train"
    started = time.monotonic()
    start = start_from_args(args)
    tracking = launch.Tracking(args.track, args.wandb_project, args.wandb_entity, args.wandb_group)
    run_dir = launch.train(start, args.out, command, not args.no_progress, tracking)
    if isinstance(start, launch.Resume):
        # a resumed run reports like the run it continues (its --preset, its --report)
        recorded = recorded_args(str(folder.load_config(run_dir).get("command", "")))
        if recorded is not None:
            args.preset = recorded.preset
            args.report = recorded.report if args.report is None else args.report
    finish(run_dir, time.monotonic() - started, args.report, args.preset)
    return 0


class _RaisingParser(argparse.ArgumentParser):
    def error(self, message):  # noqa: D102
        raise ValueError(message)


def recorded_args(command: str) -> argparse.Namespace | None:
    """The `adarl train` flags of a recorded command line, read by this command's own parser (so
    abbreviations and `--flag=value` resolve as they did when it ran); None if it does not parse."""
    try:
        words = shlex.split(command)
    except ValueError:  # a hand-edited, unbalanced command
        return None
    parser = _RaisingParser(add_help=False)
    add_arguments(parser)
    try:
        return parser.parse_known_args(words[2:])[0]
    except ValueError:
        return None


def wants_report(flag: bool | None, preset: str | None) -> bool:
    """`--report`/`--no-report` decide; without either, the presets in `REPORT_PRESETS` report."""
    return flag if flag is not None else preset in REPORT_PRESETS


def finish(run_dir: Path, wall_seconds: float, report: bool | None, preset: str | None) -> None:
    """The end-of-training summary, after the report when one is asked for (`--report`, or
    a preset in `REPORT_PRESETS`)."""
    from adarl.report.summary import training_summary
    from adarl.runs.layout import REPORT_DIR

    report_dir = None
    if wants_report(report, preset):
        from adarl.report.build import build_report
        from adarl.report.common import ReportOptions

        report_dir = run_dir / REPORT_DIR
        command = shlex.join(["adarl", "report", str(run_dir), "--out", str(report_dir)])
        build_report([run_dir], report_dir, ReportOptions(command=command))
    print(training_summary(run_dir, wall_seconds, report_dir))
