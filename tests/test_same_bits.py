"""bench/same_bits.py: the bit-for-bit check behind every change to code a running experiment
uses. Its training runs are smoke runs; here, the comparison and its refusal to compare a commit
with itself, on hand-written run folders."""

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def same_bits():
    spec = importlib.util.spec_from_file_location("same_bits", ROOT / "bench" / "same_bits.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(root: Path, commit: str, dirty=False, returns=(1.0, 2.0), weight=0.5) -> Path:
    run = root / "adarl"
    run.mkdir(parents=True)
    (run / "environment.json").write_text(
        json.dumps({"adarl": {"git_commit": commit, "git_dirty": dirty}})
    )
    rows = "".join(f"{i},{r},{0.1 * i}\n" for i, r in enumerate(returns))
    (run / "eval.csv").write_text("step,return,wall_s\n" + rows)
    np.savez(run / "policy.npz", w=np.array([weight, 1.0], np.float32))
    return root


def _main(same_bits, monkeypatch, *argv) -> int:
    monkeypatch.setattr(sys, "argv", ["same_bits.py", *argv])
    return same_bits.main()


def test_identical_runs_of_two_commits_pass(same_bits, tmp_path, monkeypatch, capsys):
    old, new = _run(tmp_path / "old", "a" * 40), _run(tmp_path / "new", "b" * 40)
    (new / "adarl" / "eval.csv").write_text("step,return,wall_s\n0,1.0,9\n1,2.0,9\n")  # timing
    assert _main(same_bits, monkeypatch, "compare", str(old), str(new)) == 0
    assert capsys.readouterr().out.splitlines()[-1] == "bit-identical"


def test_a_changed_row_or_array_is_a_difference(same_bits, tmp_path):
    old = _run(tmp_path / "old", "a" * 40)
    new = _run(tmp_path / "new", "b" * 40, returns=(1.0, 2.5), weight=0.5000001)
    differences, added = same_bits.compare(old, new)
    assert differences == ["adarl/eval.csv: rows differ", "adarl/policy.npz: w differs"]
    assert added == []


def test_both_sides_of_one_commit_compare_nothing(same_bits, tmp_path, monkeypatch, capsys):
    old, new = _run(tmp_path / "old", "a" * 40), _run(tmp_path / "new", "a" * 40)
    assert _main(same_bits, monkeypatch, "compare", str(old), str(new)) == 2
    assert "same commit: nothing was compared" in capsys.readouterr().out
    dirty = _run(tmp_path / "dirty", "a" * 40, dirty=True)  # uncommitted changes: compared
    assert _main(same_bits, monkeypatch, "compare", str(old), str(dirty)) == 0
    assert same_bits.commits(dirty) == {"a" * 40 + "+dirty"}


def test_runs_use_the_code_they_are_given(same_bits, tmp_path):
    """`train --code DIR` runs DIR's adarl even from a checkout (here: the tests' working folder,
    whose own adarl `python -m` would otherwise import first)."""
    code = tmp_path / "old-checkout"
    (code / "adarl" / "cli").mkdir(parents=True)
    (code / "adarl" / "__init__.py").write_text("")
    (code / "adarl" / "cli" / "__init__.py").write_text("")
    (code / "adarl" / "cli" / "main.py").write_text(
        "import sys, pathlib, adarl\n"
        "out = pathlib.Path(sys.argv[sys.argv.index('--out') + 1])\n"
        "out.mkdir(parents=True)\n"
        "(out / 'imported').write_text(adarl.__file__)\n"
    )
    same_bits.train(tmp_path / "bits", ["sac"], code=code)
    imported = Path((tmp_path / "bits" / "sac" / "imported").read_text())
    assert imported == code / "adarl" / "__init__.py"
