"""docs/experiments/campaign.sh, the campaign's driver, with a stand-in for Python that records
each command and answers with a chosen exit status: the sweeps in the campaign's order (claim 1
across tasks' 15 blocks, each followed by its grids and export, then Walker2d's three sweep files,
then fixed-rank-power), the robustness evaluation right after each Walker2d sweep file of each
run that lacks it, and a stop that ends it all."""

import os
import subprocess
from pathlib import Path

import pytest

EXPERIMENTS = Path(__file__).parents[2] / "docs/experiments"
SCRIPT = EXPERIMENTS / "campaign.sh"
W = EXPERIMENTS / "paper-schedule-walker2d"
CLAIM1 = EXPERIMENTS / "claim1-across-tasks"
SCRIPT1 = EXPERIMENTS / "claim1_across_tasks.py"
SWEEPS = (
    str(W / "paper-schedule-walker2d-seeds-2-4.yaml"),
    str(W / "paper-schedule-walker2d-sac-0-1.yaml"),
    str(W / "paper-schedule-walker2d.yaml"),
    "fixed-rank-power",
)
WALKER2D = SWEEPS[0:3]
# a sweep file run into another's sweep folder
SHARED_FOLDER = {
    SWEEPS[0]: "paper-schedule-walker2d",
    SWEEPS[1]: "paper-schedule-walker2d",
}
EVALUATED = ("adarl_rank_rule-cumulative", "sac")  # the control is not (paper-schedule-walker2d.md)


def _campaign(tmp_path: Path, exits: dict[str, int] | None = None) -> tuple[int, list[str]]:
    """Run the script; the stand-in exits with exits[word] when a word of its command is a key
    (a sweep, or `evaluate`), else 0. Returns the exit status and the commands, in order."""
    log = tmp_path / "commands"
    (tmp_path / "code3").mkdir(exist_ok=True)
    cases = "".join(f'    *" {word} "*) code={code} ;;\n' for word, code in (exits or {}).items())
    python = tmp_path / "python"
    python.write_text(
        "#!/usr/bin/env bash\n"
        f'echo "$(basename "$PWD") $*" >> {log}\n'
        "code=0\n"
        f'case " $* " in\n{cases}esac\n'
        "exit $code\n"
    )
    python.chmod(0o755)
    env = {
        **os.environ,
        "CAMPAIGN_CODE": str(tmp_path),
        "CAMPAIGN_CODE3": str(tmp_path / "code3"),
        "CAMPAIGN_PYTHON": str(python),
        "CAMPAIGN_RESULTS": str(tmp_path / "results"),
    }
    done = subprocess.run(["bash", str(SCRIPT)], env=env, capture_output=True, text=True)
    commands = log.read_text().splitlines() if log.exists() else []
    # each command as `where: command` (code3: the frozen code of claim 1 across tasks)
    where = {tmp_path.name: "code", "code3": "code3"}
    out = []
    for line in commands:
        folder, command = line.split(" ", 1)
        out.append(f"{where[folder]}: {command.removeprefix('-m adarl.cli.main ')}")
    return done.returncode, out


def _sweep(tmp_path: Path, sweep: str) -> str:
    folder = SHARED_FOLDER.get(sweep, Path(sweep).name.removesuffix(".yaml"))
    return f"code: sweep {sweep} --out {tmp_path / 'results' / folder} --workers 2 --no-progress"


def _claim1(tmp_path: Path, blocks=range(15)) -> list[str]:
    """The restore, then per block: its sweep, its grids, its export (all in the frozen code3)."""
    r1 = tmp_path / "results/claim1-across-tasks"
    out = [f"code3: {SCRIPT1} restore {r1}"]
    for seed in blocks:
        out += [
            f"code3: sweep {CLAIM1 / f'primary-seed-{seed}.yaml'} --out {r1} --workers 2 --no-progress",
            f"code3: {SCRIPT1} evaluate {r1} --code {tmp_path / 'code3'}",
            f"code3: {SCRIPT1} export {r1}",
        ]
    return out


def _claim2_hedged(tmp_path: Path) -> list[str]:
    """Claim 2's hedged form after claim 1: restore its rows, its sweep, its export (code3)."""
    r2 = tmp_path / "results/claim2-hedged"
    return [
        f"code3: {SCRIPT1} restore {r2} --rows {EXPERIMENTS / 'claim2-hedged/rows'}",
        f"code3: sweep {EXPERIMENTS / 'claim2-hedged/claim2-hedged.yaml'} --out {r2} --workers 2 --no-progress",
        f"code3: {EXPERIMENTS / 'claim2_hedged.py'} export {r2}",
    ]


