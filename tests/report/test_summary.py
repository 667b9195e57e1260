"""The end-of-training summary, from synthetic run folders."""

import numpy as np
import pandas as pd
import user_env
from synthetic_runs import write_run

from adarl.report.summary import behaviour_line, duration, sweep_examples, training_summary
from adarl.results import collect
from adarl.results.runs import load_run


def test_duration():
    assert [duration(s) for s in (0, 42.4, 187, 7500)] == ["0s", "42s", "3m07s", "2h05m"]


def test_summary_of_an_adarl_run_has_returns_ranks_files_and_next_commands(tmp_path):
    run_dir = write_run(tmp_path, "run", algo="adarl", seeds=(0, 1, 2), n_evals=7)
    log = pd.read_csv(run_dir / "eval.csv")  # 7 evaluations of 2 episodes per seed
    per_eval = log.groupby(["seed", "step"])["return"].mean().unstack()  # seeds × steps
    recent = per_eval.iloc[:, -5:].mean(axis=1).to_numpy()  # the last 5 evaluations
    final = per_eval.iloc[:, -1].to_numpy()
    text = training_summary(run_dir, 125.0)
    lines = text.splitlines()
    assert lines[0] == "done: adarl on hopper, 3 seed(s) x 10,000 steps, wall time 2m05s"
    assert lines[1].startswith(
        f"nominal return: {recent.mean():.1f} ± {recent.std(ddof=1):.1f} (mean of the last 5 "
        f"evaluation(s), steps {per_eval.columns[-5]:,}–10,000, 2 episode(s) each; seed 0: "
        f"{recent[0]:.1f}"
    )
    assert lines[2].startswith("  in those 15 evaluations (5 per seed) the policies stand or move")
    assert lines[3].startswith(f"final checkpoint: {final.mean():.1f} ± {final.std(ddof=1):.1f}")
    assert lines[4] == (
        "what the final policies do: episodes last 1,000 of 1,000 steps on average, forward "
        "distance not recorded (`adarl evaluate` records it): all 3 seeds stand or move "
        "(full length; the forward distance would tell which)"
    )
    assert f"  adarl evaluate {run_dir}   # records forward distance" in lines
    ranks = collect.final_ranks(load_run(run_dir))
    actor = ranks[ranks["layer"] == ranks["layer"].iloc[0]]["rank"]
    assert f"{ranks['layer'].iloc[0]} {actor.mean():.1f}" in text
    assert f"files: {run_dir}/" in text
    assert f"  adarl report {run_dir} --out {run_dir}/report" in lines
    for sweep in sweep_examples({"task": "hopper", "dynamics": "paper"}):
        assert f"  adarl evaluate {run_dir} {sweep}" in lines
    assert f"  tensorboard --logdir {run_dir}/tb" in lines


def test_summary_of_a_sac_run_with_a_report(tmp_path):
    run_dir = write_run(tmp_path, "run", algo="sac", seeds=(4,))
    text = training_summary(run_dir, 3.0, report_dir=run_dir / "report")
    assert "final ranks" not in text and " ± " not in text  # no bottleneck; one seed: no spread
    assert f"report: {run_dir}/report/index.md" in text and "adarl report" not in text
    assert f"--seed 4 --video {run_dir}/seed4.mp4" in text


def test_sweep_examples_span_the_training_range():
    assert sweep_examples({"task": "hopper", "dynamics": "paper"}) == [
        "--sweep torso_length=0.2..0.6:9",  # 0.4 + 0.2·sin(0.2·i)
        "--sweep foot_length=0.19..0.59:9",
    ]
    assert sweep_examples({"task": "ant", "dynamics": "uniform"})[0] == (
        "--sweep gravity=9.81..19.62:9"  # 14.715 + 4.905·sin(0.5·i)
    )
    assert sweep_examples({"task": "no-such-task", "dynamics": "paper"}) == []


def test_the_next_sweeps_are_the_runs_own_varied_parameters(tmp_path):
    """Issue 62: the summary suggests sweeping what the run varied, over its training range (it
    suggested mass_scale to a user who trained over a body's mass)."""
    xml = user_env.write_xml(tmp_path)
    config = {
        "task": user_env.ENV_ID,
        "env_module": "user_env",
        "env_kwargs": f"xml_file={xml}",
        "dynamics": "uniform:body:ball.mass=0.2..1,geom:floor.friction=0.3..1.5",
    }
    assert sweep_examples(config) == [
        "--sweep body:ball.mass=0.2..1:9",
        "--sweep geom:floor.friction=0.3..1.5:9",
    ]
    # a run that varied nothing: the task's own schedule (here the generic one)
    assert sweep_examples({**config, "dynamics": "nominal"}) == ["--sweep mass_scale=0.8..1.2:9"]
    run_dir = write_run(tmp_path, "r", seeds=(0,), dynamics="uniform:body:torso.mass=3..5")
    lines = training_summary(run_dir, 1.0).splitlines()
    assert f"  adarl evaluate {run_dir} --sweep body:torso.mass=3..5:9" in lines
    assert not any("mass_scale" in line for line in lines)


def test_summary_says_a_run_with_few_evaluations_and_a_falling_policy(tmp_path):
    run_dir = write_run(tmp_path, "run", algo="sac", seeds=(0,), n_evals=3)
    log = pd.read_csv(run_dir / "eval.csv")
    log["length"] = np.where(log["step"] == log["step"].max(), 136, 1000)  # falls at the end
    log.to_csv(run_dir / "eval.csv", index=False)
    lines = training_summary(run_dir, 3.0).splitlines()
    mean = log.groupby("step")["return"].mean().mean()  # all 3 evaluations: fewer than 5
    assert lines[1].startswith(f"nominal return: {mean:.1f} (mean of the last 3 evaluation(s)")
    assert lines[4] == (
        "what the final policy does: episodes last 136 of 1,000 steps, forward distance not "
        "recorded (`adarl evaluate` records it): falls (episodes end early by termination)"
    )


