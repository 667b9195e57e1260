"""What a reader takes from the figures is in the data: a spectrum shows only the network's own
components (no padding to the width it is stored at), a robustness axis includes 0 and the
figure says which point the sweep moves away from, and a rank panel's levels can be read."""

import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from synthetic_runs import write_run, write_sweep

from adarl.report import common, figures, ranks, robustness
from adarl.results import collect
from adarl.results.collect import Spectrum
from adarl.results.runs import find_runs


@pytest.fixture()
def drawn(monkeypatch):
    """The figures a report section builds (instead of their files)."""
    found = []

    def keep(folder, fig, stem):
        found.append((stem, fig))
        return []

    monkeypatch.setattr(common, "save_figure", keep)
    return found


def _cuts(rows):
    return pd.DataFrame(rows, columns=["step", "seed", "layer", "old_rank"])


# ----------------------------------------------------------------------------- spectra
def test_a_spectrum_stops_at_the_networks_rank_before_the_cut():
    """q1 of rank 3 stored at q2's width 4: its 4th value (3e-05, the SVD's noise on a zero
    component) is not drawn; q2 keeps its 4."""
    spectrum = Spectrum(
        30_000,
        {"q1_1": np.array([[3.0, 1.0, 0.5, 3e-5]]), "q2_1": np.array([[2.5, 1.2, 0.6, 0.2]])},
        np.array([0]),
    )
    cuts = _cuts([(30_000, 0, "q1_1", 3), (30_000, 0, "q2_1", 4)])
    fig = figures.singular_value_spectra([spectrum], "hopper adarl", cuts)
    q1, q2 = (ax.get_lines()[0] for ax in fig.axes)
    assert list(q1.get_xdata()) == [1, 2, 3] and list(q1.get_ydata()) == [3.0, 1.0, 0.5]
    assert list(q2.get_ydata()) == [2.5, 1.2, 0.6, 0.2]


def test_each_seed_contributes_its_own_components_to_the_mean():
    """Seeds of rank 3 and 2 in one lane, stored at width 4: σ_1, σ_2 are means over both, σ_3
    is seed 0's alone (seed 1 has no third component), nothing past 3."""
    layer = np.array([[3.0, 1.0, 0.5, 3e-5], [2.0, 0.8, 2e-5, 0.0]])
    spectrum = Spectrum(100, {"actor_1": layer}, np.array([4, 7]))
    cuts = _cuts([(100, 4, "actor_1", 3), (100, 7, "actor_1", 2), (200, 4, "actor_1", 1)])
    sigma = figures.network_spectrum(spectrum, "actor_1", cuts)
    assert sigma.tolist() == pytest.approx([2.5, 0.9, 0.5])
    # without the ranks only the padding zeros go
    assert figures.network_spectrum(spectrum, "actor_1").tolist() == pytest.approx(
        [2.5, 0.9, (0.5 + 2e-5) / 2, 3e-5]
    )


def test_the_reports_spectra_figure_draws_each_truncation_up_to_the_ranks(tmp_path, drawn):
    write_run(tmp_path, "adarl", algo="adarl", n_truncations=3, total_steps=8000)
    (run,) = find_runs([tmp_path])
    ranks.spectra_section([run], tmp_path / "report")
    ((stem, fig),) = drawn
    assert stem.startswith("spectra_")
    cuts = collect.read_table(run.path / "truncations.csv")
    for ax in fig.axes:
        layer = ax.get_title().split(": ")[-1]
        widest = cuts[cuts["layer"] == layer].groupby("step")["old_rank"].max()
        assert [len(line.get_xdata()) for line in ax.get_lines()] == widest.tolist()
        assert widest.tolist()[-1] < 64  # the stored spectra are 64 wide


# ----------------------------------------------------------------------------- robustness
def _sweep(returns_by_method):
    rows = [
        (method, seed, value, ret + seed)
        for method, returns in returns_by_method.items()
        for seed in (0, 1)
        for value, ret in zip((0.3, 0.4, 0.5), returns)
    ]
    return pd.DataFrame(rows, columns=["method", "seed", "value", "return"])


def test_the_robustness_axis_starts_at_zero():
    """Returns 313–320: a 2% spread must not fill the axis."""
    data = _sweep({"adarl": [313.0, 318.0, 315.0], "sac": [314.0, 317.0, 316.0]})
    fig = figures.robustness_curve(data, "torso_length", nominal=0.4)
    low, high = fig.axes[0].get_ylim()
    assert low == 0 and high >= 319
    negative = figures.robustness_curve(_sweep({"sac": [-40.0, 10.0, -5.0]}), "torso_length")
    low, high = negative.axes[0].get_ylim()
    assert low <= -40 and high >= 11  # nothing cut off; 0 inside


def test_the_robustness_size_curve_starts_at_zero_too():
    rows = [
        (m, s, ring, 300.0 + ring + s, 290.0 + ring)
        for m in ("adarl", "sac")
        for s in (0, 1)
        for ring in (0.0, 0.5, 1.0)
    ]
    data = pd.DataFrame(rows, columns=["method", "seed", "ring", "mean", "worst_within"])
    fig = figures.robustness_size_curve(data)
    assert all(ax.get_ylim()[0] == 0 for ax in fig.axes)


