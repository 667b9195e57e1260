"""Finding run folders for evaluation and giving each a method label that tells runs apart in a
report. Reading a run folder (its config.yaml with the format-version check, checkpoints, policy
files) is `adarl.runs`; the layout is fixed by docs/run-format.md.
"""

from __future__ import annotations

import os
import re
from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from adarl.algos import registry
from adarl.errors import UsageError
from adarl.runs.folder import done_step, load_config
from adarl.runs.layout import CONFIG_FILE, is_run

# config fields that say how a run was launched, not what was trained; runs differing only in
# these are the same method
LAUNCH_KEYS = {
    "seeds",
    "seed",
    "out",
    "out_dir",
    "run_dir",
    "resume",
    "command",
    "adarl_version",
    "format_version",
    "created",
    "started",
    "host",
    "hostname",
    "progress",
}


@dataclass(frozen=True)
class Run:
    """One run folder: its path, its parsed config.yaml and its method label."""

    path: Path
    config: dict = field(compare=False, repr=False)
    label: str = ""

    @property
    def task(self) -> str:
        return str(config_value(self.config, "task"))

    @property
    def algo(self) -> str:
        return str(config_value(self.config, "algo"))

    @property
    def dynamics(self) -> str:
        """The dynamics the run trained under (e.g. `paper`)."""
        return str(config_value(self.config, "dynamics", "?"))

    @property
    def backend(self) -> str:
        """The physics backend it trained on: `host` (MuJoCo C) or `device` (MJX), the latter
        with its solver where capped (`device, solver 1,4`); runs written before the fields
        existed trained on the host, and on the device with the XML's solver."""
        backend = str(config_value(self.config, "backend", "host"))
        solver = str(config_value(self.config, "device_solver", "xml"))
        return backend if solver == "xml" else f"{backend}, solver {solver}"

    @property
    def seeds(self) -> list[int]:
        return parse_seeds(config_value(self.config, "seeds"))

    @property
    def total_steps(self) -> int | None:
        value = config_value(self.config, "total_steps")
        return None if value is None else int(float(value))

    @property
    def command(self) -> str | None:
        value = config_value(self.config, "command")
        if isinstance(value, list | tuple):
            return " ".join(str(v) for v in value)
        return None if value is None else str(value)

    @property
    def done_step(self) -> int | None:
        """The final step recorded in DONE, or None while the run is unfinished."""
        return done_step(self.path)


def config_value(config: dict, key: str, default=None):
    """`config[key]`, else `default`. adarl writes flat configs: a value is never searched for in
    a nested record (a fork's `changed`, say), which would read another run's setting."""
    return config.get(key, default)


def flatten_config(config: dict, prefix: str = "") -> dict[str, object]:
    """`{"a": {"b": 1}}` -> `{"a.b": 1}` (lists kept as values)."""
    flat = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten_config(value, name + "."))
        else:
            flat[name] = value
    return flat


def parse_seeds(value) -> list[int]:
    """Seeds as written in a config: a list, an int, or a string such as `0-4` or `0,2,5`."""
    if value is None:
        return []
    if isinstance(value, int):
        return [value]
    if isinstance(value, list | tuple):
        return [int(v) for v in value]
    from adarl.algos.flags import parse_int_list

    try:
        return list(parse_int_list(str(value)))
    except ValueError:
        raise UsageError(f"seeds {value!r} are not a list like 0-4 or 0,2,5") from None


# ----------------------------------------------------------------------------- finding runs
def load_run(path: str | os.PathLike) -> Run:
    """Read a run folder's config (checked as a resume checks it: `adarl.runs.folder.load_config`);
    a one-line `UsageError` if the folder is not a run of this run format."""
    path = Path(path)
    config = load_config(path)
    for key in ("algo", "task"):
        if config_value(config, key) is None:
            raise UsageError(f"{path / CONFIG_FILE} has no {key!r} field; is {path} a run folder?")
    return Run(path=path, config=config, label=method_label(config))


def find_runs(paths: Iterable[str | os.PathLike]) -> list[Run]:
    """Runs named by `paths`: each is a run folder, or a folder holding run folders at any depth
    (a sweep's output). Hidden folders are skipped. A path with no run raises `UsageError`."""
    runs: dict[Path, Run] = {}
    for raw in paths:
        path = Path(raw)
        if not path.exists():
            raise UsageError(f"{path} does not exist")
        if not path.is_dir():
            raise UsageError(f"{path} is not a folder")
        if is_run(path):
            found = [path]
        else:
            found = sorted(
                p.parent
                for p in path.rglob(CONFIG_FILE)
                if not any(part.startswith(".") for part in p.relative_to(path).parts[:-1])
            )
            # a run folder's own subfolders are never runs
            found = [p for p in found if not any(q in p.parents for q in found)]
            if not found:
                raise UsageError(
                    f"{path} is not a run folder and holds none (no {CONFIG_FILE} below it)"
                )
        for p in found:
            runs.setdefault(p.resolve(), load_run(p))
    return label_runs(list(runs.values()))


