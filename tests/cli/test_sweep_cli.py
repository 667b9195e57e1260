"""`adarl sweep --help` names every shipped preset (read from the preset folder, not a list)."""

import re

import pytest

from adarl.cli.main import main
from adarl.sweeps.spec import PRESET_DIR


def test_help_lists_every_preset(capsys):
    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    out = capsys.readouterr().out
    listed = out.split("presets:", 1)[1].split("examples:", 1)[0]
    names = set(re.split(r"[,\s]+", listed.strip()))
    shipped = {p.stem for p in PRESET_DIR.glob("*.yaml")}
    assert "repro-walker2d" in shipped
    assert names == shipped
