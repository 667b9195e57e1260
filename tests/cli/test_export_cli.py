"""`adarl export`: one seed's policy as a NumPy-only file, with parameter counts."""

import numpy as np
from synthetic_runs import write_run

from adarl.cli.main import main
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


def test_export_counts_full_rank_at_the_configured_width_even_from_old_policy_files(
    tmp_path, capsys
):
    """Policy files of earlier versions recorded `n_params_full` at the compacted width (the
    largest rank across seeds); the full-rank size comes from the shapes instead: obs 11 → 16,
    a 16·16 + 16·16 bottleneck with bias, 16 → 3, counted by hand."""
    from synthetic_runs import policy_arrays

    arrays = policy_arrays(11, 3, hidden=16, rank=2)
    arrays["n_params_full"] = np.array(999)  # what an older adarl may have written
    source = tmp_path / "old.npz"
    np.savez(source, **arrays)
    full = (11 * 16 + 16) + (16 * 16 + 16 * 16 + 16) + (16 * 3 + 3)
    kept = (11 * 16 + 16) + (16 * 2 + 2 * 16 + 16) + (16 * 3 + 3)
    assert load(source).n_params_full() == full
    assert load(source).n_params() == kept