# ----------------------------------------------------------------------------- method labels
def differing_fields(configs: Sequence[dict], ignore: Collection[str] = ()) -> list[str]:
    """Flattened config keys whose values differ between `configs`, launch fields and fields
    named in `ignore` (by their last component) aside; sorted."""
    flats = [flatten_config(c) for c in configs]
    return [
        k
        for k in sorted(set().union(*flats))
        if k.split(".")[-1] not in LAUNCH_KEYS | set(ignore)
        and len({repr(f.get(k)) for f in flats}) > 1
    ]


def method_label(config: dict) -> str:
    """The name a run's method has in tables and legends: the algo, plus what makes a variant
    (the algorithm registry's `report_label`: the rank of `sac-fixed-rank`, a non-default rank
    rule or the retain clause's tolerance of `adarl`)."""
    from adarl.algos import registry

    return registry.report_label(
        config, lambda key, default=None: config_value(config, key, default)
    )


def label_runs(runs: list[Run]) -> list[Run]:
    """Give runs of the same task and method that share seeds distinct labels.

    Runs that agree on task and label and cover disjoint seeds are pooled (one method, more
    seeds). When their seeds overlap, the config fields that differ between them are appended to
    the label (`sac-parseval (coef=1e-05)`); if nothing differs, the same runs were passed twice
    under different folders and a `UsageError` names them.
    """
    groups: dict[tuple[str, str], list[int]] = {}
    for i, run in enumerate(runs):
        groups.setdefault((run.task, run.label), []).append(i)
    out = list(runs)
    for (task, label), members in groups.items():
        if len(members) < 2 or not _seeds_overlap([runs[i] for i in members]):
            continue
        flats = [flatten_config(runs[i].config) for i in members]
        differing = differing_fields([runs[i].config for i in members])
        for i, flat in zip(members, flats):
            extra = ", ".join(f"{k.split('.')[-1]}={flat.get(k)}" for k in differing)
            out[i] = replace(runs[i], label=f"{label} ({extra})" if extra else label)
        relabelled: dict[str, list[Run]] = {}
        for i in members:
            relabelled.setdefault(out[i].label, []).append(out[i])
        for same in relabelled.values():
            if _seeds_overlap(same):
                a, b = _overlapping_pair(same)
                raise UsageError(
                    f"runs {a.path} and {b.path} are both {label!r} on {task} with seed(s) "
                    f"{sorted(set(a.seeds) & set(b.seeds))}; pass only one of them"
                )
    return out


def _seeds_overlap(runs: list[Run]) -> bool:
    return _overlapping_pair(runs) is not None


def _overlapping_pair(runs: list[Run]):
    for i, a in enumerate(runs):
        for b in runs[i + 1 :]:
            sa, sb = set(a.seeds), set(b.seeds)
            if (sa & sb) or not sa or not sb:
                return a, b
    return None


# ----------------------------------------------------------------------------- display order
TASK_ORDER = ("hopper", "walker2d", "ant", "humanoid")
METHOD_ORDER = registry.REPORT_ORDER


def sort_tasks(tasks: Iterable[str]) -> list[str]:
    """The paper's task order, then any other task (a Gymnasium id: `HalfCheetah-v5`,
    `gym:Pendulum-v1`, a user's `ns/Robot-v0`) alphabetically, case and `gym:` aside."""

    def key(task: str):
        if task in TASK_ORDER:
            return (TASK_ORDER.index(task), "", task)
        return (len(TASK_ORDER), task.removeprefix("gym:").lower(), task)

    return sorted(set(tasks), key=key)


def sort_methods(methods: Iterable[str]) -> list[str]:
    """AdaRL first, then the paper's baselines, then variants (ablations, fixed ranks by rank)."""

    def key(label: str):
        base = label.split(" ")[0]
        rank = re.search(r"r=(\d+)", label)
        return (
            METHOD_ORDER.index(base) if base in METHOD_ORDER else len(METHOD_ORDER),
            label != base,
            base,
            int(rank.group(1)) if rank else 0,
            label,
        )

    return sorted(set(methods), key=key)
