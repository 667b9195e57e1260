"""`adarl train`: train any algorithm on any task, several seeds in one process, or resume a run."""

from __future__ import annotations

import argparse
import dataclasses
import shlex
import sys
import time
import typing
from pathlib import Path

from adarl.errors import UsageError, check_choice

HELP = "train an algorithm (AdaRL, SAC baselines, RNAC) on a task, or resume a run"
RUN_FLAGS = ("algo", "task", "dynamics", "seeds", "total_steps")
REPORT_PRESETS = ("quickstart",)  # presets whose runs end with a report in RUN_DIR/report


def _config_classes():
    from adarl.algos import rnac, sac

    return {"sac": sac.SACConfig, "rnac": rnac.RNACConfig}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = (
        "examples:\n"
        "  adarl train --preset quickstart\n"
        "  adarl train --algo adarl --task walker2d --seeds 0-4 --truncate-every 700000\n"
        "  adarl train --algo sac-fixed-rank --rank 7 --task hopper\n"
        "  adarl train --resume runs/hopper-adarl-20261121-120000\n"
        "Every config field is a flag (--field-name VALUE); tuples take commas (--seeds 0,2,4 or 0-4)."
    )
    parser.add_argument(
        "--algo", default="adarl", help="adarl, sac, sac-fixed-rank, sac-parseval, sac-sparse, rnac"
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
        help="continue a run from its newest complete checkpoint",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
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
    seen = {"algo"}
    for family, cls in _config_classes().items():
        group = parser.add_argument_group(f"{family.upper()}-family config fields")
        for f in dataclasses.fields(cls):
            if f.name in seen:
                continue
            seen.add(f.name)
            group.add_argument(
                f"--{f.name.replace('_', '-')}",
                dest=f"cfg_{f.name}",
                default=None,
                metavar=_metavar(f),
                help=f"default: {_default_text(f)}",
            )


def _metavar(f) -> str:
    return str(f.type).replace("typing.", "").upper().split("[")[0].replace(" | NONE", "")


def _default_text(f) -> str:
    from adarl.algos import TASK_DEFAULTS

    value = f.default if f.default is not dataclasses.MISSING else f.default_factory()
    text = ",".join(map(str, value)) if isinstance(value, tuple) else str(value)
    per_task = [
        f"{algo} on {task}: {fields[f.name]}"
        for algo, tasks in TASK_DEFAULTS.items()
        for task, fields in tasks.items()
        if f.name in fields
    ]
    return text + (f" ({'; '.join(per_task)})" if per_task else "")


def parse_value(name: str, text: str, type_text: str):
    """Convert a flag's text to the field's type (`int`, `float`, `bool`, tuples, optionals)."""
    t = type_text.replace(" ", "")
    flag = "--" + name.replace("_", "-")
    if t.endswith("|None") and text.lower() in ("none", "off", ""):
        return None
    t = t.removesuffix("|None")
    try:
        if t == "int":
            return int(text)
        if t == "float":
            return float(text)
        if t == "bool":
            lowered = text.lower()
            if lowered not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError
            return lowered in ("true", "1", "yes")
        if t == "str":
            return text
        if t == "tuple[int,...]":
            return parse_int_list(text)
        if t == "tuple[str,...]":
            return split_specs(text)
    except ValueError:
        raise UsageError(f"{flag} expects {t}, got {text!r}") from None
    raise UsageError(f"{flag}: unsupported field type {t}")


def split_specs(text: str) -> tuple[str, ...]:
    """Comma-separated items, where a `key=value` piece without its own `name:` prefix belongs to
    the item before it: 'nominal,fixed:a=1,b=2' -> ('nominal', 'fixed:a=1,b=2')."""
    items: list[str] = []
    for part in text.split(","):
        if not part:
            continue
        if items and "=" in part and ":" not in part and ":" in items[-1]:
            items[-1] += "," + part
        else:
            items.append(part)
    return tuple(items)


def parse_int_list(text: str) -> tuple[int, ...]:
    """'0-4' -> (0, 1, 2, 3, 4); '0,2,5' -> (0, 2, 5); ranges and lists mix ('0-2,7')."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        lo, dash, hi = part.partition("-")
        if dash and lo:
            a, b = int(lo), int(hi)
            if b < a:
                raise ValueError
            out.extend(range(a, b + 1))
        else:
            out.append(int(part))
    if not out:
        raise ValueError
    return tuple(out)


def build_config(args: argparse.Namespace):
    """defaults <- the algorithm's definition <- --preset <- flags; returns (family, config)."""
    from adarl.algos import ALGOS, SAC_FAMILY, TASK_DEFAULTS

    algo = check_choice("algo", args.algo, ALGOS)
    family = "rnac" if algo == "rnac" else "sac"
    cls = _config_classes()[family]
    module = _algo_module(family)
    values: dict = {"algo": algo} if family == "sac" else {}
    if family == "sac":
        values.update(SAC_FAMILY[algo])
    preset = args.preset or ("paper" if family == "sac" else "default")
    check_choice(f"preset for {algo}", preset, module.PRESETS)
    hints = typing.get_type_hints(cls)
    fields = {f.name for f in dataclasses.fields(cls)}
    flags = {}
    for key, text in vars(args).items():
        if not key.startswith("cfg_") or text is None:
            continue
        name = key[4:]
        if name not in fields:
            raise UsageError(f"--{name.replace('_', '-')} does not apply to --algo {algo}")
        flags[name] = parse_value(name, text, _type_text(hints[name]))
    # the algorithm's per-task defaults sit below the preset and the flags
    task = flags.get("task", module.PRESETS[preset].get("task", cls.task))
    values.update(TASK_DEFAULTS.get(algo, {}).get(task, {}))
    values.update(module.PRESETS[preset])
    values.update(flags)
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return family, cls(**values).validate()


def _type_text(hint) -> str:
    text = str(hint) if not isinstance(hint, type) else hint.__name__
    return text.replace("typing.", "").replace("Optional[", "").replace("NoneType", "None")


def _algo_module(family: str):
    if family == "rnac":
        from adarl.algos import rnac

        return rnac
    from adarl.algos import sac

    return sac


def _trainer(family: str):
    if family == "rnac":
        from adarl.algos.rnac import train

        return lambda config, run_dir, resume, progress, command: train(config, run_dir, resume)
    from adarl.train.sac_loop import train

    return train


def config_from_run(run_dir: Path):
    """The config a run folder was started with (for --resume)."""
    from adarl.train.sac_loop import load_run_config

    values = load_run_config(run_dir)
    algo = values.get("algo", "rnac")
    family = "rnac" if algo == "rnac" else "sac"
    cls = _config_classes()[family]
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - names - {"algo", "format_version", "adarl_version", "command"})
    if unknown:  # a typo or a hand edit: dropping it silently would change the run
        raise UsageError(
            f"{Path(run_dir) / 'config.yaml'} has unknown field {unknown[0]!r}; allowed: the "
            f"config fields of --algo {algo} (adarl train --help)"
        )
    kept = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items() if k in names}
    if family == "sac" and "lr_schedule" not in values:  # written before the field existed
        kept["lr_schedule"] = "restart"
    return family, cls(**kept).validate()