def test_behaviour_line_with_distance():
    table = pd.DataFrame(
        {"seed": [0, 1, 2], "length": [136.0, 1000.0, 990.0], "distance": [1.5, 0.4, 9.0],
         "max_length": 1000}
    )  # fmt: skip
    assert behaviour_line(table) == (
        "what the final policies do: episodes last 709 of 1,000 steps on average, forward "
        "distance 3.63 m; falls (episodes end early by termination): seed 0; stands (full "
        "length, less than 3 m forward): seed 1; moves (long episodes, at least 3 m forward): "
        "seed 2"
    )


def test_final_ranks_are_those_of_the_last_logged_step(tmp_path):
    """The summary's final ranks are each seed's ranks at its last train.csv row (read here with
    the csv module, not with the code under test), and they differ from the first row's."""
    import csv

    run_dir = write_run(tmp_path, "run", algo="adarl", seeds=(0, 1, 2), n_evals=7)
    with open(run_dir / "train.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    layers = [c.removeprefix("rank_") for c in rows[0] if c.startswith("rank_")]
    last = {}
    for row in rows:  # written in step order; keep each seed's last row
        last[int(row["seed"])] = row
    first = {int(r["seed"]): r for r in reversed(rows)}
    line = next(x for x in training_summary(run_dir, 1.0).splitlines() if x.startswith("final r"))
    for layer in layers:
        final = [int(last[s][f"rank_{layer}"]) for s in (0, 1, 2)]
        assert final != [int(first[s][f"rank_{layer}"]) for s in (0, 1, 2)]  # it did change
        span = f" ({min(final)}-{max(final)})" if min(final) != max(final) else ""
        assert f"{layer} {np.mean(final):.1f}{span}" in line, (layer, final, line)
        table = collect.final_ranks(load_run(run_dir))
        got = table[table["layer"] == layer].sort_values("seed")["rank"].astype(int).tolist()
        assert got == final


def _eval_csv(run_dir, evaluations, distance=False):
    """eval.csv from (seed, step, [(return, length, distance), ...]) per evaluation."""
    rows = [
        {"step": step, "seed": seed, "dynamics": "nominal", "episode": e, "return": ret,
         "length": length, **({"distance": dist} if distance else {})}
        for seed, step, episodes in evaluations
        for e, (ret, length, dist) in enumerate(episodes)
    ]  # fmt: skip
    pd.DataFrame(rows).to_csv(run_dir / "eval.csv", index=False)


def test_the_headline_says_what_the_evaluations_behind_it_did(tmp_path):
    """Issue 57's quickstart: a return of 906 averages four evaluations that stand (or hop) the
    full 1,000 steps at ~1,000 with a last one that falls at 136 steps; the line under the
    headline says so (the first evaluation, older than the last 5, is not in it)."""
    run_dir = write_run(tmp_path, "run", algo="adarl", seeds=(0,), n_evals=6)
    full = [(1000.0, 1004.0), (1090.0, 1100.0), (1040.0, 1060.0), (1010.0, 1030.0)]
    evaluations = [(0, 25_000, [(50.0, 40, 0), (70.0, 60, 0)])]
    evaluations += [(0, 50_000 + 25_000 * i, [(a, 1000, 0), (b, 1000, 0)]) for i, (a, b) in
                    enumerate(full)]  # fmt: skip
    evaluations.append((0, 150_000, [(360.0, 130, 0), (366.6, 142, 0)]))
    _eval_csv(run_dir, evaluations)
    lines = training_summary(run_dir, 60.0).splitlines()
    # (1002 + 1095 + 1050 + 1020 + 363.3) / 5
    assert lines[1].startswith("nominal return: 906.1 (mean of the last 5 evaluation(s), steps "
                               "50,000–150,000")  # fmt: skip
    assert lines[2] == (
        "  in those 5 evaluations the policy stands or moves in 4 (1,000 of 1,000 steps, return "
        "1,002.0–1,095.0) and falls in 1 (step 150,000: 136 of 1,000 steps, return 363.3); "
        "forward distance not recorded during training (`adarl evaluate` records it)"
    )


def test_with_distances_the_line_says_stands_moves_or_falls_per_seed(tmp_path):
    run_dir = write_run(tmp_path, "run", algo="sac", seeds=(0, 1), n_evals=2)
    _eval_csv(
        run_dir,
        [
            (0, 5000, [(900.0, 1000, 5.1)]),
            (0, 10000, [(1000.0, 1000, 8.0)]),
            (1, 5000, [(1000.0, 1000, 0.4)]),
            (1, 10000, [(200.0, 90, 1.0)]),
        ],
        distance=True,
    )
    lines = training_summary(run_dir, 1.0).splitlines()
    assert lines[2] == (
        "  in those 4 evaluations (2 per seed) the policies move in 2 (1,000 of 1,000 steps, "
        "5.10–8.00 m forward, return 900.0–1,000.0), fall in 1 (90 of 1,000 steps, 1.00 m "
        "forward, return 200.0) and stand in 1 (1,000 of 1,000 steps, 0.40 m forward, return "
        "1,000.0)"
    )  # the most frequent first; a tie in the order falls, stands, moves
