"""`adarl export`: one seed's policy as a NumPy-only file, with parameter counts."""

import numpy as np

from adarl.cli.main import main
from adarl.evaluation.synthetic import write_run
from adarl.policy import load


def test_export_writes_a_loadable_policy_and_reports_sizes(tmp_path, capsys):
    run = write_run(tmp_path, "r", algo="sac-fixed-rank", rank=2, seeds=(3, 4))
    out = tmp_path / "exported" / "policy.npz"
    assert main(["export", str(run), "--seed", "4", "--out", str(out)]) == 0
    source = run / "checkpoints" / "step_000000010000" / "policy_seed_4.npz"
    assert out.read_bytes() == source.read_bytes()
    assert load(out)(np.zeros(11, np.float32)).shape == (3,)
    text = capsys.readouterr().out
    assert "seed 4" in text and "parameters:" in text and "full rank:" in text and "% kept" in text
    assert main(["export", str(run), "--out", str(tmp_path / "default.npz")]) == 0
    assert "seed 3" in capsys.readouterr().out  # default: the lowest seed


def test_export_bad_input(tmp_path, capsys):
    run = write_run(tmp_path, "r", seeds=(0,))
    assert main(["export", str(run), "--seed", "9", "--out", str(tmp_path / "p.npz")]) == 2
    assert "has no seed 9; it has seeds: 0" in capsys.readouterr().err
    bare = write_run(tmp_path, "bare", checkpoint=False)
    assert main(["export", str(bare), "--out", str(tmp_path / "p.npz")]) == 2
    assert "has no complete checkpoint" in capsys.readouterr().err
    assert main(["export", str(tmp_path), "--out", str(tmp_path / "p.npz")]) == 2
    assert "is not a run folder" in capsys.readouterr().err
    assert not (tmp_path / "p.npz").exists()
