"""docs/experiments/campaign.sh, the campaign's driver, with a stand-in for Python that records
each command and answers with a chosen exit status: the sweeps in issue 34's order, the robustness
evaluation right after the Walker2d sweep until both runs have it, and a stop that ends it all."""

import os
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).parents[2] / "docs/experiments/campaign.sh"
PRESETS = ("table1-ant-humanoid", "paper-schedule-walker2d", "fixed-rank-power")


def _campaign(tmp_path: Path, exits: dict[str, int] | None = None) -> tuple[int, list[str]]:
    """Run the script; the stand-in exits with exits[word] when a word of its command is a key
    (a preset, or `evaluate`), else 0. Returns the exit status and the commands, in order."""
    log = tmp_path / "commands"
    cases = "".join(f'    *" {word} "*) code={code} ;;\n' for word, code in (exits or {}).items())
    python = tmp_path / "python"
    python.write_text(
        "#!/usr/bin/env bash\n"
        f'echo "$*" >> {log}\n'
        "code=0\n"
        f'case " $* " in\n{cases}esac\n'
        "exit $code\n"
    )
    python.chmod(0o755)
    env = {
        **os.environ,
        "CAMPAIGN_CODE": str(tmp_path),
        "CAMPAIGN_PYTHON": str(python),
        "CAMPAIGN_RESULTS": str(tmp_path / "results"),
    }
    done = subprocess.run(["bash", str(SCRIPT)], env=env, capture_output=True, text=True)
    commands = log.read_text().splitlines() if log.exists() else []
    return done.returncode, [c.removeprefix("-m adarl.cli.main ") for c in commands]


def _sweep(tmp_path: Path, preset: str) -> str:
    out = tmp_path / "results" / preset
    return f"sweep {preset} --out {out} --workers 2 --no-progress"


def _robustness(tmp_path: Path) -> str:
    w = tmp_path / "results/paper-schedule-walker2d/walker2d"
    return (
        f"evaluate {w}/adarl_rank_rule-cumulative/seeds-0-4 {w}/sac/seeds-0-4 --suite paper "
        "--episodes 5 --workers 2 --no-progress"
    )


def test_the_sweeps_in_order_with_the_robustness_evaluation_after_walker2d(tmp_path):
    code, commands = _campaign(tmp_path)
    assert code == 0
    assert commands == [
        _sweep(tmp_path, PRESETS[0]),
        _sweep(tmp_path, PRESETS[1]),
        _robustness(tmp_path),
        _sweep(tmp_path, PRESETS[2]),
    ]


def test_a_finished_robustness_evaluation_is_not_repeated_and_a_half_one_is(tmp_path):
    w = tmp_path / "results/paper-schedule-walker2d/walker2d"
    for unit in ("adarl_rank_rule-cumulative", "sac"):
        (w / unit / "seeds-0-4/suites").mkdir(parents=True)
    (w / "sac/seeds-0-4/suites/paper.csv").write_text("suite\n")
    assert _robustness(tmp_path) in _campaign(tmp_path)[1]  # one of the two has it
    (tmp_path / "commands").unlink()
    (w / "adarl_rank_rule-cumulative/seeds-0-4/suites/paper.csv").write_text("suite\n")
    assert _robustness(tmp_path) not in _campaign(tmp_path)[1]


@pytest.mark.parametrize("code", [130, 2])
def test_a_stopped_or_refused_sweep_ends_the_campaign(tmp_path, code):
    assert _campaign(tmp_path, {PRESETS[1]: code}) == (
        code,
        [_sweep(tmp_path, PRESETS[0]), _sweep(tmp_path, PRESETS[1])],
    )


def test_the_walker2d_sweep_with_a_failed_unit_is_not_evaluated(tmp_path):
    code, commands = _campaign(tmp_path, {PRESETS[1]: 1})  # 1: some unit failed
    assert code == 0 and commands == [_sweep(tmp_path, p) for p in PRESETS]


@pytest.mark.parametrize(("code", "goes_on"), [(143, False), (130, False), (1, True)])
def test_a_stopped_evaluation_ends_the_campaign_and_a_failed_one_does_not(tmp_path, code, goes_on):
    status, commands = _campaign(tmp_path, {"evaluate": code})
    assert commands[-1] == (_sweep(tmp_path, PRESETS[2]) if goes_on else _robustness(tmp_path))
    assert status == (0 if goes_on else code)
