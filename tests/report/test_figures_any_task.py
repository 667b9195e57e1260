"""Issue 62: the report's figures for a robot that is not the paper's, with 1, 2 and 5 seeds.

A user's cart-pole (InvertedPendulum-v5 with their own XML, whose pole ends in a ball `bob` of
0.5 kg), or InvertedPendulum-v5 itself, swept over a body's mass: every point inside the axes
and clear of the legend, the nominal value drawn, bands within the returns the task can give
(0 to the time limit) or said to be normal-theory, the rank figure from the initial rank through
the first cut to the end, markers where a curve has few points (the words of index.md and of
the summary: test_index_words.py). Tiny synthetic run folders (`synthetic_runs`), no
training."""

import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.transforms import Bbox
from synthetic_runs import write_run, write_sweep

from adarl.envs.elements import address_default
from adarl.envs.tasks import get_task
from adarl.report import common, figures, ranks, robustness
from adarl.results.runs import find_runs

XML = """<mujoco model="cartpole_bob">
  <compiler angle="degree" inertiafromgeom="true"/>
  <option timestep="0.02"/>
  <worldbody>
    <body name="cart" pos="0 0 0">
      <joint name="slider" type="slide" axis="1 0 0" limited="true" range="-1 1"/>
      <geom name="cart" type="box" size="0.1 0.05 0.05" mass="1"/>
      <body name="pole" pos="0 0 0">
        <joint name="hinge" type="hinge" axis="0 1 0" limited="true" range="-90 90"/>
        <geom name="rod" type="capsule" fromto="0 0 0 0 0 0.6" size="0.02" mass="0.1"/>
        <body name="bob" pos="0 0 0.6">
          <geom name="bob" type="sphere" size="0.05" mass="0.5"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="push" joint="slider" gear="100" ctrlrange="-3 3" ctrllimited="true"/>
  </actuator>
</mujoco>
"""
TASK = "InvertedPendulum-v5"
LIMIT = 200  # the runs' time limit: a return is 0 to 200 (1 per step the pole is up)
BOB = [0.25, 0.5, 0.75, 1.0, 1.25]
SEEDS = {1: (0,), 2: (0, 1), 5: (0, 1, 2, 3, 4)}


@pytest.fixture()
def drawn(monkeypatch):
    """The figures a report section builds (instead of their files)."""
    found = []

    def keep(folder, fig, stem):
        found.append((stem, fig))
        return []

    monkeypatch.setattr(common, "save_figure", keep)
    return found


def balanced(value, seed, episode):
    """A policy that holds the pole for the whole episode, except under the heaviest bob."""
    return float(LIMIT if value < 1.2 else LIMIT - 10 - seed)


def spread(value, seed, episode):
    """Seeds far apart (200 and 20): a normal-theory band from 2 seeds reaches ±1,000."""
    return float(LIMIT if seed % 2 == 0 else 20)


def bob_runs(root, seeds, returns=balanced, xml=True, param="body:bob.mass", values=BOB, **kw):
    """One adarl run on the user's cart-pole (or InvertedPendulum-v5 itself), swept over
    `param`."""
    config = {"max_episode_steps": LIMIT}
    if xml:
        (root / "cartpole_bob.xml").write_text(XML)
        config["env_kwargs"] = f"xml_file={root / 'cartpole_bob.xml'}"
    run = write_run(
        root, "bob", algo="adarl", task=TASK, seeds=seeds, total_steps=6000, length=LIMIT,
        extra_config=config, **kw,
    )  # fmt: skip
    write_sweep(run, param, values, returns=returns)
    return find_runs([root])


def robustness_figure(tmp_path, drawn, seeds, returns=balanced, **kw):
    section = robustness.robustness_section(
        bob_runs(tmp_path, seeds, returns, **kw), tmp_path / "report", None, []
    )
    ((_, fig),) = drawn
    return section, fig


def data_lines(ax):
    """The method curves: the lines with a marker at each swept value."""
    return [ln for ln in ax.get_lines() if ln.get_marker() == "o"]


def legends(fig):
    return [*fig.legends, *(ax.get_legend() for ax in fig.axes if ax.get_legend())]