def test_the_reports_robustness_figure_states_its_base_point(tmp_path, drawn):
    write_run(tmp_path, "adarl", algo="adarl", n_truncations=3, total_steps=8000)
    write_sweep(tmp_path / "adarl", "torso_length", [0.3, 0.4, 0.5], hold={"foot_length": 0.39})
    section = robustness.robustness_section(find_runs([tmp_path]), tmp_path / "r", None, [])
    ((_, fig),) = drawn
    base = fig._supxlabel.get_text().replace("\n", " ")
    assert base == "base: nominal dynamics; foot_length 0.39"
    assert fig.axes[0].get_ylim()[0] == 0
    assert "base point" in section.text and "a y-axis that includes 0" in section.text


def test_the_base_point_lists_every_other_parameter():
    table = pd.DataFrame(
        {"p_torso_length": [0.3, 0.4], "p_foot_length": [0.39, 0.39], "p_mass": [1.0, 2.0]}
    )
    text = robustness.base_point(table, "torso_length", "fixed:foot_length=0.39")
    assert text == "fixed:foot_length=0.39 dynamics; foot_length 0.39, mass varies"


# ----------------------------------------------------------------------------- ranks
LEVELS = {  # the quickstart's shape: 4 truncations, one seed (issue 57)
    "actor_1": [64, 35, 30, 27, 26],
    "q1_1": [64, 20, 16, 15, 14],
    "q2_1": [64, 21, 17, 16, 15],
}
STEPS = [5_000, 30_000, 60_000, 90_000, 120_000]


def _history(levels, seeds=(0,)):
    rows = []
    for seed in seeds:
        for layer, ranks_ in levels.items():
            path = ranks_ if isinstance(ranks_[0], int) else ranks_[seed]
            rows += [(step, seed, layer, r) for step, r in zip(STEPS, path)]
            rows.append((150_000, seed, layer, path[-1]))
    return pd.DataFrame(rows, columns=["step", "seed", "layer", "rank"])


def _texts(ax):
    return [t for t in ax.texts if t.get_visible() and t.get_text()]


def _tick_labels(ax):
    low, high = ax.get_ylim()
    return [
        t
        for t, v in zip(ax.get_yticklabels(), ax.get_yticks())
        if t.get_visible() and t.get_text() and low <= v <= high
    ]


def _overlapping(texts, renderer):
    boxes = [t.get_window_extent(renderer) for t in texts]
    return [
        (texts[i].get_text(), texts[j].get_text())
        for i in range(len(boxes))
        for j in range(i + 1, len(boxes))
        if boxes[i].overlaps(boxes[j])
    ]


def test_every_rank_level_can_be_read_in_its_panel():
    fig = figures.rank_trajectories(_history(LEVELS), 7, "hopper adarl", STEPS[1:])
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    for ax in fig.axes:
        layer = ax.get_title().split(": ")[-1]
        written = {float(t.get_text()) for t in _texts(ax)}
        assert written == set(map(float, LEVELS[layer])), layer
        assert not _overlapping(_texts(ax), renderer), layer
        # each label sits at its level's start, just above it
        for text in _texts(ax):
            x, y = text.xy
            assert y == float(text.get_text()) and x in STEPS
        assert not _overlapping(_tick_labels(ax), renderer), layer
        assert ax.get_ylim()[1] > 64  # room above the top level's label
    ticks = {t.get_text() for t in _tick_labels(fig.axes[0])}
    assert {"8", "12", "16", "24", "32", "48", "64"} <= ticks  # 7 to 64: two per octave


def test_close_levels_of_several_seeds_share_one_label():
    levels = {"actor_1": [[64, 35, 30, 27, 26], [64, 36, 30, 28, 27], [64, 37, 30, 28, 28]]}
    fig = figures.rank_trajectories(_history(levels, seeds=(0, 1, 2)), 7)
    FigureCanvasAgg(fig).draw()
    texts = [t.get_text() for t in _texts(fig.axes[0])]
    assert sorted(texts, key=lambda t: float(t.split(",")[0].split("–")[0])) == [
        "26, 27",
        "27, 28",
        "30",
        "35–37",
        "64",
    ]  # fmt: skip: seed 2 stays at 28 at the last cut (no new level)


@pytest.mark.parametrize(
    ("low", "high", "expected"),
    [
        (14, 64, [14, 16, 20, 24, 28, 32, 40, 48, 56, 64]),  # up to 2.5 octaves: four per octave
        (7, 64, [8, 12, 16, 24, 32, 48, 64]),  # up to 5: two
        (1, 256, [1, 2, 4, 8, 16, 32, 64, 128, 256]),  # more: the powers of two
    ],
)
def test_log2_ticks_are_integers_as_dense_as_the_range_allows(low, high, expected):
    assert figures.Log2Ticks().tick_values(low, high) == expected


def test_a_long_schedule_writes_only_the_first_and_last_levels():
    steps = [1000 * k for k in range(20)]
    history = pd.DataFrame(
        [(step, 0, "actor_1", 64 - k) for k, step in enumerate(steps)],
        columns=["step", "seed", "layer", "rank"],
    )
    assert len(steps) > figures.MAX_LEVEL_STEPS
    fig = figures.rank_trajectories(history, 7)
    assert sorted(t.get_text() for t in _texts(fig.axes[0])) == ["45", "64"]
