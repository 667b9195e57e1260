"""docs/experiments/evidence.py recomputes the shipped experiments' numbers from committed rows
(issue 34 §2). Expected values are the ones the reports and the issue state, written down from
their text, not from the script's output."""

import importlib.util
from pathlib import Path

import pytest

SCRIPT = Path(__file__).parents[2] / "docs/experiments/evidence.py"


@pytest.fixture(scope="module")
def results():
    spec = importlib.util.spec_from_file_location("evidence", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.compute()


def test_mechanism_hopper(results):
    (r,) = results["mechanism-hopper"]
    assert r["difference"] == pytest.approx(-323, abs=1)
    assert (r["t_low"], r["t_high"]) == pytest.approx((-708, 62), abs=1)
    assert r["t_p"] == pytest.approx(0.090, abs=0.001)
    assert r["perm_p"] == pytest.approx(0.057, abs=0.001)
    assert (r["perm"].low, r["perm"].high) == pytest.approx((-748.5, 4.7), abs=0.5)
    assert r["sd"] == pytest.approx(538, abs=1) and r["detectable"] == pytest.approx(536, abs=1)


def test_mechanism_walker2d(results):
    (r,) = results["mechanism-walker2d"]
    assert r["difference"] == pytest.approx(138, abs=1)
    assert (r["t_low"], r["t_high"]) == pytest.approx((-53, 328), abs=1)
    assert r["t_p"] == pytest.approx(0.137, abs=0.001)  # the pre-registered test
    assert r["perm_p"] == pytest.approx(0.002, abs=0.0001)
    assert r["sd"] == pytest.approx(267, abs=1) and r["detectable"] == pytest.approx(265, abs=1)


def test_physics_power(results):
    consistent, _, paper_ompo = results["physics-power"]
    assert consistent["difference"] == pytest.approx(-334, abs=1)
    assert (consistent["t_low"], consistent["t_high"]) == pytest.approx((-790, 123), abs=1)
    assert paper_ompo["difference"] == pytest.approx(286, abs=1)
    assert (paper_ompo["t_low"], paper_ompo["t_high"]) == pytest.approx((44, 528), abs=1)
    assert paper_ompo["perm_p"] == pytest.approx(0.025, abs=0.001)
    assert paper_ompo["holm_p"] == pytest.approx(0.075, abs=0.002)  # the referee's figure


def test_paper_schedule_hopper_3m(results):
    """From the per-seed table of paper-schedule-hopper.md (rounded there: ±2 points)."""
    control, sac = results["paper-schedule-hopper"]
    assert control["difference"] == pytest.approx(336, abs=2)
    assert (control["t_low"], control["t_high"]) == pytest.approx((-890, 1562), abs=2)
    assert control["t_p"] == pytest.approx(0.49, abs=0.005)
    assert control["sd"] == pytest.approx(987, abs=2)
    assert control["detectable_range"] == pytest.approx((995, 4772), abs=5)
    assert sac["difference"] == pytest.approx(182, abs=2)
    assert (sac["t_low"], sac["t_high"]) == pytest.approx((-1341, 1705), abs=2)
    assert sac["t_p"] == pytest.approx(0.79, abs=0.005)
    assert sac["sd"] == pytest.approx(1042, abs=2)
    means = {r["comparison"].split()[0]: r for r in results["paper-schedule-hopper-means"]}
    assert means["adarl"]["mean"] == pytest.approx(2102, abs=1)
    assert means["adarl"]["sd"] == pytest.approx(979, abs=2)
    assert means["sac"]["mean"] == pytest.approx(1920, abs=1)
    assert means["sac"]["sd"] == pytest.approx(1101, abs=2)
