"""Every algorithm by name: its config class, the fields that define it, its per-task defaults,
its presets and its roles in the paper's protocol. The CLI, the sweeps and the report read this
table; adding an algorithm is a config (and presets) in `adarl/algos/<name>_config.py`, its maths
in `adarl/algos`, one entry here and one in `adarl.train.trainers` (docs/algorithms.md, "Adding an
algorithm").

A config is resolved in one order everywhere (`resolve_config`): the config class's defaults
<- the algorithm's defining fields <- its per-task defaults <- the preset <- the flags.

Everything here is JAX-free (configs and presets live apart from the maths), so reading the
table (the report, `adarl --help`) does not load JAX. The trainers, which do, are in
`adarl.train.trainers`.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import io
import tokenize
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from adarl.algos import rnac_config, sac_config
from adarl.algos.config import BudgetRule, follows_budget
from adarl.algos.flags import field_value, type_text
from adarl.algos.sac_config import SAC_FAMILY
from adarl.errors import UsageError, check_choice

# keys config.yaml holds beside the config fields (docs/run-format.md)
RUN_RECORD_KEYS = ("algo", "format_version", "adarl_version", "command", "fork")


@dataclass(frozen=True)
class Retired:
    """A config field adarl no longer has, which config.yaml files written before still hold."""

    today: object  # the value that means what adarl does today: read, and dropped
    meant: str  # what the other values meant
    last_commit: str  # the last adarl commit that resumes and forks runs with another value


@dataclass(frozen=True)
class Algorithm:
    name: str
    config_class: type  # its config dataclass (a `RunConfig`)
    # config fields that define the algorithm (applied before presets and flags)
    defaults: Mapping[str, object]
    # task -> fields, below the preset and the flags (a budget where the user sets none)
    task_defaults: Mapping[str, Mapping[str, object]]
    presets: Mapping[str, Mapping[str, object]]  # preset name -> fields
    default_preset: str
    # fields a config.yaml written before they existed is read with (their value back then)
    legacy_fields: Mapping[str, object] = field(default_factory=dict)
    # fields that follow the step budget on a task outside the paper's four where neither a flag
    # nor the preset sets them (`resolve_config`; issue 62)
    budget_rules: Mapping[str, BudgetRule] = field(default_factory=dict)
    # fields it no longer has: runs that recorded another value evaluate, report and export,
    # but resume and fork only with the adarl that trained them (`check_resumable`)
    retired_fields: Mapping[str, Retired] = field(default_factory=dict)
    # its original reports each seed's best checkpoint by evaluation: `adarl report
    # --best-checkpoint best` scores it there (the loop keeps every algorithm's best policy,
    # docs/run-format.md; the other algorithms are always scored at their final checkpoint)
    best_checkpoint: bool = False
    # the method's name in reports, from a run's config (`value(field, default)`): variants apart
    report_label: Callable[[Callable], str] | None = None
    # --- roles in the paper's protocol, read by the report
    adapts_rank: bool = False  # its bottleneck ranks change: the rank and ablation sections
    # its runs span fixed ranks: the bias–variance figure, not the main table
    rank_sweep: bool = False
    # a config field whose best value per task the main table keeps ("best of N", as the paper
    # does for Parseval's coefficient)
    best_of: str | None = None
    # the algorithm this one is the schedule-matched control of: the report pairs their seeds
    control_of: str | None = None


# ---------------------------------------------------------------------------- report labels
# AdaRL's default rank rule and threshold (the config's): runs with them are labelled plain `adarl`
DEFAULT_RANK_RULE = sac_config.SACConfig.rank_rule
DEFAULT_BETA = sac_config.SACConfig.beta


def _fixed_rank_label(value) -> str:
    rank = value("rank")
    return f"sac-fixed-rank r={rank}" if rank is not None else "sac-fixed-rank"


def _sparse_label(value) -> str:
    """`sac-sparse`, with its width where it is not the paper's."""
    width = value("sparse_width")
    default = SAC_FAMILY["sac-sparse"]["sparse_width"]
    return "sac-sparse" if width in (None, default) else f"sac-sparse w={width}"


def _adarl_label(value) -> str:
    """`adarl` (or `adarl-control`), plus a non-default rank rule, threshold beta or the retain
    clause's tolerance."""
    name = str(value("algo", "adarl"))
    rule = str(value("rank_rule", "cumulative"))  # runs from before the field: Eq. 5
    beta, tolerance = value("beta"), value("retain_tolerance")
    parts = [] if rule == DEFAULT_RANK_RULE else [f"{rule} rule"]
    parts += [] if beta is None or float(beta) == DEFAULT_BETA else [f"beta {float(beta):g}"]
    parts += [] if tolerance is None else [f"retain {float(tolerance):g}"]
    return f"{name} ({', '.join(parts)})" if parts else name


