"""No module imports from a higher layer (docs/architecture.md, "Code map"): the maths never
reaches for the training loop, the loops never for the evaluation or the CLI, and so on; and no
two modules of one package import each other, directly or round a loop. Imports inside
functions count too. Nothing is imported by a string, which would hide an edge from this test."""

import ast
import re
from pathlib import Path

import adarl

PACKAGE = Path(adarl.__file__).parent
# lowest first; a module may import from its own layer and the layers before it
LAYERS = [
    # stats: the statistics of comparisons (NumPy and SciPy), imports no adarl module
    {"__init__", "__version__", "errors", "runtime", "files", "policy", "executor", "schedules"}
    | {"stats"},
    {"envs", "device"},  # device: the same tasks as pure JAX functions (MJX)
    {"lowrank"},  # the public rank-adaptation module: JAX and optax only, imports no adarl module
    {"nets"},
    {"algos"},
    {"runs"},
    {"train"},
    # results: reading finished run folders into tables (pandas) for everything after training.
    # It needs more than the run format's ONLY allows (the NumPy policy, the config-flag parser)
    # and the training loop never reads a run back, so it sits above train, not inside runs.
    {"results"},
    # evaluation: the engine that rolls policies out under perturbed physics; export: a policy
    # out of a run as a NumPy file or a video
    {"evaluation", "export", "theory"},
    {"report"},  # tables, figures, statistics sections, the end-of-training summary
    {"sweeps"},
    {"cli"},
    # api: `adarl.train(...)` and friends, the CLI's jobs as Python calls (it runs the CLI's own
    # argument checks, so it sits above the CLI)
    {"api"},
]
# `adarl` itself only sets `__version__` and registers the Gymnasium ids
EXEMPT = {("__init__", "envs")}
# the Python API's two doors, resolved at call time: `adarl.evaluate` and friends (adarl's
# `__getattr__`) and `adarl.train(...)` (the train package is callable); nothing else reaches it
# (these two modules only, not the packages under them)
FACADES = {("__init__", "api"), ("train", "api")}
# of the layers below it, the run format reads only the ground floor and the algorithm registry
# (JAX-free: it turns a config.yaml back into a config), never the environments or the maths
ONLY = {"runs": {"__init__", "__version__", "errors", "files", "algos.registry"}}
# reading run folders needs the run format, the algorithm registry and config flags (JAX-free)
# and the NumPy policy, never the environments, the networks, the maths or the training loop
ONLY["results"] = ONLY["runs"] | {"policy", "algos.flags", "runs"}


def _layer(part: str) -> int:
    for i, names in enumerate(LAYERS):
        if part in names:
            return i
    raise AssertionError(f"adarl.{part} is in no layer of LAYERS; add it")


def _module(path: Path) -> str:
    """`train.loop` for adarl/train/loop.py, `train` for adarl/train/__init__.py."""
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" and len(parts) > 1 else parts)


MODULES = {_module(p) for p in PACKAGE.rglob("*.py")}


def _imports(path: Path):
    """The adarl modules `path` imports, as `_module` names (`from adarl.train import fork`:
    `train.fork`; a name that is not a module: the module it comes from)."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("adarl"):
            base = node.module.split(".")[1:]
            for alias in node.names:
                full = ".".join([*base, alias.name])
                yield full if full in MODULES or not base else ".".join(base)
        elif isinstance(node, ast.Import):
            yield from (a.name.split(".", 1)[1] for a in node.names if a.name.startswith("adarl."))


GRAPH = {_module(p): set(_imports(p)) for p in sorted(PACKAGE.rglob("*.py"))}


def test_no_module_imports_a_higher_layer():
    found = []
    for module, targets in GRAPH.items():
        top = module.split(".")[0]
        for target in sorted(targets):
            head = target.split(".")[0]
            if (module, head) in EXEMPT | FACADES or (top, head) in EXEMPT:
                continue
            if _layer(head) > _layer(top):
                found.append(f"adarl.{module} imports adarl.{target}")
            elif head != top and top in ONLY and target not in ONLY[top] and head not in ONLY[top]:
                found.append(f"adarl.{module} imports adarl.{target} (not in ONLY[{top!r}])")
    assert not found, "; ".join(found)


def test_no_import_cycle_inside_a_package():
    """Modules of one package (`train.io` and `train.provenance` once) form no import cycle."""

    def package(module: str) -> str:
        return module.rpartition(".")[0]

    edges = {
        m: {t for t in targets if t != m and package(t) == package(m) and package(m)}
        for m, targets in GRAPH.items()
    }
    cycles, state = [], {}  # state: 1 on the current path, 2 done

    def visit(module: str, path: list[str]) -> None:
        state[module] = 1
        for target in sorted(edges.get(module, ())):
            if state.get(target) == 1:
                loop = [*path[path.index(target) :], target]
                cycles.append(" -> ".join(f"adarl.{m}" for m in loop))
            elif target not in state:
                visit(target, [*path, target])
        state[module] = 2

    for module in sorted(edges):
        if module not in state:
            visit(module, [module])
    assert not cycles, "import cycles: " + "; ".join(cycles)


# the one computed import: the module a user names with --env-module to register their own ids
USER_MODULE_IMPORTS = {("envs/tasks.py", "import_env_module")}
MODULE_ATTR = re.compile(r"^adarl(\.\w+)+:\w+$")  # "adarl.train.sac_loop:train"


def _string_imports(path: Path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    where = path.relative_to(PACKAGE).as_posix()
    allowed = {
        id(call)
        for fn in ast.walk(tree)
        if isinstance(fn, ast.FunctionDef) and (where, fn.name) in USER_MODULE_IMPORTS
        for call in ast.walk(fn)
    }
    # Gymnasium's registry takes its entry points as "module:attr" (adarl/envs/registration.py)
    gymnasium_ids = {
        id(k.value) for k in ast.walk(tree) if isinstance(k, ast.keyword) and k.arg == "entry_point"
    }
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            name = node.func.attr if isinstance(node.func, ast.Attribute) else ""
            name = node.func.id if isinstance(node.func, ast.Name) else name
            literal = node.args and isinstance(node.args[0], ast.Constant)
            if name in ("import_module", "__import__") and not literal and id(node) not in allowed:
                yield f"line {node.lineno}: {name} of a computed name"
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            if MODULE_ATTR.match(node.value) and id(node) not in gymnasium_ids:
                yield f"line {node.lineno}: {node.value!r}"


def test_no_module_imports_by_string():
    """Code is referenced by import, so that the graph above is the whole graph: no
    `importlib.import_module` of a computed name, no "module:attribute" tables."""
    found = [
        f"adarl/{path.relative_to(PACKAGE)} {where}"
        for path in sorted(PACKAGE.rglob("*.py"))
        for where in _string_imports(path)
    ]
    assert not found, "; ".join(found)


def test_learners_do_not_reach_into_the_loop():
    """The loop drives a learner one way (`adarl.train.learner`): no learner imports the loop,
    its logs, the run folder or the file writers; it returns what the loop writes."""
    learners = [m for m in GRAPH if m.startswith("train.") and m.endswith("_learner")]
    assert learners
    forbidden = {"train.loop", "runs.logs", "runs.folder", "runs.lock", "runs.provenance", "files"}
    found = [f"adarl.{m} imports adarl.{t}" for m in learners for t in GRAPH[m] if t in forbidden]
    assert not found, "; ".join(found)