# ----------------------------------------------------------------------------- robustness
@pytest.mark.parametrize("n", SEEDS)
def test_every_point_lies_inside_the_axes_clear_of_the_spines(tmp_path, drawn, n):
    """Returns at the task's maximum: the points must not sit on the top spine, half cut."""
    _, fig = robustness_figure(tmp_path, drawn, SEEDS[n])
    (ax,) = fig.axes
    (low, high), (left, right) = ax.get_ylim(), ax.get_xlim()
    (line,) = data_lines(ax)
    x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
    assert y.max() == LIMIT
    margin_y, margin_x = 0.03 * (high - low), 0.03 * (right - left)
    assert (y >= low + margin_y).all() and (y <= high - margin_y).all(), (low, high, y)
    assert (x >= left + margin_x).all() and (x <= right - margin_x).all(), (left, right, x)


@pytest.mark.parametrize("n", SEEDS)
@pytest.mark.parametrize("returns", [balanced, spread])
def test_the_legend_covers_no_point_line_or_band(tmp_path, drawn, n, returns):
    _, fig = robustness_figure(tmp_path, drawn, SEEDS[n], returns)
    FigureCanvasAgg(fig).draw()
    (ax,) = fig.axes
    (legend,) = legends(fig)
    box = legend.get_window_extent()
    for line in data_lines(ax):
        radius = line.get_markersize() * fig.dpi / 72 / 2
        points = ax.transData.transform(np.column_stack([line.get_xdata(), line.get_ydata()]))
        covered = [
            (x, y)
            for x, y in points
            if box.overlaps(Bbox.from_extents(x - radius, y - radius, x + radius, y + radius))
        ]
        assert not covered, f"the legend {box} covers the points {covered}"
        assert not ax.transData.transform_path(line.get_path()).intersects_bbox(box, filled=False)
    for band in ax.collections:
        for path in band.get_paths():
            assert not ax.transData.transform_path(path).intersects_bbox(box, filled=True)
    texts = [fig._suptitle, fig._supxlabel, ax.title, ax.xaxis.label, ax.yaxis.label]
    for text in (t for t in texts if t is not None and t.get_text()):  # nor the words around
        assert not box.overlaps(text.get_window_extent()), text.get_text()


@pytest.mark.parametrize(
    "xml, param, values, nominal",
    [
        (True, "body:bob.mass", BOB, 0.5),  # the user's XML: bob's mass
        (False, "body:pole.mass", [3.0, 4.0, 5.0, 6.0, 7.0], None),  # InvertedPendulum-v5's own
        (False, "gravity", [7.0, 8.0, 9.0, 10.0, 11.0], 9.81),  # a generic parameter
    ],
)
def test_the_nominal_value_of_the_swept_parameter_is_drawn(
    tmp_path, drawn, xml, param, values, nominal
):
    """No `adarl evaluate --dynamics nominal` needed: the nominal value is the task's."""
    if nominal is None:
        nominal = address_default(_pendulum_xml(), param)
    section, fig = robustness_figure(
        tmp_path, drawn, (0, 1), lambda v, s, e: 150.0 + s, xml=xml, param=param, values=values
    )
    (ax,) = fig.axes
    lines = [ln for ln in ax.get_lines() if ln.get_label() == "nominal"]
    assert len(lines) == 1, [ln.get_label() for ln in ax.get_lines()]
    (line,) = lines
    assert list(line.get_xdata()) == pytest.approx([nominal, nominal])
    assert line.get_linestyle() == ":" and line.get_color() == "grey"
    assert "grey dotted line: the nominal value" in section.text.lower()


def _pendulum_xml():
    from adarl.envs.dynamics import xml_path

    return xml_path(get_task(TASK, env_kwargs=""))  # Gymnasium's own, not the last one made


@pytest.mark.parametrize("n", [2, 5])
def test_a_band_stays_within_the_returns_the_task_can_give(tmp_path, drawn, n):
    """Returns 200 and 20 of at most 200: the band is clipped to [0, 200], and the text says so
    and says what the y-axis shows."""
    section, fig = robustness_figure(tmp_path, drawn, SEEDS[n], spread)
    (ax,) = fig.axes
    (band,) = ax.collections
    ys = np.concatenate([path.vertices[:, 1] for path in band.get_paths()])
    assert ys.min() >= 0 and ys.max() <= LIMIT, (ys.min(), ys.max())
    assert "0 to 200" in section.text and "clipped" in section.text
    low, high = ax.get_ylim()
    assert low <= 0 <= high and ("starts at 0" not in section.text or low == 0)