def _runs(tmp_path: Path, evaluated=()) -> list[Path]:
    """Make Walker2d's run folders, one per seed and arm (control included); those of
    `evaluated` (arm, seed) get their suites/paper.csv. Returns the AdaRL and SAC runs."""
    w = tmp_path / "results/paper-schedule-walker2d/walker2d"
    runs = []
    for arm in (*EVALUATED, "adarl-control-eq5"):
        for seed in range(5):
            run = w / arm / f"seeds-{seed}"
            (run / "suites").mkdir(parents=True)
            if (arm, seed) in evaluated:
                (run / "suites/paper.csv").write_text("suite\n")
            if arm in EVALUATED:
                runs.append(run)
    return runs


def _robustness(runs) -> str:
    return (
        f"code: evaluate {' '.join(map(str, runs))} --suite paper --episodes 5 --workers 2 "
        "--no-progress"
    )


def test_the_sweeps_in_order_with_the_robustness_evaluation_after_walker2d(tmp_path):
    runs = _runs(tmp_path)
    code, commands = _campaign(tmp_path)
    assert code == 0
    after_each = [_robustness(runs)]  # AdaRL's five seeds, then SAC's (the stand-in writes none)
    assert commands == [
        *_claim1(tmp_path),
        *_claim2_hedged(tmp_path),
        *(c for s in WALKER2D for c in [_sweep(tmp_path, s), *after_each]),
        _sweep(tmp_path, SWEEPS[3]),
    ]


def test_only_the_runs_without_their_robustness_evaluation_are_evaluated(tmp_path):
    runs = _runs(tmp_path, evaluated={("sac", 0), ("adarl_rank_rule-cumulative", 3)})
    todo = [r for r in runs if not (r / "suites/paper.csv").exists()]
    assert len(todo) == 8 and _robustness(todo) in _campaign(tmp_path)[1]
    (tmp_path / "commands").unlink()
    for run in todo:
        (run / "suites/paper.csv").write_text("suite\n")
    assert not any(c.startswith("code: evaluate") for c in _campaign(tmp_path)[1])


def test_no_walker2d_runs_nothing_to_evaluate(tmp_path):
    code, commands = _campaign(tmp_path)
    assert code == 0 and commands == [
        *_claim1(tmp_path),
        *_claim2_hedged(tmp_path),
        *(_sweep(tmp_path, s) for s in SWEEPS),
    ]


@pytest.mark.parametrize("code", [130, 2])
def test_a_stopped_or_refused_sweep_ends_the_campaign(tmp_path, code):
    block3 = str(CLAIM1 / "primary-seed-3.yaml")
    assert _campaign(tmp_path, {block3: code}) == (code, _claim1(tmp_path, range(4))[:-2])
    (tmp_path / "commands").unlink()
    assert _campaign(tmp_path, {WALKER2D[0]: code}) == (
        code,
        [*_claim1(tmp_path), *_claim2_hedged(tmp_path), _sweep(tmp_path, WALKER2D[0])],
    )


@pytest.mark.parametrize(("code", "goes_on"), [(143, False), (130, False), (1, True)])
def test_claim1_a_stopped_grid_ends_the_campaign_and_a_failed_one_does_not(tmp_path, code, goes_on):
    status, commands = _campaign(tmp_path, {"--code": code})  # the grids of claim 1 only
    if goes_on:
        assert status == 0 and commands[: len(_claim1(tmp_path))] == _claim1(tmp_path)
    else:
        assert (status, commands) == (code, _claim1(tmp_path, range(1))[:-1])


def test_claim1_a_failed_unit_still_evaluates_and_exports_its_block(tmp_path):
    status, commands = _campaign(tmp_path, {str(CLAIM1 / "primary-seed-0.yaml"): 1})
    assert status == 0 and commands[: len(_claim1(tmp_path))] == _claim1(tmp_path)


def test_claim1_a_failed_restore_stops_before_any_unit(tmp_path):
    assert _campaign(tmp_path, {"restore": 1}) == (2, _claim1(tmp_path, range(0)))


def test_a_walker2d_sweep_with_a_failed_unit_is_not_evaluated(tmp_path):
    _runs(tmp_path)
    fails = {s: 1 for s in WALKER2D}  # 1: some unit failed
    code, commands = _campaign(tmp_path, fails)
    assert code == 0 and commands == [
        *_claim1(tmp_path),
        *_claim2_hedged(tmp_path),
        *(_sweep(tmp_path, s) for s in SWEEPS),
    ]


@pytest.mark.parametrize(("code", "goes_on"), [(143, False), (130, False), (1, True)])
def test_a_stopped_evaluation_ends_the_campaign_and_a_failed_one_does_not(tmp_path, code, goes_on):
    runs = _runs(tmp_path)
    status, commands = _campaign(tmp_path, {"--suite": code})  # Walker2d's evaluation only
    assert commands[-1] == (_sweep(tmp_path, SWEEPS[3]) if goes_on else _robustness(runs))
    assert commands[-2] == (_robustness(runs) if goes_on else _sweep(tmp_path, WALKER2D[0]))
    assert status == (0 if goes_on else code)