# ---------------------------------------------------------------------------- the table
# the method every other is compared against (probability of improvement), and the paper's
# Table 1 order of methods in reports; other algorithms follow
REFERENCE = "adarl"
REPORT_ORDER = ("adarl", "adarl-control", "sac", "sac-parseval", "sac-sparse", "rnac")
# the SAC family: configurations of adarl/algos/sac.py (`SAC_FAMILY`), trained by the one loop
SAC_FAMILY_ROLES: dict[str, dict] = {
    "adarl": {"report_label": _adarl_label, "adapts_rank": True},
    "adarl-control": {"report_label": _adarl_label, "control_of": "adarl"},
    "sac-fixed-rank": {"report_label": _fixed_rank_label, "rank_sweep": True},
    "sac-parseval": {"best_of": "parseval_coef"},
    "sac-sparse": {"report_label": _sparse_label},
}
ADARL_SCHEDULE = ("adarl", "adarl-control")  # the control runs AdaRL's schedule
# `lanes: K` (K ≥ 1) of runs started before 2026-12-02 (8f57d24); none of the presets, the
# sweeps' run folders or the campaign's (all `lanes: 0`) has it (docs/algorithms.md)
SAC_RETIRED = {
    "lanes": Retired(
        today=0,
        meant="its seeds trained in K vmapped groups sharing one bottleneck width",
        last_commit="4ef91cf",
    )
}

ALGORITHMS: dict[str, Algorithm] = {
    **{
        name: Algorithm(
            name=name,
            config_class=sac_config.SACConfig,
            defaults={"algo": name, **fields},
            task_defaults=sac_config.ADARL_TASK_DEFAULTS if name in ADARL_SCHEDULE else {},
            presets=sac_config.PRESETS,
            default_preset="paper",
            legacy_fields={"lr_schedule": "restart"},
            retired_fields=SAC_RETIRED,
            budget_rules=sac_config.budget_rules(name),
            **SAC_FAMILY_ROLES.get(name, {}),
        )
        for name, fields in SAC_FAMILY.items()
    },
    "rnac": Algorithm(
        name="rnac",
        config_class=rnac_config.RNACConfig,
        defaults={},
        task_defaults={},
        presets=rnac_config.PRESETS,
        default_preset="default",
        best_checkpoint=True,
    ),
}
ALGOS: tuple[str, ...] = tuple(ALGORITHMS)
# fields added to the configs after run folders had been written without them, with the value
# those runs had: a config.yaml that lacks one keeps that value on resume (`runs.folder`)
#: The key of `Algorithm.task_defaults` for every task outside the paper's four.
OTHER_TASKS = "*"
ADDED_FIELDS = {"backend": "host", "device_solver": "xml", "env_kwargs": "", "env_module": ""}


def get(name: str) -> Algorithm:
    """The algorithm called `name` (one-line UsageError naming the allowed ones otherwise)."""
    return ALGORITHMS[check_choice("algo", name, ALGOS)]


def config_classes() -> list[type]:
    """Every config class, once, in registry order."""
    return list(dict.fromkeys(a.config_class for a in ALGORITHMS.values()))


def report_label(values: Mapping, value: Callable | None = None) -> str:
    """A run's method name in reports, from its config values (`value(field, default)` reads
    them, by default `values.get`); an algorithm without its own labels is its name."""
    value = value or (lambda key, default=None: values.get(key, default))
    algo = str(value("algo"))
    entry = ALGORITHMS.get(algo)
    return entry.report_label(value) if entry and entry.report_label else algo


def reports_best_checkpoint(algo: str) -> bool:
    """May `adarl report --best-checkpoint best` score `algo` at each seed's best checkpoint?"""
    entry = ALGORITHMS.get(algo)
    return bool(entry and entry.best_checkpoint)


def role(algo: str, name: str):
    """The protocol role `name` (adapts_rank, rank_sweep, best_of) of `algo`; False/None for
    an algorithm this version does not know."""
    entry = ALGORITHMS.get(algo)
    return getattr(entry, name) if entry else getattr(Algorithm, name, None)


def field_names(algo: str) -> set[str]:
    return {f.name for f in dataclasses.fields(get(algo).config_class)}


