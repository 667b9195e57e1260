"""`adarl --version`, `--help` and usage errors answer at once: they import none of the heavy
libraries (JAX, MuJoCo, Gymnasium, pandas, matplotlib, ...), which a command imports only where
it needs them (`adarl.cli.main` adds the arguments of the one command it is given). And `import
adarl` still registers the Gymnasium ids, now when Gymnasium is imported (`adarl/__init__.py`)."""

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

import adarl

HEAVY = ("jax", "mujoco", "gymnasium", "pandas", "matplotlib", "scipy", "optax", "ray", "wandb")
#: --version and --help need not even NumPy or PyYAML
NOTHING_BUT_ADARL = (*HEAVY, "numpy", "yaml")

SCRIPT = """
import json, sys
from adarl.cli.main import main
try:
    code = main({argv!r})
except SystemExit as exc:  # argparse's --version, --help and errors exit
    code = exc.code
print(json.dumps({{"code": code, "loaded": sorted(m for m in {names!r} if m in sys.modules)}}))
"""


def _start(argv: list[str], names, cwd) -> tuple[int, list[str], str]:
    """Run `adarl ARGV` in a fresh interpreter: (exit code, which of `names` it imported, stderr)."""
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT.format(argv=argv, names=tuple(names))],
        capture_output=True,
        text=True,
        cwd=cwd,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    return result["code"], result["loaded"], done.stderr


@pytest.mark.parametrize(
    ("argv", "code"),
    [(["--version"], 0), (["--help"], 0), ([], 2), (["theory", "--help"], 0)],
)
def test_version_and_help_import_nothing_heavy(tmp_path, argv, code):
    assert _start(argv, NOTHING_BUT_ADARL, tmp_path)[:2] == (code, [])


@pytest.mark.parametrize(
    ("argv", "bad"),
    [
        (["nosuch"], "nosuch"),
        (["train", "--task", "nosuch"], "nosuch"),
        (["train", "--seeds", "x"], "'x'"),
        (["train", "--algo", "nosuch"], "nosuch"),
        (["tasks", "nosuch"], "nosuch"),
        (["sweep", "nosuch"], "nosuch"),
        (["train", "--no-such-flag"], "--no-such-flag"),
    ],
)
def test_a_usage_error_is_one_line_and_imports_nothing_heavy(tmp_path, argv, bad):
    code, loaded, stderr = _start(argv, HEAVY, tmp_path)
    assert (code, loaded) == (2, []), stderr
    assert len(stderr.strip().splitlines()) == 1 and bad in stderr, stderr


def test_train_help_imports_nothing_heavy(tmp_path):
    code, loaded, _ = _start(["train", "--algo", "sac", "--help"], HEAVY, tmp_path)
    assert (code, loaded) == (0, [])


REGISTRATION = """
import sys
{first}
import gymnasium
assert gymnasium.spec("adarl/Hopper-v0").kwargs == {{"task": "hopper"}}
assert sorted(i for i in gymnasium.registry if i.startswith("adarl/")) == [
    "adarl/Ant-v0", "adarl/Hopper-v0", "adarl/Humanoid-v0", "adarl/Walker2d-v0"
]
"""


@pytest.mark.parametrize(
    "first",
    [
        "import adarl; assert 'gymnasium' not in sys.modules and 'numpy' not in sys.modules",
        "import gymnasium, adarl",  # Gymnasium loaded first: registered by `import adarl`
        "from adarl.envs.registration import IDS",  # the module that imports Gymnasium itself
        "import importlib.util, adarl; importlib.util.find_spec('gymnasium')",  # a look, no load
    ],
)
def test_import_adarl_still_registers_the_gymnasium_ids(tmp_path, first):
    code = REGISTRATION.format(first=first)
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr[-2000:]


def _imports_gymnasium_at_the_top(path: Path) -> bool:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return any(
        (
            isinstance(node, ast.Import)
            and any(a.name.split(".")[0] == "gymnasium" for a in node.names)
        )
        or (isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "gymnasium")
        for node in tree.body
    )


PACKAGE = Path(adarl.__file__).parent
#: the modules whose import loads Gymnasium first (the registration then runs in the middle of
#: their import), and the one the registration reads its tasks from
FIRST_TO_LOAD_GYMNASIUM = sorted(
    {
        "adarl." + ".".join(p.relative_to(PACKAGE).with_suffix("").parts)
        for p in PACKAGE.rglob("*.py")
        if p.name != "__init__.py" and _imports_gymnasium_at_the_top(p)
    }
    | {"adarl.envs.tasks"}
)


@pytest.mark.parametrize("module", FIRST_TO_LOAD_GYMNASIUM)
def test_the_ids_are_registered_whichever_module_loads_gymnasium(tmp_path, module):
    """A module that imports Gymnasium at its top starts the registration in the middle of its
    own import: nothing the registration needs may be half-imported then."""
    code = REGISTRATION.format(first=f"import adarl; import {module}")
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr[-2000:]
