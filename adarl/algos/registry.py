"""Every algorithm by name: its config class, the fields that define it, its per-task defaults,
its presets and its trainer. The CLI, the sweeps and the report read this table; adding an
algorithm is a new maths file in `adarl/algos`, a trainer in `adarl/train` and one entry here
(docs/algorithms.md, "Adding an algorithm").

A config is resolved in one order everywhere (`resolve_config`): the config class's defaults
<- the algorithm's defining fields <- its per-task defaults <- the preset <- the flags.

The table names the config classes, presets and trainers as "module:attribute" and imports them
when asked, so reading it (the report, `adarl --help`) does not load JAX.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import inspect
import io
import tokenize
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from adarl.algos.flags import parse_value, type_text
from adarl.errors import UsageError, check_choice

# keys config.yaml holds beside the config fields (docs/run-format.md)
RUN_RECORD_KEYS = ("algo", "format_version", "adarl_version", "command", "fork")


def _load(path: str):
    module, _, attribute = path.partition(":")
    return getattr(importlib.import_module(module), attribute)


@dataclass(frozen=True)
class Algorithm:
    name: str
    config: str  # "module:Class" of its config dataclass
    # config fields that define the algorithm (applied before presets and flags)
    defaults: Mapping[str, object]
    # task -> fields, below the preset and the flags (a budget where the user sets none)
    task_defaults: Mapping[str, Mapping[str, object]]
    preset_table: str  # "module:DICT" of its presets (name -> fields)
    default_preset: str
    # "module:function" of the trainer, train(config, run_dir, resume, progress, command); named,
    # not imported, because `adarl/train` sits above `adarl/algos`
    trainer: str
    # fields a config.yaml written before they existed is read with (their value back then)
    legacy_fields: Mapping[str, object] = field(default_factory=dict)
    # the trainer keeps each seed's best policy by evaluation beside the final one (docs/run-format.md)
    best_policy: bool = False
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

    @property
    def config_class(self) -> type:
        return _load(self.config)

    @property
    def presets(self) -> Mapping[str, Mapping[str, object]]:
        return _load(self.preset_table)


# ---------------------------------------------------------------------------- report labels
# AdaRL's default rank rule and threshold: runs with them are labelled plain `adarl`
DEFAULT_RANK_RULE = "energy"
DEFAULT_BETA = 0.98


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
# the SAC family: configurations of adarl/algos/sac.py, trained by adarl/train/sac_learner.py
SAC_FAMILY: dict[str, dict] = {
    "sac": {},
    "adarl": {"bottleneck": ("actor:1", "critic:1"), "adapt_rank": True},
    # AdaRL's schedule-matched control: the same truncations (SVD re-parameterisation, resets,
    # warm-up), the rule's rank logged but never applied (docs/algorithms.md)
    "adarl-control": {
        "bottleneck": ("actor:1", "critic:1"),
        "adapt_rank": True,
        "apply_cuts": False,
    },
    "sac-fixed-rank": {"bottleneck": ("actor:1", "critic:1"), "adapt_rank": False},
    "sac-parseval": {"parseval_coef": 1e-4, "init": "orthogonal"},
    "sac-sparse": {"sparse_width": 1024},
}

SAC_FAMILY_ROLES: dict[str, dict] = {
    "adarl": {"report_label": _adarl_label, "adapts_rank": True},
    "adarl-control": {"report_label": _adarl_label, "control_of": "adarl"},
    "sac-fixed-rank": {"report_label": _fixed_rank_label, "rank_sweep": True},
    "sac-parseval": {"best_of": "parseval_coef"},
    "sac-sparse": {"report_label": _sparse_label},
}

# AdaRL's budget where the user sets none (no --total-steps / --truncate-every, flag or preset):
# the paper's d_t (10⁶ gradient steps, 0.7·10⁶ on Walker2d) and the `paper-table1` step budgets,
# so that a default run truncates (Hopper 2, the others 4 times); a flat 10⁶ steps would not.
TASK_DEFAULTS: dict[str, dict[str, dict]] = {
    "adarl": {
        "hopper": {"total_steps": 3_000_000, "truncate_every": 1_000_000},
        "walker2d": {"total_steps": 3_000_000, "truncate_every": 700_000},
        "ant": {"total_steps": 5_000_000, "truncate_every": 1_000_000},
        "humanoid": {"total_steps": 5_000_000, "truncate_every": 1_000_000},
    },
}
TASK_DEFAULTS["adarl-control"] = TASK_DEFAULTS["adarl"]  # the control runs AdaRL's schedule

ALGORITHMS: dict[str, Algorithm] = {
    **{
        name: Algorithm(
            name=name,
            config="adarl.algos.sac:SACConfig",
            defaults={"algo": name, **fields},
            task_defaults=TASK_DEFAULTS.get(name, {}),
            preset_table="adarl.algos.sac:PRESETS",
            default_preset="paper",
            trainer="adarl.train.sac_learner:train",
            legacy_fields={"lr_schedule": "restart"},
            **SAC_FAMILY_ROLES.get(name, {}),
        )
        for name, fields in SAC_FAMILY.items()
    },
    "rnac": Algorithm(
        name="rnac",
        config="adarl.algos.rnac:RNACConfig",
        defaults={},
        task_defaults={},
        preset_table="adarl.algos.rnac:PRESETS",
        default_preset="default",
        trainer="adarl.train.rnac_learner:train",
        best_policy=True,
    ),
}
ALGOS: tuple[str, ...] = tuple(ALGORITHMS)
# the algorithm of a config.yaml without an `algo` key (none written by adarl so far)
LEGACY_ALGO = "rnac"


def get(name: str) -> Algorithm:
    """The algorithm called `name` (one-line UsageError naming the allowed ones otherwise)."""
    return ALGORITHMS[check_choice("algo", name, ALGOS)]


def trainer(algo: str) -> Callable:
    """The algorithm's `train(config, run_dir, resume=False, progress=True, command="")`."""
    return _load(get(algo).trainer)