def run(args: argparse.Namespace) -> int:
    command = "adarl train " + shlex.join(sys.argv[2:]) if len(sys.argv) > 1 else "adarl train"
    started = time.monotonic()
    if args.resume:
        given = [k[4:] for k, v in vars(args).items() if k.startswith("cfg_") and v is not None]
        if given or args.preset or args.out:
            extra = given[0].replace("_", "-") if given else ("preset" if args.preset else "out")
            raise UsageError(f"--resume continues a run with its own settings; drop --{extra}")
        run_dir = Path(args.resume)
        family, config = config_from_run(run_dir)
        with _tracked(args, run_dir, config, command):
            _trainer(family)(config, run_dir, True, not args.no_progress, command)
    else:
        family, config = build_config(args)
        task = getattr(config, "task", "task")
        run_dir = (
            Path(args.out)
            if args.out
            else Path("runs") / (f"{task}-{args.algo}-{time.strftime('%Y%m%d-%H%M%S')}")
        )
        with _tracked(args, run_dir, config, command):
            _trainer(family)(config, run_dir, False, not args.no_progress, command)
    finish(run_dir, time.monotonic() - started, args.report, args.preset)
    return 0


def wants_report(flag: bool | None, preset: str | None) -> bool:
    """`--report`/`--no-report` decide; without either, the presets in `REPORT_PRESETS` report."""
    return flag if flag is not None else preset in REPORT_PRESETS


def finish(run_dir: Path, wall_seconds: float, report: bool | None, preset: str | None) -> None:
    """The end-of-training summary, after the report when one is asked for (`--report`, or
    a preset in `REPORT_PRESETS`)."""
    from adarl.evaluation.summary import training_summary

    report_dir = None
    if wants_report(report, preset):
        from adarl.evaluation.report import ReportOptions, build_report

        report_dir = run_dir / "report"
        command = shlex.join(["adarl", "report", str(run_dir), "--out", str(report_dir)])
        build_report([run_dir], report_dir, ReportOptions(command=command))
    print(training_summary(run_dir, wall_seconds, report_dir))


def _tracked(args: argparse.Namespace, run_dir: Path, config, command: str):
    from adarl.train import tracking

    for name in ("wandb_project", "wandb_entity", "wandb_group"):
        if getattr(args, name) is not None and not args.track:
            raise UsageError(f"--{name.replace('_', '-')} is for --track")
    return tracking.tracked(
        args.track,
        run_dir,
        config,
        project=args.wandb_project,
        entity=args.wandb_entity,
        group=args.wandb_group,
        command=command,
    )
