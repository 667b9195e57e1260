"""Each figure from a small synthetic run folder: built without error, with the expected axes
and series (inspected on the returned matplotlib Figure)."""

import numpy as np
import pandas as pd
import pytest
from synthetic_runs import write_run, write_sweep

from adarl.report import figures
from adarl.results import collect
from adarl.results.runs import find_runs

TORSO = [0.2, 0.3, 0.4, 0.5, 0.6]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("runs")
    write_run(root, "adarl", algo="adarl", n_truncations=3, total_steps=8000)
    write_run(root, "ratio", algo="adarl", rank_rule="ratio", n_truncations=3, total_steps=8000)
    write_run(root, "sac", algo="sac", quality=0.7, total_steps=8000)
    write_run(root, "w-sac", algo="sac", task="walker2d", quality=0.7)
    for rank in (2, 8, 32):
        write_run(root, f"fixed{rank}", algo="sac-fixed-rank", rank=rank, quality=rank / 32)
    write_sweep(root / "adarl", "torso_length", TORSO, hold={"foot_length": 0.39})
    write_sweep(root / "sac", "torso_length", TORSO, hold={"foot_length": 0.39}, quality=0.7)
    return {r.path.name: r for r in find_runs([root])}


def labels(ax):
    return [line.get_label() for line in ax.get_lines() if not line.get_label().startswith("_")]


def red_dashed(ax):
    return [ln for ln in ax.get_lines() if ln.get_color() == "red" and ln.get_linestyle() == "--"]


def test_training_curves_have_a_panel_per_task_and_truncation_lines(runs):
    curves, truncations = {}, {}
    for name in ("adarl", "sac", "w-sac"):
        r = runs[name]
        curves.setdefault(r.task, {})[r.label] = collect.training_curve(r)[0]
        truncations.setdefault(r.task, []).extend(collect.truncation_steps(r))
    fig = figures.training_curves(curves, truncations)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in axes] == ["hopper", "walker2d"]
    hopper, walker = axes
    assert labels(hopper) == ["adarl", "sac", "truncation"]
    assert labels(walker) == ["sac"]
    assert [ln.get_xdata()[0] for ln in red_dashed(hopper)] == [2000, 4000, 6000]
    assert red_dashed(walker) == []
    assert hopper.get_xlabel() == "environment steps" and "return" in hopper.get_ylabel()
    adarl_line = hopper.get_lines()[0]
    assert list(adarl_line.get_xdata()) == [1600, 3200, 4800, 6400, 8000]
    assert len(hopper.collections) == 2  # one confidence band per method
    assert hopper.xaxis.get_major_formatter()(4000, 0) == "4k"


def test_a_legend_below_the_panels_overlaps_no_panel(runs):
    curves = {}
    for name in ("adarl", "sac", "w-sac"):
        r = runs[name]
        curves.setdefault(r.task, {})[r.label] = collect.training_curve(r)[0]
    height = figures.training_curves(curves).get_figheight()
    fig = figures.training_curves(curves, legend_loc="below")
    assert fig.get_figheight() > height
    fig.canvas.draw()
    axes = [ax for ax in fig.axes if ax.get_visible()]
    for ax in axes:
        legend = ax.get_legend().get_window_extent()
        assert [t.get_text() for t in ax.get_legend().get_texts()] == labels(ax)
        assert all(not legend.overlaps(other.get_window_extent()) for other in axes)
        assert legend.y1 < ax.get_window_extent().y0  # under its own panel


@pytest.mark.parametrize(
    "steps, text", [(0, "0"), (500, "500"), (1_000, "1k"), (250_000, "250k"), (1_500_000, "1.5M"),
                    (3_000_000, "3M"), (700_950, "700.95k")],
)  # fmt: skip
def test_step_ticks_are_short(steps, text):
    assert figures.steps_label(steps) == text


def test_rank_trajectories_per_layer_and_seed_with_the_intrinsic_rank(runs):
    r = runs["adarl"]
    fig = figures.rank_trajectories(
        collect.rank_history(r), 7, "hopper adarl", collect.truncation_steps(r)
    )
    assert [ax.get_title() for ax in fig.axes] == [
        "hopper adarl: actor_1", "hopper adarl: q1_1", "hopper adarl: q2_1",
    ]  # fmt: skip
    ax = fig.axes[0]
    assert labels(ax) == ["seed 0", "seed 1", "seed 2", "$2d_a+1$ = 7", "truncation"]
    intrinsic = [ln for ln in ax.get_lines() if ln.get_label() == "$2d_a+1$ = 7"][0]
    assert list(intrinsic.get_ydata()) == [7, 7]
    assert ax.get_yscale() == "log" and len(red_dashed(ax)) == 3
    ranks = ax.get_lines()[0].get_ydata()
    assert ranks[0] == 64 and np.all(np.diff(ranks) <= 0)


def test_robustness_curve_one_line_per_method_over_the_swept_values(runs):
    frames = []
    for name in ("adarl", "sac"):
        (ev,) = [e for e in collect.evaluations(runs[name]) if e.swept]
        per_seed = ev.table.groupby(["seed", "p_torso_length"], as_index=False)["return"].mean()
        frames.append(
            per_seed.rename(columns={"p_torso_length": "value"}).assign(method=runs[name].label)
        )
    data = pd.concat(frames)
    fig = figures.robustness_curve(data, "torso_length", "hopper: torso_length", nominal=0.4)
    (ax,) = fig.axes
    assert labels(ax) == ["adarl", "sac", "nominal"]
    assert list(ax.get_lines()[0].get_xdata()) == TORSO
    assert ax.get_xlabel() == "torso_length" and ax.get_ylabel() == "return"
    assert len(ax.collections) == 2
    # the synthetic curve peaks at the nominal torso length
    assert np.argmax(ax.get_lines()[0].get_ydata()) == TORSO.index(0.4)


