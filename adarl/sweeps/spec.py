"""Sweep files: parse a YAML spec (or a shipped preset), check everything, expand it into units.

A unit is one task × one algorithm entry × one group of seeds: exactly one training run, whose
seeds train together in one process (each in its own lane). Each unit carries the config it
trains, resolved as `adarl train` resolves its flags (`registry.resolve_config`), so a bad spec
fails here, with a one-line `UsageError`, before anything starts. The format is documented in docs/sweeps.md.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from pathlib import Path

from adarl.errors import UsageError, check_choice
from adarl.files import read_yaml
from adarl.train import launch

PRESET_DIR = Path(__file__).parent / "presets"

TOP_KEYS = (
    "name",
    "description",
    "tasks",
    "algos",
    "seeds",
    "seeds_per_unit",
    "budget",
    "dynamics",
    "preset",
    "evaluation",
    "overrides",
    "cpus_per_unit",
)
REQUIRED_KEYS = ("tasks", "algos", "seeds", "budget")
EVAL_KEYS = ("eval_every", "eval_episodes", "eval_dynamics")
ENTRY_KEYS = ("algo", "name", "preset", "grid", "seeds", "fork")
FORK_KEYS = ("from", "at")  # an entry's `fork`: the label of the entry it forks, and the step
# set by the spec's own keys (tasks, seeds, budget), never by overrides
RESERVED_FIELDS = {"algo": "algos", "task": "tasks", "seeds": "seeds", "total_steps": "budget"}
#: The most seeds a sweep file lists (its `seeds`, or an entry's; a range is counted before it is
#: expanded) and the most units it expands to: 10,000 units of the `smoke` preset's 1,000 steps
#: are already ~18 h on the project's 2-core machine (`adarl sweep --dry-run`), and expanding
#: them takes ~10 s (docs/reliability.md).
MAX_SEEDS = 10_000
MAX_UNITS = 10_000


@dataclass(frozen=True)
class Unit:
    """One run of the sweep, trained into `<sweep>/<id>`. What it trains exists once, as
    `start`: a new run (`launch.New`), or a fork (`launch.ForkOf`) of the unit whose id is
    `start.parent`; its `adarl train` flags, its worker's record and the fork's parent folder are
    derived from it."""

    id: str  # "<task>/<label>/seeds-<...>", also the run folder relative to the sweep folder
    task: str
    algo: str
    label: str
    seeds: tuple[int, ...]
    total_steps: int
    start: launch.New | launch.ForkOf = field(hash=False)
    config: object = field(compare=False, repr=False)  # the config it trains, to check the sweep

    @property
    def fork_of(self) -> str | None:
        """A fork: the id of the unit it starts from (docs/sweeps.md)."""
        return self.start.parent if isinstance(self.start, launch.ForkOf) else None

    @property
    def fork_step(self) -> int:
        """A fork: the step of its parent it starts from (the pre-truncation checkpoint)."""
        return int(self.start.at) if isinstance(self.start, launch.ForkOf) else 0

    @property
    def flat_id(self) -> str:
        """The id as one file name (for logs and lock files)."""
        return self.id.replace("/", "__")

    @property
    def train_args(self) -> tuple[str, ...]:
        """The `adarl train` flags (--out aside) that train the same run, a fork's parent named
        by its unit id: what `--dry-run` shows and the manifest records."""
        return self.start.argv()

    def start_in(self, out: Path) -> launch.New | launch.ForkOf:
        """`start` for the sweep folder `out`: a fork's parent is its unit's run folder there."""
        if isinstance(self.start, launch.ForkOf):
            return dataclasses.replace(self.start, parent=str(out / self.start.parent))
        return self.start


@dataclass(frozen=True)
class Sweep:
    name: str
    source: str  # the preset name or the file path it came from
    units: tuple[Unit, ...]
    cpus_per_unit: int = 1


# ----------------------------------------------------------------------------- loading
def list_presets() -> list[str]:
    return sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))


def resolve(spec: str) -> Path:
    """A path to an existing file, else the shipped preset of that name."""
    path = Path(spec)
    if path.is_file():
        return path
    preset = PRESET_DIR / f"{spec}.yaml"
    if "/" not in spec and preset.is_file():
        return preset
    raise UsageError(
        f"no sweep file or preset named {spec!r}; presets: {', '.join(list_presets())}"
    )


def load(spec: str, run: bool = False) -> Sweep:
    """Read, check and expand a sweep file or preset name; a one-line UsageError on bad input.
    `run`: the sweep is to run (not `--dry-run`), so the env-modules the file names, which the
    user gave on the command line with it, may be imported; otherwise only those named with
    `--env-module` (`adarl.envs.tasks.name_env_module`)."""
    from adarl.envs.tasks import check_named, name_env_module

    path = resolve(spec)
    doc = read_yaml(path)
    source = spec if path.parent == PRESET_DIR and not Path(spec).is_file() else str(path)
    for module in env_modules(doc):
        if not run:
            check_named(module, source)
            continue
        try:
            name_env_module(module)
        except UsageError as exc:
            raise UsageError(f"{source}: {exc}") from None
    return parse(doc, source=source, default_name=path.stem)


def env_modules(doc) -> list[str]:
    """Every `env_module` a sweep file's YAML names (in its overrides, a task's, an entry's or a
    grid's), as text."""
    found: list[str] = []
    if isinstance(doc, dict):
        for key, value in doc.items():
            if key == "env_module":
                found += [str(v) for v in (value if isinstance(value, list) else [value]) if v]
            else:
                found += env_modules(value)
    elif isinstance(doc, list):
        for value in doc:
            found += env_modules(value)
    return found