def test_a_band_of_a_task_without_a_known_range_is_said_to_be_normal_theory(tmp_path, drawn):
    run = write_run(tmp_path, "adarl", algo="adarl", seeds=(0, 1))  # Hopper: any return
    write_sweep(run, "torso_length", [0.3, 0.4, 0.5], returns=lambda v, s, e: 900.0 * s + 10)
    section = robustness.robustness_section(find_runs([tmp_path]), tmp_path / "r", None, [])
    ((_, fig),) = drawn
    (ax,) = fig.axes
    ys = np.concatenate([path.vertices[:, 1] for path in ax.collections[0].get_paths()])
    assert ys.min() < 0  # the t band itself, not clipped: nothing is known to bound a return
    assert "normal theory" in section.text
    low, high = ax.get_ylim()
    assert low <= ys.min() and ("starts at 0" not in section.text or low == 0)


@pytest.mark.parametrize("n", SEEDS)
def test_the_size_curve_keeps_every_point_inside_its_panels(n):
    """Return against the size of the perturbation: the nominal ring (size 0) and returns at the
    task's maximum are not cut in half by the left or top spine; the legend is under the panels."""
    rows = [
        (m, s, ring, float(LIMIT) - 40 * ring * (m == "sac"), float(LIMIT) - 60 * ring - s)
        for m in ("adarl", "sac")
        for s in SEEDS[n]
        for ring in (0.0, 0.5, 1.0, 1.5)
    ]
    data = pd.DataFrame(rows, columns=["method", "seed", "ring", "mean", "worst_within"])
    fig = figures.robustness_size_curve(data, bounds=(0.0, LIMIT))
    FigureCanvasAgg(fig).draw()
    (legend,) = legends(fig)
    for ax in fig.axes:
        (low, high), (left, right) = ax.get_ylim(), ax.get_xlim()
        for line in data_lines(ax):
            x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
            assert (x >= left + 0.03 * (right - left)).all(), (left, x)
            assert (y <= high - 0.03 * (high - low)).all(), (high, y)
        assert legend.get_window_extent().y1 < ax.get_window_extent().y0


# ----------------------------------------------------------------------------- training curves
@pytest.mark.parametrize("n", SEEDS)
@pytest.mark.parametrize("evaluations, marked", [(1, True), (2, True), (30, True), (40, False)])
def test_a_curve_of_few_evaluations_has_markers(tmp_path, drawn, n, evaluations, marked):
    """Two evaluations were a bare straight line (one: nothing at all)."""
    runs = bob_runs(
        tmp_path, SEEDS[n], n_evals=evaluations, eval_returns=lambda step, s, e: 100.0 + 10 * s
    )
    ranks.training_section(runs, tmp_path / "report", None)
    ((_, fig),) = drawn
    ax = fig.axes[0]
    (line,) = [ln for ln in ax.get_lines() if ln.get_label() == "adarl"]
    assert len(line.get_xdata()) == evaluations
    assert (line.get_marker() not in ("None", None, "")) == marked, line.get_marker()
    if evaluations == 1 and n > 1:  # the interval of one evaluation: a vertical bar, not a band
        (bar,) = ax.collections
        ((bottom, top),) = [seg[:, 1] for seg in bar.get_segments()]
        assert bottom < line.get_ydata()[0] < top


@pytest.mark.parametrize("n", [2, 5])
def test_the_training_band_stays_within_the_returns_the_task_can_give(tmp_path, drawn, n):
    runs = bob_runs(
        tmp_path, SEEDS[n], eval_returns=lambda step, s, e: float(LIMIT if s % 2 else 20)
    )
    section = ranks.training_section(runs, tmp_path / "report", None)
    ((_, fig),) = drawn
    ys = np.concatenate([path.vertices[:, 1] for path in fig.axes[0].collections[0].get_paths()])
    assert ys.min() >= 0 and ys.max() <= LIMIT
    assert "0 to 200" in section.text