def test_bias_variance_marks_adarls_converged_rank(runs):
    frames = [collect.final_scores(runs[f"fixed{k}"])[0].assign(rank=k) for k in (2, 8, 32)]
    fig = figures.bias_variance(pd.concat(frames), [12, 14, 13], [900.0, 950.0, 1000.0], 7)
    (ax,) = fig.axes
    assert ax.get_xscale() == "log" and ax.get_xlabel() == "rank of the bottleneck"
    names = labels(ax)
    assert "AdaRL converged rank (13)" in names and "AdaRL" in names and "$2d_a+1$ = 7" in names
    assert len(ax.containers) == 1  # the fixed-rank error bars
    assert list(ax.containers[0].lines[0].get_xdata()) == [2, 8, 32]
    star = [ln for ln in ax.get_lines() if ln.get_label() == "AdaRL"][0]
    assert (star.get_xdata()[0], star.get_ydata()[0]) == (13, 950)


def test_rank_rule_ablation_one_line_per_rule(runs):
    histories = {
        "cumulative rule": collect.rank_history(runs["adarl"]),
        "ratio rule": collect.rank_history(runs["ratio"]),
    }
    fig = figures.rank_rule_ablation(histories, 7, "hopper")
    assert len(fig.axes) == 3
    assert labels(fig.axes[0]) == ["cumulative rule", "ratio rule", "$2d_a+1$ = 7"]
    assert fig.axes[0].get_legend() and not any(ax.get_legend() for ax in fig.axes[1:])
    cumulative, ratio = fig.axes[0].get_lines()[:2]
    assert cumulative.get_ydata()[-1] < ratio.get_ydata()[-1]  # the ratio rule stalls


def test_spectra_one_line_per_truncation(runs):
    spectra = collect.spectra(runs["adarl"])
    assert [s.step for s in spectra] == [2000, 4000, 6000]
    fig = figures.singular_value_spectra(spectra, "hopper adarl")
    assert len(fig.axes) == 3
    ax = fig.axes[0]
    assert labels(ax) == ["step 2000", "step 4000", "step 6000"]
    assert ax.get_yscale() == "log" and len(ax.get_lines()[0].get_xdata()) == 64


def test_aggregate_profile_and_improvement_figures():
    estimates = pd.DataFrame(
        [("adarl", "IQM", 0.8, 0.7, 0.9), ("sac", "IQM", 0.4, 0.3, 0.5),
         ("adarl", "Mean", 0.7, 0.6, 0.8), ("sac", "Mean", 0.5, 0.4, 0.6)],
        columns=["method", "metric", "point", "low", "high"],
    )  # fmt: skip
    fig = figures.aggregate_intervals(estimates)
    assert [ax.get_title() for ax in fig.axes] == ["IQM", "Mean"]
    assert [t.get_text() for t in fig.axes[0].get_yticklabels()] == ["sac", "adarl"]
    taus = np.linspace(0, 1, 11)
    profile = (np.linspace(1, 0, 11),) * 3
    fig = figures.performance_profiles(taus, {"adarl": profile, "sac": profile})
    assert labels(fig.axes[0]) == ["adarl", "sac"] and "τ" in fig.axes[0].get_xlabel()
    poi = pd.DataFrame([("sac", 0.9, 0.8, 1.0)], columns=["baseline", "point", "low", "high"])
    fig = figures.probability_of_improvement(poi)
    assert [t.get_text() for t in fig.axes[0].get_yticklabels()] == ["P(adarl > sac)"]
    assert fig.axes[0].get_xlim() == (0, 1)


def test_save_figure_writes_png_and_pdf_even_with_dots_in_the_name(tmp_path, runs):
    fig = figures.rank_trajectories(collect.rank_history(runs["adarl"]), 7)
    paths = figures.save_figure(fig, tmp_path / "ranks_foot_length-0.39")
    assert [p.name for p in paths] == ["ranks_foot_length-0.39.png", "ranks_foot_length-0.39.pdf"]
    assert paths[0].read_bytes()[:4] == b"\x89PNG" and paths[1].read_bytes()[:4] == b"%PDF"
    width_in = fig.get_size_inches()[0]
    assert width_in == pytest.approx(figures.FULL_WIDTH)  # paper size


def test_learning_rate_schedules_draws_both_schedules():
    fig = figures.learning_rate_schedules(total_steps=31_000, truncate_every=10_000)
    envelope, restart = (line.get_ydata() for line in fig.axes[0].get_lines()[:2])
    assert envelope[0] == restart[0] == pytest.approx(3e-3)  # both start at the base rate
    assert envelope.min() == 0.0 and restart.min() == 0.0  # each truncation warms up from zero
    assert envelope[-1] == pytest.approx(3e-4, rel=1e-2)  # the envelope ends at its floor
    # 31k steps, updates from step 1,000, 50 every 50 steps: 30,050 updates, cuts every 10k
    cuts = [line.get_xdata()[0] for line in fig.axes[0].get_lines()[2:]]
    assert cuts == [10_000, 20_000, 30_000]