# ----------------------------------------------------------------------------- parsing
def parse(doc, source: str = "<spec>", default_name: str = "sweep") -> Sweep:
    """Check a spec already read from YAML and expand it into units."""
    from adarl import envs
    from adarl.algos.registry import ALGOS

    where = source
    if not isinstance(doc, dict):
        raise UsageError(f"{where}: a sweep file is a mapping of keys ({', '.join(TOP_KEYS)})")
    _check_keys(doc, TOP_KEYS, f"{where}")
    for key in REQUIRED_KEYS:
        if key not in doc:
            raise UsageError(f"{where}: missing key {key!r} (required: {', '.join(REQUIRED_KEYS)})")
    fields = _algo_fields()
    all_fields = set().union(*fields.values())

    name = _name(doc.get("name", default_name), f"{where}: name")
    overrides = _overrides(doc.get("overrides"), f"{where}: overrides", all_fields)
    tasks = _tasks(doc["tasks"], where, all_fields, overrides)
    seeds = _seeds(doc["seeds"], where)
    group = doc.get("seeds_per_unit", len(seeds))
    if not _is_int(group) or group < 1:
        raise UsageError(f"{where}: seeds_per_unit must be an integer ≥ 1, got {group!r}")
    cpus = doc.get("cpus_per_unit", 1)
    if not _is_int(cpus) or cpus < 1:
        raise UsageError(f"{where}: cpus_per_unit must be an integer ≥ 1, got {cpus!r}")
    budget = _budget(doc["budget"], tasks, where)
    base: dict = {}
    if doc.get("dynamics") is not None:
        base["dynamics"] = _string(doc["dynamics"], f"{where}: dynamics")
    evaluation = doc.get("evaluation") or {}
    if not isinstance(evaluation, dict):
        raise UsageError(f"{where}: evaluation must be a mapping of {', '.join(EVAL_KEYS)}")
    _check_keys(evaluation, EVAL_KEYS, f"{where}: evaluation")
    base.update(evaluation)
    entries = _algo_entries(doc["algos"], where, fields, ALGOS)
    presets = _algo_presets()
    preset = doc.get("preset")
    if preset is not None:
        preset = _string(preset, f"{where}: preset")
        known = sorted({p for names in presets.values() for p in names})
        if preset not in known:
            raise UsageError(f"{where}: unknown preset {preset!r}; allowed: {', '.join(known)}")

    n_units = len(tasks) * sum(-(-len(e["seeds"] or seeds) // group) for e in entries)
    if n_units > MAX_UNITS:
        raise UsageError(
            f"{where}: {n_units:,} units ({len(tasks)} task(s) x {len(entries)} algorithm "
            f"entries x their seeds in groups of seeds_per_unit {group}); allowed: at most "
            f"{MAX_UNITS:,} per sweep file; raise seeds_per_unit or split the sweep"
        )
    units = []
    for task, task_overrides in tasks.items():
        for entry in entries:
            entry_seeds = entry["seeds"] or seeds
            groups = [tuple(entry_seeds[i : i + group]) for i in range(0, len(entry_seeds), group)]
            algo_fields = fields[entry["algo"]]
            values = dict(base)
            values.update({k: v for k, v in overrides.items() if k in algo_fields})
            values.update({k: v for k, v in task_overrides.items() if k in algo_fields})
            values.update(entry["fields"])
            # the file's preset reaches the entries without their own, where the algorithm has it
            algo_preset = preset if preset in presets[entry["algo"]] else None
            for seed_group in groups:
                units.append(
                    _unit(
                        task,
                        entry,
                        seed_group,
                        budget[task],
                        entry["preset"] or algo_preset,
                        values,
                        where,
                        envs,
                    )
                )
    _check_distinct_folders(units, where)
    units = _forks(units, entries, where)
    return Sweep(name=name, source=source, units=tuple(units), cpus_per_unit=int(cpus))


def _check_distinct_folders(units: list[Unit], where: str) -> None:
    """A one-line UsageError when two units would train into one folder (two tasks whose names
    map to one folder name, `rel6/Bot-v0` and `rel6__Bot-v0`): the second would never train
    and be reported done, with the first's rows under its name (issue 61 §7)."""
    seen: dict[str, Unit] = {}
    for unit in units:
        first = seen.setdefault(unit.id, unit)
        if first is not unit:
            raise UsageError(
                f"{where}: tasks {first.task!r} and {unit.task!r} would train into one unit folder "
                f"{unit.id!r}; allowed: task names that stay apart once '/' becomes '__' (rename "
                "one, or register it under another id)"
            )


def _forks(units: list[Unit], entries: list[dict], where: str) -> list[Unit]:
    """Turn the units of entries with a `fork` into forks of their parents' units (same task
    and seeds) at the parent's checkpoint before the truncation `at` names, changing the fields
    in which their config differs from the parent's."""
    from adarl.train import fork

    by_label = {e["label"]: e for e in entries}
    out = []
    for unit in units:
        entry = by_label[unit.label]
        if entry["fork"] is None:
            out.append(unit)
            continue
        here = f"{where}: {unit.id}"
        parent_label, at = entry["fork"]["from"], entry["fork"]["at"]
        parent_entry = by_label.get(parent_label)
        if parent_entry is None or parent_entry["fork"] is not None:
            plain = [e["label"] for e in entries if e["fork"] is None]
            raise UsageError(
                f"{here}: fork from {parent_label!r}: no such entry without a fork; "
                f"entries: {', '.join(plain)}"
            )
        parent_id = f"{unit.task.replace('/', '__')}/{parent_label}/seeds-{_seed_text(unit.seeds)}"
        parent = next((u for u in units if u.id == parent_id), None)
        if parent is None:
            raise UsageError(f"{here}: its parent {parent_id} is not in the sweep (same seeds?)")
        try:
            changed = fork.check_forkable(parent.config, unit.config)
            step = fork.fork_step(parent.config, at)
        except UsageError as exc:
            raise UsageError(f"{here}: {exc}") from None
        from adarl.algos import schedule

        if step not in schedule.truncation_steps(parent.config):
            raise UsageError(
                f"{here}: fork at step {step}: {parent_id} truncates at "
                f"{', '.join(map(str, schedule.truncation_steps(parent.config))) or 'no step'}; "
                f"a sweep forks at a truncation ({fork.FIRST_TRUNCATION} or one of those steps)"
            )
        if not parent.config.checkpoint_before_truncation:
            raise UsageError(f"{here}: {parent_id} keeps no checkpoint before its truncations")
        changes = {  # algo follows apply_cuts
            name: _flag_text(getattr(unit.config, name)) for name in changed if name != "algo"
        }
        out.append(dataclasses.replace(unit, start=launch.ForkOf(parent_id, step, changes)))
    return out


def _unit(task, entry, seeds, total_steps, preset, values, where, envs) -> Unit:
    from adarl.envs.tasks import task_of

    label, algo = entry["label"], entry["algo"]
    # a namespaced Gymnasium id (`ns/Name-v0`) is one folder level, as the paper's names are
    uid = f"{task.replace('/', '__')}/{label}/seeds-{_seed_text(seeds)}"
    # as flag text, parsed by the field's type as `adarl train` parses its flags (a YAML 1.5e5
    # for an integer field is 150000 either way)
    flags = {"task": task, "seeds": ",".join(map(str, seeds)), "total_steps": str(total_steps)}
    for name, value in values.items():
        if (
            name == "eval_dynamics"
            and isinstance(value, list)
            and any("," in str(v) for v in value)
        ):
            raise UsageError(
                f"{where}: {uid}: eval_dynamics items are comma-separated (as for "
                f"adarl train --eval-dynamics), so none can hold a comma; got {value!r}"
            )
        flags[name] = _flag_text(value)
    start = launch.New(algo, preset, flags)
    try:
        config = start.config()
        task_spec = task_of(config)  # made as the unit trains it: its env_kwargs, env_module
        for spec in (config.dynamics, *config.eval_dynamics):  # as its learner will
            envs.check_dynamics(spec, task_spec, **config.env_options())
    except UsageError as exc:
        raise UsageError(f"{where}: {uid}: {exc}") from None
    return Unit(
        id=uid,
        task=task,
        algo=algo,
        label=label,
        seeds=tuple(seeds),
        total_steps=int(total_steps),
        start=start,
        config=config,
    )


# ----------------------------------------------------------------------------- pieces
def _algo_fields() -> dict[str, set[str]]:
    from adarl.algos import registry

    return {algo: registry.field_names(algo) for algo in registry.ALGOS}


def _algo_presets() -> dict[str, set[str]]:
    from adarl.algos import registry

    return {algo: set(entry.presets) for algo, entry in registry.ALGORITHMS.items()}


def _check_keys(mapping: dict, allowed, where: str) -> None:
    for key in mapping:
        if key not in allowed:
            raise UsageError(f"{where}: unknown key {key!r}; allowed: {', '.join(allowed)}")


def _tasks(value, where: str, all_fields: set[str], overrides: dict) -> dict[str, dict]:
    """The spec's tasks (the paper's four, any Gymnasium id), each with its overrides; a
    Gymnasium id is made with the `env_kwargs` and `env_module` its overrides (else the file's
    `overrides`) give, so that a user's registered id and XML are found."""
    from adarl.envs import get_task
    from adarl.envs.tasks import TASKS

    if isinstance(value, str):
        value = [value]
    if isinstance(value, list):
        twice = [t for t in value if value.count(t) > 1]
        if twice:
            raise UsageError(f"{where}: task {twice[0]!r} is listed twice")
        value = dict.fromkeys(value)
    if not isinstance(value, dict):
        raise UsageError(
            f"{where}: tasks must be a list of task names or a mapping "
            f"task -> overrides, got {value!r}"
        )
    if not value:
        raise UsageError(f"{where}: tasks is empty, so the sweep has nothing to run")
    tasks = {}
    for task, own in value.items():
        own = _overrides(own, f"{where}: tasks: {task}", all_fields)
        options = {}
        if str(task).strip().lower() not in TASKS:
            options = {
                key: str(own.get(key, overrides.get(key, "")) or "")
                for key in ("env_kwargs", "env_module")
            }
        try:
            name = get_task(str(task), **options).name
        except UsageError as exc:
            raise UsageError(f"{where}: {exc}") from None
        tasks[name] = own
    return tasks


def _overrides(value, where: str, allowed: set[str]) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise UsageError(f"{where} must be a mapping of config fields to values, got {value!r}")
    for key in value:
        _check_field(key, allowed, where)
    return dict(value)


def _check_field(key, allowed: set[str], where: str, algo: str | None = None) -> None:
    if key in RESERVED_FIELDS:
        raise UsageError(f"{where}: {key!r} is set by the spec's {RESERVED_FIELDS[key]!r} key")
    if key not in allowed:
        what = f"a config field of {algo}" if algo else "a config field of any algorithm"
        raise UsageError(f"{where}: unknown key {key!r}; it is not {what} (see adarl train --help)")


def _seeds(value, where: str) -> tuple[int, ...]:
    from adarl.algos.flags import ListTooLong, parse_int_list

    if _is_int(value):
        value = [value]
    if isinstance(value, str):
        try:
            value = list(parse_int_list(value, most=MAX_SEEDS))
        except ListTooLong as error:
            _too_many_seeds(error.count, value, where)
        except ValueError:
            raise UsageError(f"{where}: seeds {value!r} are not a list like 0-4 or 0,2,5") from None
    if isinstance(value, list) and len(value) > MAX_SEEDS:
        _too_many_seeds(len(value), f"[{value[0]!r}, ...]", where)
    if not isinstance(value, list) or not all(_is_int(s) and s >= 0 for s in value):
        raise UsageError(
            f"{where}: seeds must be integers ≥ 0 (a list, or text like 0-4), got {value!r}"
        )
    if not value:
        raise UsageError(f"{where}: seeds is empty, so the sweep has nothing to run")
    if len(set(value)) != len(value):
        raise UsageError(f"{where}: seeds contain duplicates: {value}")
    return tuple(value)


def _too_many_seeds(count: int, text, where: str):
    raise UsageError(
        f"{where}: seeds {text!r} are {count:,} seeds; allowed: at most {MAX_SEEDS:,} per sweep "
        "file; split the seeds over several sweep files"
    )


def _budget(value, tasks: dict, where: str) -> dict[str, int]:
    if not isinstance(value, dict):
        value = {task: value for task in tasks}
    extra = [t for t in value if t not in tasks]
    if extra:
        raise UsageError(
            f"{where}: budget names task {extra[0]!r}, which is not in tasks ({', '.join(tasks)})"
        )
    budget = {}
    for task in tasks:
        if task not in value:
            raise UsageError(f"{where}: budget has no entry for task {task!r}")
        steps = _steps(value[task])
        if steps is None or steps <= 0:
            raise UsageError(
                f"{where}: budget for {task} must be a number of steps > 0, got {value[task]!r}"
            )
        budget[task] = steps
    return budget


def _steps(value) -> int | None:
    """An integral number of steps: 150000, 150_000, 1.5e5 or '1.5e5'; else None."""
    if isinstance(value, bool):
        return None
    if isinstance(value, str):
        try:
            value = float(value.replace("_", ""))
        except ValueError:
            return None
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    return value if isinstance(value, int) else None


def _algo_entries(value, where: str, fields: dict[str, set[str]], algos) -> list[dict]:
    if isinstance(value, str | dict):
        value = [value]
    if not isinstance(value, list):
        raise UsageError(
            f"{where}: algos must be a list of algorithm names or entries, got {value!r}"
        )
    if not value:
        raise UsageError(f"{where}: algos is empty, so the sweep has nothing to run")
    entries: list[dict] = []
    for item in value:
        entries.extend(_algo_entry(item, where, fields, algos))
    labels: dict[str, int] = {}
    for entry in entries:
        labels[entry["label"]] = labels.get(entry["label"], 0) + 1
    twice = [label for label, n in labels.items() if n > 1]
    if twice:
        raise UsageError(
            f"{where}: two algos entries are both named {twice[0]!r}; "
            f"give them different settings or a `name`"
        )
    return entries


def _algo_entry(item, where: str, fields: dict[str, set[str]], algos) -> list[dict]:
    if isinstance(item, str):
        item = {"algo": item}
    if not isinstance(item, dict) or "algo" not in item:
        raise UsageError(
            f"{where}: an algos entry is a name or a mapping with an `algo` key, got {item!r}"
        )
    try:
        algo = check_choice("algo", str(item["algo"]), algos)
    except UsageError as exc:
        raise UsageError(f"{where}: {exc}") from None
    here = f"{where}: algos entry {algo!r}"
    allowed = fields[algo]
    settings = {k: v for k, v in item.items() if k not in ENTRY_KEYS}
    for key in settings:
        _check_field(key, allowed, here, algo)
    preset = item.get("preset")
    if preset is not None:
        preset = _string(preset, f"{here}: preset")
    name = item.get("name")
    seeds = _seeds(item["seeds"], f"{here}: seeds") if "seeds" in item else None
    grid = item.get("grid", {})
    if not isinstance(grid, dict) or ("grid" in item and not grid):
        raise UsageError(
            f"{here}: grid must be a non-empty mapping of config fields to lists "
            f"of values, got {grid!r}"
        )
    points: list[dict] = [{}]
    for key, values in grid.items():
        _check_field(key, allowed, f"{here}: grid", algo)
        if not isinstance(values, list):
            values = [values]
        if not values:
            raise UsageError(f"{here}: grid {key!r} is empty, so the sweep has nothing to run")
        points = [{**p, key: v} for p in points for v in values]
    if name is not None and len(points) > 1:
        raise UsageError(f"{here}: a `name` cannot label the {len(points)} points of a grid")
    fork = item.get("fork")
    if fork is not None:
        if not isinstance(fork, dict) or set(fork) != set(FORK_KEYS) or len(points) > 1:
            raise UsageError(
                f"{here}: fork must be a mapping {{from: <entry label>, at: first-truncation or "
                f"a step}} on an entry without a grid, got {fork!r}"
            )
        fork = {"from": str(fork["from"]), "at": fork["at"]}
    out = []
    for point in points:
        label = (
            _name(name, f"{here}: name")
            if name is not None
            else _label(algo, preset, {**settings, **point})
        )
        out.append(
            {
                "algo": algo,
                "preset": preset,
                "label": label,
                "fields": {**settings, **point},
                "seeds": seeds,
                "fork": fork,
            }
        )
    return out


def _label(algo: str, preset: str | None, settings: dict) -> str:
    """The folder name of an algos entry: the algo, its preset, then each setting
    (`sac-fixed-rank_rank-7`, `adarl_rank_rule-ratio`)."""
    parts = [algo] + ([preset] if preset else [])
    parts += [f"{k}-{_flag_text(v)}" for k, v in settings.items()]
    return re.sub(r"[^A-Za-z0-9._=+-]+", "-", "_".join(parts))


def _name(value, where: str) -> str:
    text = _string(value, where)
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._=+-]*", text):
        raise UsageError(
            f"{where} {text!r} must be letters, digits and . _ - = + (it names a folder)"
        )
    return text


def _string(value, where: str) -> str:
    if not isinstance(value, str | int | float) or isinstance(value, bool) or value == "":
        raise UsageError(f"{where} must be a non-empty string, got {value!r}")
    return str(value)


def _is_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _seed_text(seeds: tuple[int, ...]) -> str:
    """(0, 1, 2) -> '0-2'; (0, 2) -> '0_2'; (3,) -> '3'."""
    if len(seeds) > 1 and list(seeds) == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}-{seeds[-1]}"
    return "_".join(map(str, seeds))


def _flag_text(value) -> str:
    """A YAML value as `adarl train` flag text: lists joined by commas, booleans in lower case,
    integral floats (1e6) as integers."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "none"
    if isinstance(value, list | tuple):
        return ",".join(_flag_text(v) for v in value)
    if isinstance(value, str) and re.fullmatch(r"[+-]?\d+(\.\d*)?[eE][+-]?\d+", value):
        value = float(value)  # YAML reads 1e6 (no dot) as text
    if isinstance(value, float) and value.is_integer() and abs(value) >= 1:
        return str(int(value))
    return str(value)