def config_classes() -> list[type]:
    """Every config class, once, in registry order."""
    return [_load(path) for path in dict.fromkeys(a.config for a in ALGORITHMS.values())]


def report_label(values: Mapping, value: Callable | None = None) -> str:
    """A run's method name in reports, from its config values (`value(field, default)` reads
    them, by default `values.get`); an algorithm without its own labels is its name."""
    value = value or (lambda key, default=None: values.get(key, default))
    algo = str(value("algo"))
    entry = ALGORITHMS.get(algo)
    return entry.report_label(value) if entry and entry.report_label else algo


def keeps_best_policy(algo: str) -> bool:
    entry = ALGORITHMS.get(algo)
    return bool(entry and entry.best_policy)


def role(algo: str, name: str):
    """The protocol role `name` (adapts_rank, rank_sweep, best_of) of `algo`; False/None for
    an algorithm this version does not know."""
    entry = ALGORITHMS.get(algo)
    return getattr(entry, name) if entry else getattr(Algorithm, name, None)


def field_names(algo: str) -> set[str]:
    return {f.name for f in dataclasses.fields(get(algo).config_class)}


def algo_of(config) -> str:
    """The registered name of a config's algorithm."""
    name = getattr(config, "algo", None)
    if name in ALGORITHMS:
        return name
    return next(a.name for a in ALGORITHMS.values() if isinstance(config, a.config_class))


# ---------------------------------------------------------------------------- config resolution
def resolve_config(algo: str, preset: str | None = None, flags: Mapping[str, object] = ()):
    """The validated config of `algo`: class defaults <- the algorithm's fields <- its per-task
    defaults <- `preset` (None: the algorithm's default preset) <- `flags` (field -> value, or
    text as typed on a command line, parsed by the field's type)."""
    entry = get(algo)
    cls = entry.config_class
    preset = preset or entry.default_preset
    check_choice(f"preset for {algo}", preset, entry.presets)
    hints = typing.get_type_hints(cls)
    values = dict(entry.defaults)
    parsed = {}
    for name, value in dict(flags).items():
        if name not in hints:
            raise UsageError(f"--{name.replace('_', '-')} does not apply to --algo {algo}")
        parsed[name] = (
            parse_value(name, value, type_text(hints[name])) if isinstance(value, str) else value
        )
    task = parsed.get("task", entry.presets[preset].get("task", cls.task))
    values.update(entry.task_defaults.get(task, {}))
    values.update(entry.presets[preset])
    values.update(parsed)
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return cls(**values).validate()


def config_from_record(values: dict, where: str):
    """(algo, config) from a run's config.yaml (already read); `where` names it in errors."""
    algo = values.get("algo", LEGACY_ALGO)
    entry = get(algo)
    names = field_names(algo)
    unknown = sorted(set(values) - names - set(RUN_RECORD_KEYS))
    if unknown:  # a typo or a hand edit: dropping it silently would change the run
        raise UsageError(
            f"{where} has unknown field {unknown[0]!r}; allowed: the config fields of "
            f"--algo {algo} (adarl train --help)"
        )
    kept = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items() if k in names}
    for name, value in entry.legacy_fields.items():
        kept.setdefault(name, value)
    return algo, entry.config_class(**kept).validate()


# ---------------------------------------------------------------------------- help text
@functools.cache
def field_help(cls: type) -> dict[str, str]:
    """Each field's meaning, read from the comments next to it in the class body: the comment
    at the end of the field's line, after the comment lines right above it (a `# --- section`
    line is a heading, not help). The comments are the one place a field is explained."""
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
