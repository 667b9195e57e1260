"""No module imports from a higher layer (README, "Code map"): the maths never reaches for the
training loop, the loops never for the evaluation or the CLI, and so on. Imports inside functions
count too."""

import ast
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
# `adarl` itself only sets `__version__` and registers the Gymnasium ids
EXEMPT = {("__init__", "envs")}


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
