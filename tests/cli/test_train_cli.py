"""`adarl train` flags: config building, and one-line errors with exit code 2 for bad input."""

import re

import pytest

from adarl.algos import registry
from adarl.algos.flags import parse_int_list
from adarl.cli.main import main
from adarl.cli.train import add_arguments, build_config


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--algo", "ppo"], "unknown algo 'ppo'; allowed: sac, adarl"),
        (["--beta", "1.5"], "beta must be in (0, 1)"),
        (["--beta", "0"], "beta must be in (0, 1)"),
        (["--truncate-every", "0"], "truncate-every must be > 0"),
        (["--algo", "sac-fixed-rank", "--rank", "65"], "rank must be in 1..64"),
        (["--algo", "sac-fixed-rank"], "sac-fixed-rank needs --rank"),
        (["--rank-rule", "median"], "unknown rank rule 'median'"),
        (["--bottleneck", "actor:5"], "bottleneck layer 'actor:5' does not exist"),
        (["--total-steps", "0"], "total-steps must be > 0"),
        (["--total-steps", "-3"], "total-steps must be > 0"),
        (["--batch-size", "abc"], "--batch-size expects int"),
        (["--seeds", "4-1"], "--seeds expects tuple[int,...]"),
        (["--seeds", "0,0"], "seeds contain duplicates"),
        (["--preset", "fast"], "unknown preset for adarl 'fast'"),
        (["--task", "cartpole"], "cartpole"),
        (["--dynamics", "wobbly"], "wobbly"),
        (["--algo", "sac-parseval", "--parseval-coef", "-1"], "parseval-coef must be"),
        (["--algo", "sac-parseval", "--parseval-coef", "0"], "must be > 0 for sac-parseval, got 0"),
        (["--algo", "sac-sparse", "--sparse-width", "-1"], "sparse-width must be"),
        (["--hidden", "64,0"], "hidden sizes must be"),
        (["--eval-every", "1001"], "eval-every must be a multiple of update-every (50), got 1001"),
        (
            ["--retain-tolerance", "0"],
            "retain-tolerance must be a finite number > 0 (or off), got 0",
        ),
        (["--retain-tolerance", "-0.1"], "retain-tolerance must be a finite number > 0"),
        (["--retain-tolerance", "nan"], "retain-tolerance must be a finite number"),
        (["--retain-tolerance", "inf"], "retain-tolerance must be a finite number"),
        (["--retain-tolerance", "tight"], "--retain-tolerance expects float, got 'tight'"),
        (["--rank-rule", "srank"], "unknown rank rule 'srank'; allowed: cumulative, ratio, energy"),
        (["--lr-schedule", "linear"], "unknown lr schedule 'linear'; allowed: envelope, restart"),
        (["--retain-samples", "0"], "retain-samples must be > 0"),
        (["--backend", "gpu"], "unknown backend 'gpu'; allowed: host, device"),
        (
            ["--backend", "device", "--physics", "ompo"],
            "unknown physics for --backend device 'ompo'; allowed: consistent",
        ),
        (
            ["--backend", "device", "--dynamics", "uniform", "--model-version", "v4"],
            "unknown model version for --backend device 'v4'; allowed: v5",
        ),
        (
            ["--backend", "device", "--device-solver", "0,4"],
            "device-solver must be 'xml' or 'ITERATIONS,LS_ITERATIONS' (integers from 1 to 10,000, "
            "e.g. 100,4), "
            "got '0,4'",
        ),
        (
            ["--device-solver", "100,4"],
            "device-solver applies to --backend device, got --device-solver 100,4 with --backend "
            "host",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2_and_creates_nothing(argv, needle, tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["train", *argv, "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err, err
    assert err.count("\n") == 1  # one line
    assert not out.exists()


def test_unknown_flag_is_one_line(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "--learning-rate", "3"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "unrecognized arguments: --learning-rate" in err and err.count("\n") == 1


def test_resume_takes_no_other_settings(tmp_path, capsys):
    assert main(["train", "--resume", str(tmp_path), "--task", "walker2d"]) == 2
    assert "drop --task" in capsys.readouterr().err


def test_rnac_flags_do_not_apply_to_sac(capsys):
    assert main(["train", "--algo", "sac", "--uncertainty-set", "ds"]) == 2
    assert "does not apply to --algo sac" in capsys.readouterr().err


def test_seed_lists():
    assert parse_int_list("0-4") == (0, 1, 2, 3, 4)
    assert parse_int_list("0,2,5") == (0, 2, 5)
    assert parse_int_list("0-1,7") == (0, 1, 7)
    for bad in ("", "a", "3-1"):
        with pytest.raises(ValueError):
            parse_int_list(bad)


def test_spec_lists_keep_fixed_dynamics_whole():
    from adarl.algos.flags import split_specs

    assert split_specs("nominal,fixed:torso_length=0.5,foot_length=0.39,default") == (
        "nominal",
        "fixed:torso_length=0.5,foot_length=0.39",
        "default",
    )
    assert split_specs("actor:1,critic:1") == ("actor:1", "critic:1")


def help_text(capsys, *argv) -> str:
    with pytest.raises(SystemExit) as exit_info:
        main(["train", *argv, "--help"])
    assert exit_info.value.code == 0
    return " ".join(capsys.readouterr().out.split())


@pytest.mark.parametrize("algo", registry.ALGOS)
def test_help_lists_the_fields_of_the_algorithm_with_its_defaults(capsys, algo):
    """`adarl train --algo X --help`: X's config fields, each with X's default (its default
    preset, per-task budgets aside), and no other algorithm's."""
    import dataclasses

    out = help_text(capsys, "--algo", algo)
    entry = registry.get(algo)
    defaults = registry.resolve_config(algo, check=False)
    for f in dataclasses.fields(entry.config_class):
        if f.name == "algo":
            continue
        value = getattr(defaults, f.name)
        text = ",".join(map(str, value)) if isinstance(value, tuple) else str(value)
        assert re.search(rf"--{f.name.replace('_', '-')} \S+ .*?default: {re.escape(text)}", out)
    others = {f.name for c in registry.config_classes() for f in dataclasses.fields(c)}
    flags = out.split("examples:")[0]
    for name in others - registry.field_names(algo):
        assert f"--{name.replace('_', '-')} " not in flags


def test_help_without_algo_is_adarls_and_says_how_to_get_the_others(capsys):
    out = help_text(capsys)
    assert "--truncate-every" in out and "--uncertainty-set" not in out
    assert "adarl train --algo ALGO --help" in out
    rnac = help_text(capsys, "--algo", "rnac")
    for flag, value in [
        ("total-steps", 3_000_000),
        ("eval-every", 5000),
        ("eval-episodes", 3),
        ("log-every", 2048),
        ("checkpoint-every", 100_000),
    ]:
        assert re.search(rf"--{flag} INT [^-]*default: {value}\b", rnac), flag


def config_for(*argv):
    import argparse

    parser = argparse.ArgumentParser(add_help=False)
    add_arguments(parser)
    return build_config(parser.parse_args(list(argv)))[1]


def test_adarl_without_a_budget_uses_its_per_task_budget_and_truncates():
    from adarl.algos import schedule

    for task, steps, d_t, cuts in [
        ("hopper", 3_000_000, 1_000_000, 2),
        ("walker2d", 3_000_000, 700_000, 4),
        ("ant", 5_000_000, 1_000_000, 4),
        ("humanoid", 5_000_000, 1_000_000, 4),
    ]:
        config = config_for("--algo", "adarl", "--task", task)
        assert (config.total_steps, config.truncate_every) == (steps, d_t)
        assert schedule.n_truncations(config) == cuts
    # flags and presets sit above the per-task budget; other algorithms keep theirs
    assert config_for("--algo", "adarl", "--total-steps", "500000").total_steps == 500_000
    assert config_for("--algo", "adarl", "--preset", "quickstart").total_steps == 150_000
    assert (
        config_for(
            "--algo", "adarl", "--task", "walker2d", "--truncate-every", "9000"
        ).truncate_every
        == 9000
    )
    assert config_for("--algo", "sac", "--task", "hopper").total_steps == 1_000_000
    assert config_for("--algo", "adarl").retain_tolerance is None  # see docs/algorithms.md
    assert config_for("--algo", "adarl", "--retain-tolerance", "off").retain_tolerance is None
    assert config_for("--algo", "adarl", "--retain-tolerance", "0.02").retain_tolerance == 0.02


def test_adarl_budget_without_truncations_warns_once(tmp_path, capsys):
    """A budget with no cut, or mostly random warm-up, is said plainly at the start and again in
    the summary (issue 62: one warning line above the progress bar was easy to miss)."""
    code = main(
        [
            "train",
            "--preset",
            "smoke",
            "--total-steps",
            "400",
            "--out",
            str(tmp_path / "r"),
            "--no-progress",
        ]
    )
    assert code == 0
    captured = capsys.readouterr()
    warnings = [line for line in captured.err.splitlines() if line.startswith("warning:")]
    assert [w.split(":")[1].strip() for w in warnings] == ["no cut", "all random"]
    assert "fewer than d_t = 500: the rank never adapts" in warnings[0]
    assert "start-steps 500 ≥ total-steps 400" in warnings[1]
    out = captured.out.splitlines()
    assert out[0].startswith("start: adarl on hopper, 1 seed x 400 steps; no cut of the rank")
    done = out.index(next(line for line in out if line.startswith("done:")))
    assert out[done + 1 : done + 3] == warnings  # the summary says them again, under done:


def test_on_other_tasks_d_t_and_the_warm_up_follow_the_budget():
    """Issue 62: on a task outside the paper's four, d_t = total-steps / 5 (four cuts) and the
    warm-up 5% of the budget (at most 10,000) where neither a flag nor the preset sets them."""
    from adarl.algos import schedule

    def budget(*argv):
        config = config_for(*argv)
        return config.total_steps, config.truncate_every, config.start_steps

    cheetah = ("--task", "HalfCheetah-v5")
    assert budget("--algo", "adarl", *cheetah, "--total-steps", "100000") == (
        100_000,
        20_000,
        5_000,
    )
    assert (
        schedule.n_truncations(config_for("--algo", "adarl", *cheetah, "--total-steps", "100000"))
        == 4
    )
    assert budget("--algo", "adarl", *cheetah) == (1_000_000, 200_000, 10_000)  # as before
    assert budget("--algo", "adarl-control", *cheetah, "--total-steps", "50000")[1:] == (
        10_000,
        2_500,
    )
    assert budget("--algo", "sac", *cheetah, "--total-steps", "40000")[2] == 2_000
    # explicit flags and presets win
    assert budget("--algo", "adarl", *cheetah, "--total-steps", "100000", "--truncate-every",
                  "30000", "--start-steps", "7000") == (100_000, 30_000, 7_000)  # fmt: skip
    assert budget("--algo", "adarl", *cheetah, "--preset", "smoke")[1:] == (500, 500)
    # the paper's four keep the paper's settings, and so do the presets
    assert budget("--algo", "adarl", "--task", "hopper", "--total-steps", "100000") == (
        100_000, 1_000_000, 10_000,
    )  # fmt: skip
    assert budget("--algo", "sac", "--task", "walker2d", "--total-steps", "40000")[2] == 10_000
    assert budget("--algo", "adarl", "--preset", "quickstart") == (150_000, 30_000, 5_000)


def test_help_says_the_budget_rule(capsys):
    out = help_text(capsys, "--algo", "adarl")
    assert re.search(r"--truncate-every INT .*?on other tasks: total-steps / 5\)", out)
    assert re.search(r"--start-steps INT .*?on other tasks: 5% of total-steps, at most 10,000", out)
    assert "what neither a flag nor --preset sets follows --total-steps" in out


def test_tasks_shows_the_adarl_default_budget(capsys):
    assert main(["tasks", "walker2d"]) == 0
    out = capsys.readouterr().out
    assert (
        "adarl default budget: 3,000,000 steps, d_t = 700,000 gradient steps (4 truncations)\n"
        in out
    )  # the paper's tasks keep the paper's settings: no budget rule
    assert main(["tasks", "InvertedPendulum-v5"]) == 0
    out = capsys.readouterr().out
    assert (
        "with another --total-steps, unless given: start_steps = 5% of total-steps, at most "
        "10,000; truncate_every = total-steps / 5" in out
    )  # issue 62: `adarl tasks` says the rule on the other tasks


def test_report_flag_writes_the_report_and_the_summary_names_it(tmp_path, capsys, monkeypatch):
    from adarl.report import common

    # drawing: tested apart
    monkeypatch.setattr(common, "save_figure", lambda folder, fig, stem: [])
    run_dir = tmp_path / "r"
    argv = ["train", "--preset", "smoke", "--algo", "sac", "--out", str(run_dir), "--no-progress"]
    assert main([*argv, "--report"]) == 0
    out = capsys.readouterr().out
    assert (run_dir / "report" / "index.md").is_file()
    assert "done: sac on hopper, 1 seed(s) x 2,000 steps" in out
    assert "\nnominal return: " in out and "\nfinal checkpoint: " in out
    assert "\nwhat the final policy does: episodes last " in out and " of 200 steps" in out  # smoke
    assert f"report: {run_dir}/report/index.md" in out


def test_quickstart_reports_unless_told_not_to():
    from adarl.cli.train import wants_report

    assert wants_report(None, "quickstart") and not wants_report(False, "quickstart")
    assert not wants_report(None, "paper") and not wants_report(None, None)
    assert wants_report(True, None)


def test_resuming_a_run_of_a_reporting_preset_writes_its_report(tmp_path, monkeypatch):
    import sys

    from adarl.cli import train as train_cli
    from adarl.report import common

    # drawing: tested apart
    monkeypatch.setattr(common, "save_figure", lambda folder, fig, stem: [])
    run_dir = tmp_path / "r"
    argv = ["train", "--preset", "smoke", "--algo", "sac", "--out", str(run_dir), "--no-progress"]
    monkeypatch.setattr(sys, "argv", ["adarl", *argv])  # what the run records as its command
    assert main(argv) == 0 and not (run_dir / "report").exists()
    monkeypatch.setattr(train_cli, "REPORT_PRESETS", ("smoke",))
    resume = ["train", "--resume", str(run_dir), "--no-progress"]
    monkeypatch.setattr(sys, "argv", ["adarl", *resume])
    assert main(resume) == 0
    assert (run_dir / "report" / "index.md").is_file()


def test_a_resumed_run_reads_its_recorded_preset_and_report_flag():
    from adarl.cli.train import recorded_args

    def preset(command):
        args = recorded_args(command)
        return None if args is None else args.preset

    assert preset("adarl train --preset quickstart --seeds 0") == "quickstart"
    assert preset("adarl train --algo sac --preset=smoke") == "smoke"
    assert preset("adarl train --pres quickstart") == "quickstart"  # argparse's abbreviation
    assert preset("adarl train --algo sac --no-progress") is None
    assert recorded_args("adarl train --algo sac --report").report is True
    assert recorded_args("adarl train --preset") is None and recorded_args("adarl train 'x") is None


def test_every_config_field_has_its_meaning_in_help(capsys):
    """A field's meaning is the comment next to it in its config class, shown by --help."""
    import dataclasses

    for cls in registry.config_classes():
        meanings = registry.field_help(cls)
        missing = [f.name for f in dataclasses.fields(cls) if not meanings.get(f.name)]
        assert not missing, f"{cls.__name__}: give these fields a comment: {missing}"
    assert registry.field_help(registry.get("sac").config_class)["buffer_size"] == (
        "replay buffer capacity per seed (transitions)"
    )
    out = help_text(capsys)
    assert (
        "--buffer-size INT replay buffer capacity per seed (transitions); default: 1000000" in out
    )
    assert "--clip-eps FLOAT PPO's clip range ε; default: 0.2" in help_text(
        capsys, "--algo", "rnac"
    )
    # a comment block above a field is its help; a `# --- section` heading is not
    assert "--compact-bottlenecks BOOL after a truncation, narrow each seed's bottlenecks" in out
    assert "--hidden TUPLE hidden layer widths of actor and critics; default: 64,64" in out


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--at", "100"], "--at is for --fork RUN_DIR"),
        (["--fork", "{sac}"], "--fork needs --at STEP (a checkpoint step, or first-truncation)"),
        (["--fork", "{sac}", "--at", "5", "--resume", "x"], "drop --resume"),
        (["--fork", "{sac}", "--at", "5", "--preset", "smoke"], "drop --preset"),
        (["--fork", "{sac}", "--at", "5", "--algo", "adarl"], "drop --algo"),
        (["--fork", "{sac}", "--at", "5"], "has no checkpoint at step 5; fork points: none"),
        (["--fork", "{rnac}", "--at", "5"], "is a rnac run; forks are for the SAC family (sac, adarl"),
        (["--fork", "{sac}", "--at", "5", "--hidden", "8,8"], "--hidden cannot change at a fork"),
        (["--fork", "{missing}", "--at", "5"], "does not exist"),
    ],
)  # fmt: skip
def test_bad_forks_are_one_line_exit_2_and_create_nothing(argv, needle, tmp_path, capsys):
    runs = {}
    for algo in ("sac", "rnac"):  # run folders with a config and no checkpoint
        runs[algo] = tmp_path / algo
        runs[algo].mkdir()
        (runs[algo] / "config.yaml").write_text(f"algo: {algo}\nformat_version: 1\n")
    runs["missing"] = tmp_path / "missing"
    argv = [a.format(**runs) for a in argv]
    out = tmp_path / "fork"
    code = main(["train", *argv, "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err, err
    assert err.count("\n") == 1
    assert not out.exists()


def test_fork_the_control_at_the_first_truncation(tmp_path, capsys):
    """The documented command: the control forked from an AdaRL run where it first truncates."""
    parent, child = tmp_path / "adarl", tmp_path / "control"
    budget = ["--preset", "smoke", "--total-steps", "700", "--truncate-every", "100"]
    assert main(["train", "--algo", "adarl", *budget, "--out", str(parent), "--no-progress"]) == 0
    argv = ["--fork", str(parent), "--at", "first-truncation", "--apply-cuts", "false"]
    assert main(["train", *argv, "--out", str(child), "--no-progress"]) == 0
    assert "done: adarl-control on hopper" in capsys.readouterr().out
    import yaml

    from adarl.runs.logs import read_csv

    config = yaml.safe_load((child / "config.yaml").read_text())
    assert config["algo"] == "adarl-control" and config["apply_cuts"] is False
    assert config["fork"]["step"] == 550 and config["fork"]["checkpoint"] == "pre_truncation"
    cuts = read_csv(child / "truncations.csv")
    assert {r["step"] for r in cuts} == {"550", "650"}
    assert all(r["new_rank"] == r["old_rank"] for r in cuts)
    assert main(["train", "--resume", str(child), "--no-progress"]) == 0  # already complete
    assert "is already complete" in capsys.readouterr().err
