"""`adarl theory` end to end on a tiny grid, and its bad-input errors."""

import csv
import json

import pytest

from adarl.cli.main import main
from adarl.theory.synthetic import COLUMNS

TINY = [
    "--d", "5", "--r0", "2", "--eps", "0", "0.1", "--draws", "3",
    "--mdp-states", "4", "--mdp-actions", "2", "--mdp-core", "1", "--mdp-d", "4",
]  # fmt: skip


def test_cli_end_to_end(tmp_path, capsys):
    out = tmp_path / "theory"
    assert main(["theory", "--out", str(out), *TINY]) == 0
    stdout = capsys.readouterr().out
    assert "synthetic: r° = 2" in stdout and "mdp: r° = 2" in stdout
    names = {p.name for p in out.iterdir()}
    expected = {"synthetic.csv", "mdp.csv", "picard.csv", "summary.json"}
    for stem in ("synthetic_error", "synthetic_bound", "mdp_error", "mdp_bound", "picard"):
        expected |= {f"{stem}.png", f"{stem}.pdf"}
    assert names == expected  # and no temp files left behind
    for stem in ("synthetic", "mdp"):
        with open(out / f"{stem}.csv") as f:
            rows = list(csv.DictReader(f))
        assert list(rows[0]) == COLUMNS
        assert len(rows) == 2 * (5 if stem == "synthetic" else 4)
        for row in rows:
            assert float(row["error_mean"]) <= float(row["bound"]) * (1 + 1e-5)
    assert (out / "synthetic_error.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "mdp_bound.pdf").read_bytes()[:5] == b"%PDF-"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["synthetic"]["per_eps"][0]["best_r"] == 2
    assert summary["synthetic"]["per_eps"][0]["bound_violations"] == 0
    assert summary["mdp"]["r0"] == 2


@pytest.mark.parametrize(
    "flags, needle",
    [
        (["--d", "4", "--r0", "5"], "--r0 5"),
        (["--p", "1"], "--p 1.0"),
        (["--p", "0.5"], "--p 0.5"),
        (["--eps", "0", "-0.1"], "--eps -0.1"),
        (["--eps", "2"], "--eps 2.0"),
        (["--draws", "0"], "--draws 0"),
        (["--d", "0"], "--d 0"),
        (["--kappa", "nan"], "--kappa nan"),
        (["--mdp-states", "4", "--mdp-core", "4"], "--mdp-core 4"),
        (["--mdp-d", "100"], "--mdp-d 100"),
        (["--gamma", "1"], "--gamma 1.0"),
    ],
)
def test_cli_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, flags, needle):
    out = tmp_path / "theory"
    assert main(["theory", "--out", str(out), *flags]) == 2
    err = capsys.readouterr().err
    assert err.startswith("adarl theory: error: ") and needle in err
    assert err.count("\n") == 1
    assert not out.exists()


def test_cli_out_must_be_a_folder(tmp_path, capsys):
    target = tmp_path / "file.txt"
    target.write_text("x")
    assert main(["theory", "--out", str(target)]) == 2
    assert "--out" in capsys.readouterr().err
    assert target.read_text() == "x"


def test_cli_non_numeric_flag_is_an_argparse_error(tmp_path):
    with pytest.raises(SystemExit) as info:
        main(["theory", "--out", str(tmp_path / "o"), "--d", "four"])
    assert info.value.code == 2