# ---------------------------------------------------------------------------- config resolution
def resolve_config(
    algo: str, preset: str | None = None, flags: Mapping[str, object] = (), check: bool = True
):
    """The validated config of `algo`: class defaults <- the algorithm's fields <- its per-task
    defaults <- `preset` (None: the algorithm's default preset) <- `flags` (field -> value, or
    text as typed on a command line, parsed by the field's type); on a task outside the paper's
    four, the fields of `Algorithm.budget_rules` that neither the preset nor a flag sets follow
    the resolved total_steps. `check=False` skips the validation (`--help` shows the defaults
    of an algorithm that needs a flag, as --rank)."""
    entry = get(algo)
    cls = entry.config_class
    preset = preset or entry.default_preset
    check_choice(f"preset for {algo}", preset, entry.presets)
    hints = typing.get_type_hints(cls)
    values = dict(entry.defaults)
    parsed = {}
    for name, value in dict(flags).items():
        if name not in hints:
            from adarl.device import NOT_ON_DEVICE  # why an algorithm has no --backend

            if name == "backend" and algo in NOT_ON_DEVICE:
                raise UsageError(NOT_ON_DEVICE[algo])
            raise UsageError(f"--{name.replace('_', '-')} does not apply to --algo {algo}")
        parsed[name] = field_value(name, value, type_text(hints[name]))
    task = parsed.get("task", entry.presets[preset].get("task", cls.task))
    values.update(entry.task_defaults.get(task, entry.task_defaults.get(OTHER_TASKS, {})))
    if "max_episode_steps" not in parsed and "max_episode_steps" not in entry.presets[preset]:
        from adarl.envs.tasks import registered_time_limit

        given = {**entry.presets[preset], **parsed}
        limit = registered_time_limit(  # a Gymnasium id's own (Reacher: 50)
            str(task), str(given.get("env_module", "")), given.get("env_kwargs", "")
        )
        if limit:
            values["max_episode_steps"] = limit
    values.update(entry.presets[preset])
    values.update(parsed)
    if follows_budget(task):
        for name, rule in entry.budget_rules.items():
            if name not in parsed and name not in entry.presets[preset]:
                values[name] = rule.value(int(values.get("total_steps", cls.total_steps)))
    if values.get("backend") == "device" and "device_solver" not in values:
        from adarl.device.tasks import default_solver  # 100,4 where it is C's physics

        values["device_solver"] = default_solver(str(task))
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    config = cls(**values)
    return config.validate() if check else config


def record_algo(values: dict, where: str) -> str:
    """The algorithm a run's config.yaml (already read) names; `where` names it in errors."""
    if "algo" not in values:  # every config.yaml adarl has written names it
        raise UsageError(
            f"{where} has no algo: line; put back the run's algorithm, one of {', '.join(ALGOS)}"
        )
    return str(values["algo"])


def check_resumable(values: dict, where: str) -> None:
    """A one-line UsageError if a run's config.yaml (already read) holds a retired field with a
    value adarl no longer trains (`Algorithm.retired_fields`), naming the commit that does."""
    for name, retired in get(record_algo(values, where)).retired_fields.items():
        if name in values and values[name] != retired.today:
            raise UsageError(
                f"{where} has {name}: {values[name]} ({retired.meant}), which this adarl no "
                f"longer trains: evaluate, report and export it here, resume or fork it with "
                f"adarl at commit {retired.last_commit} (git checkout {retired.last_commit})"
            )


def config_from_record(values: dict, where: str):
    """(algo, config) from a run's config.yaml (already read); `where` names it in errors.
    Retired fields are dropped (`check_resumable` says whether the run can go on). The config
    is to train (a resume, a fork, a sweep's check), so its env-module must be one the user
    named: a run folder alone never makes adarl import one (`adarl.envs.tasks.check_named`)."""
    from adarl.envs.tasks import check_named

    check_named(str(values.get("env_module") or ""), where)
    algo = record_algo(values, where)
    entry = get(algo)
    values = {k: v for k, v in values.items() if k not in entry.retired_fields}
    names = field_names(algo)
    unknown = sorted(set(values) - names - set(RUN_RECORD_KEYS))
    if unknown:  # a typo or a hand edit: dropping it silently would change the run
        raise UsageError(
            f"{where} has unknown field {unknown[0]!r}; allowed: the config fields of "
            f"--algo {algo} (adarl train --algo {algo} --help)"
        )
    hints = typing.get_type_hints(entry.config_class)
    kept = {  # each value checked as its flag would be, before validate() checks its range
        k: field_value(k, v, type_text(hints[k]), where) for k, v in values.items() if k in names
    }
    for name, value in entry.legacy_fields.items():
        kept.setdefault(name, value)
    return algo, entry.config_class(**kept).validate()


# ---------------------------------------------------------------------------- help text
def field_help(cls: type) -> dict[str, str]:
    """Each field's meaning, read from the comments next to it in the class body (a subclass's
    comment over its base's, for a redeclared field). The comments are the one place a field is
    explained."""
    out: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if dataclasses.is_dataclass(klass):
            out.update(_class_field_help(klass))
    return out


@functools.cache
def _class_field_help(cls: type) -> dict[str, str]:
    """The help of the fields declared in `cls`'s own body: the comment at the end of the
    field's line, after the comment lines right above it (a `# --- section` line is a heading,
    not help)."""
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):  # no source (a frozen install): no help text
        return {}
    names = {f.name for f in dataclasses.fields(cls)}
    lines = source.splitlines()
    comments: dict[int, str] = {}  # line number (0-based) -> comment text
    code_lines: set[int] = set()
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0] - 1] = tok.string.lstrip("#").strip()
        elif tok.type not in (tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT):
            code_lines.add(tok.start[0] - 1)
    out = {}
    for i, line in enumerate(lines):
        name = line.strip().partition(":")[0]
        if name not in names or line.strip().startswith("#"):
            continue
        above = []
        j = i - 1
        while j >= 0 and j in comments and j not in code_lines:
            if comments[j].startswith("---"):
                break
            above.insert(0, comments[j])
            j -= 1
        parts = [*above, comments[i]] if i in comments and i in code_lines else above
        if parts:
            out[name] = " ".join(parts)
    return out
