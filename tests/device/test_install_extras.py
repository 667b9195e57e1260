"""`pip install -e ".[cuda12]"` / `".[cuda13]"` (pyproject.toml): MJX and JAX's CUDA plugin at the
project's own JAX, the versions constraints.txt pins, so that a GPU machine runs the JAX the CPU
tests ran (the H200 check of 2026-12-04 ran the machine's JAX 0.11.2 instead)."""

import re
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def pins() -> dict[str, str]:
    found = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        name, sep, version = line.split("#")[0].strip().partition("==")
        if sep:
            found[name.lower()] = version.strip()
    return found


@pytest.mark.parametrize("cuda", ["cuda12", "cuda13"])
def test_the_cuda_extras_pin_the_projects_jax_and_mjx(cuda):
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"
    ]
    pinned = pins()
    assert sorted(extras[cuda]) == sorted(
        [f"jax[{cuda}]=={pinned['jax']}", f"mujoco-mjx=={pinned['mujoco-mjx']}"]
    )
    assert pinned["jaxlib"] == pinned["jax"]


@pytest.mark.parametrize("cuda", ["cuda12", "cuda13"])
def test_the_pinned_jax_has_the_extra_with_its_plugin_at_the_same_version(cuda):
    """The installed JAX is constraints.txt's; its metadata declares the extra, which pulls the
    CUDA plugin and jaxlib at exactly that version."""
    version = pins()["jax"]
    assert metadata.version("jax") == version
    wanted = [r for r in metadata.requires("jax") or [] if f'extra == "{cuda}"' in r]
    plugin = [r for r in wanted if r.startswith(f"jax-{cuda}-plugin")]
    assert plugin and all(re.search(rf"[<>]=\s*{re.escape(version)}\b", r) for r in wanted)
