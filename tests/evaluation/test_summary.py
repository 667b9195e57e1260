"""The end-of-training summary, from synthetic run folders."""

from adarl.evaluation import collect
from adarl.evaluation.runs import load_run
from adarl.evaluation.summary import duration, sweep_example, training_summary
from adarl.evaluation.synthetic import write_run


def test_duration():
    assert [duration(s) for s in (0, 42.4, 187, 7500)] == ["0s", "42s", "3m07s", "2h05m"]


def test_summary_of_an_adarl_run_has_returns_ranks_files_and_next_commands(tmp_path):
    run_dir = write_run(tmp_path, "run", algo="adarl", seeds=(0, 1, 2))
    scores = collect.final_scores(load_run(run_dir))[0]["score"].to_numpy()
    text = training_summary(run_dir, 125.0)
    lines = text.splitlines()
    assert lines[0] == "done: adarl on hopper, 3 seed(s) x 10,000 steps, wall time 2m05s"
    assert f"final nominal return: {scores.mean():.1f} ± {scores.std(ddof=1):.1f}" in lines[1]
    ranks = collect.final_ranks(load_run(run_dir))
    actor = ranks[ranks["layer"] == ranks["layer"].iloc[0]]["rank"]
    assert f"{ranks['layer'].iloc[0]} {actor.mean():.1f}" in text
    assert f"files: {run_dir}/" in text
    assert f"  adarl report {run_dir} --out {run_dir}/report" in lines
    assert f"  adarl evaluate {run_dir} {sweep_example('hopper')}" in lines
    assert f"  tensorboard --logdir {run_dir}/tb" in lines


def test_summary_of_a_sac_run_with_a_report(tmp_path):
    run_dir = write_run(tmp_path, "run", algo="sac", seeds=(4,))
    text = training_summary(run_dir, 3.0, report_dir=run_dir / "report")
    assert "final ranks" not in text and " ± " not in text  # no bottleneck; one seed: no spread
    assert f"report: {run_dir}/report/index.md" in text and "adarl report" not in text
    assert f"--seed 4 --video {run_dir}/seed4.mp4" in text


def test_sweep_example_spans_the_training_range():
    assert sweep_example("hopper") == "--sweep torso_length=0.2:0.6:9"  # 0.4 + 0.2·sin(0.2·i)
    assert sweep_example("ant") == "--sweep gravity=9.81:19.62:9"  # 14.715 + 4.905·sin(0.5·i)
    assert sweep_example("no-such-task") == ""