@pytest.mark.parametrize("n", SEEDS)
@pytest.mark.parametrize("evaluations", [1, 2, 5])
def test_the_training_legend_covers_no_point_line_or_band(tmp_path, drawn, n, evaluations):
    runs = bob_runs(
        tmp_path,
        SEEDS[n],
        n_evals=evaluations,
        eval_returns=lambda step, s, e: float(LIMIT if s % 2 else 20 + step / 100),
    )
    ranks.training_section(runs, tmp_path / "report", None)
    ((_, fig),) = drawn
    FigureCanvasAgg(fig).draw()
    (legend,) = legends(fig)
    box = legend.get_window_extent()
    for ax in (ax for ax in fig.axes if ax.get_visible()):
        for line in ax.get_lines():
            points = ax.transData.transform(np.column_stack([line.get_xdata(), line.get_ydata()]))
            if line.get_label() == "adarl":
                radius = line.get_markersize() * fig.dpi / 72 / 2
                assert not any(
                    box.overlaps(Bbox.from_extents(x - radius, y - radius, x + radius, y + radius))
                    for x, y in points
                )
            assert not ax.transData.transform_path(line.get_path()).intersects_bbox(box, False)
        for band in ax.collections:
            for path in band.get_paths():
                assert not ax.transData.transform_path(path).intersects_bbox(box, filled=True)


# ----------------------------------------------------------------------------- ranks
def test_the_rank_figure_shows_the_initial_rank_every_cut_and_the_last_level(tmp_path, drawn):
    """The first cut (step 2,450) comes before the first log row (2,500), the last (7,450) after
    the last (7,000): each seed's line starts at the initial rank 64, drops at every cut and
    holds its last level to the end of the run."""
    run = write_run(tmp_path, "bob", algo="adarl", task=TASK, seeds=(0, 1), total_steps=10_000)
    cuts = pd.read_csv(run / "truncations.csv")
    cuts["step"] -= 50  # 2,450, 4,950, 7,450
    cuts.to_csv(run / "truncations.csv", index=False)
    train = pd.read_csv(run / "train.csv")
    train[(train["step"] > 2_450) & (train["step"] <= 7_000)].to_csv(run / "train.csv", index=False)
    ranks.rank_section(find_runs([tmp_path]), tmp_path / "report")
    ((_, fig),) = drawn
    for ax in fig.axes:
        layer = ax.get_title().split(": ")[-1]
        for seed in (0, 1):
            (line,) = [ln for ln in ax.get_lines() if ln.get_label() == f"seed {seed}"]
            x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
            mine = cuts[(cuts["seed"] == seed) & (cuts["layer"] == layer)].sort_values("step")
            assert (x[0], y[0]) == (0, 64), (layer, seed, x, y)
            for cut in mine.itertuples():  # the rank before and after each cut
                assert y[x < cut.step][-1] == cut.old_rank and y[x == cut.step][-1] == cut.new_rank
            assert (x[-1], y[-1]) == (10_000, mine["new_rank"].iloc[-1])
        assert "64" in [t.get_text() for t in ax.texts]


# ----------------------------------------------------------------------------- bounds
def test_return_bounds_only_where_the_reward_function_bounds_the_return():
    from adarl.envs.tasks import return_bounds

    assert return_bounds(get_task(TASK, env_kwargs=""), 200) == (0.0, 200.0)
    assert return_bounds(get_task("InvertedDoublePendulum-v5", env_kwargs=""), 1000) == (
        -np.inf,
        10_000.0,
    )
    changed = get_task("InvertedDoublePendulum-v5", env_kwargs="healthy_reward=20")
    assert return_bounds(changed, 1000) == (-np.inf, np.inf)  # not the default reward
    assert return_bounds(get_task("hopper"), 1000) == (-np.inf, np.inf)


def test_the_band_text_names_the_range_or_says_normal_theory():
    assert "InvertedPendulum-v5: 0 to 200" in common.band_text({TASK: (0.0, 200.0)})
    mixed = common.band_text({"Reacher-v5": (-np.inf, 0.0), "hopper": (-np.inf, np.inf)})
    assert "Reacher-v5: at most 0; other tasks' bands not clipped" in mixed
    assert "may reach returns the task cannot give" in common.band_text(
        {"hopper": (-np.inf, np.inf)}
    )
