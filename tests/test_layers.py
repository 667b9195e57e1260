"""No module imports from a higher layer (README, "Code map"): the maths never reaches for the
training loop, the loops never for the evaluation or the CLI, and so on. Imports inside functions
count too. Nothing is imported by a string, which would hide an edge from this test."""

import ast
import re
from pathlib import Path

import adarl

PACKAGE = Path(adarl.__file__).parent
# lowest first; a module may import from its own layer and the layers before it
LAYERS = [
    {"__init__", "__version__", "errors", "runtime", "files", "policy", "cluster"},
    {"envs"},
    {"nets"},
    {"algos"},
    {"train"},
    {"evaluation", "theory"},
    {"sweeps"},
    {"cli"},
]
# `adarl` itself only sets `__version__` and registers the Gymnasium ids; a sweep worker is a
# process entry point that runs `adarl train` as the CLI does
EXEMPT = {("__init__", "envs"), ("sweeps.worker", "cli")}


def _layer(part: str) -> int:
    for i, names in enumerate(LAYERS):
        if part in names:
            return i
    raise AssertionError(f"adarl.{part} is in no layer of LAYERS; add it")


def _imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("adarl"):
            parts = node.module.split(".")
            names = [parts[1]] if len(parts) > 1 else [a.name for a in node.names]
            yield from names
        elif isinstance(node, ast.Import):
            yield from (a.name.split(".")[1] for a in node.names if a.name.startswith("adarl."))


def test_no_module_imports_a_higher_layer():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = ".".join(path.relative_to(PACKAGE).with_suffix("").parts)
        top = module.split(".")[0]
        for target in _imports(path):
            if (module, target) in EXEMPT or (top, target) in EXEMPT:
                continue
            if _layer(target) > _layer(top):
                found.append(f"adarl.{module} imports adarl.{target}")
    assert not found, "; ".join(found)


MODULE_ATTR = re.compile(r"^adarl(\.\w+)+:\w+$")  # "adarl.train.sac_loop:train"


def _string_imports(path: Path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    # Gymnasium's registry takes its entry points as "module:attr" (adarl/envs/registration.py)
    gymnasium_ids = {
        id(k.value) for k in ast.walk(tree) if isinstance(k, ast.keyword) and k.arg == "entry_point"
    }
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            name = node.func.attr if isinstance(node.func, ast.Attribute) else ""
            name = node.func.id if isinstance(node.func, ast.Name) else name
            literal = node.args and isinstance(node.args[0], ast.Constant)
            if name in ("import_module", "__import__") and not literal:
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
