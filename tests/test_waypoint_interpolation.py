"""Waypoint paths without overshoot: the shape-preserving (pchip) curve through the waypoints."""

import math

import numpy as np
import pytest

from mpcdrive.paths import WaypointPath
from mpcdrive.scenarios import build_experiment, dump_scenario, validate_scenario_data, warn_suspicious
from mpcdrive.scenarios.loader import ScenarioError
from mpcdrive.types import ScenarioWarning

CORNER = [[0.0, 0.0], [5.0, 0.0], [5.0, 5.0]]


def _distance_to_polyline(xy, pts):
    pts = np.asarray(pts, float)
    best = np.full(len(xy), np.inf)
    for a, b in zip(pts[:-1], pts[1:]):
        d = b - a
        t = np.clip((xy - a) @ d / (d @ d), 0.0, 1.0)
        best = np.minimum(best, np.hypot(*(xy - a - t[:, None] * d).T))
    return best


def _samples(p, n=4001):
    return p.position(np.linspace(0.0, p.length_m, n))


def test_corner_stays_on_the_polyline_and_the_first_leg_is_straight():
    p = WaypointPath(CORNER, interpolation="pchip")
    # the table step (2 mm here) bounds the chord error of the linear interpolation between entries
    assert _distance_to_polyline(_samples(p), CORNER).max() < 0.02
    s = np.linspace(0.0, 4.9, 50)
    np.testing.assert_allclose(p.heading(s), 0.0, atol=1e-6)
    np.testing.assert_allclose(p.heading(np.linspace(5.1, p.length_m, 50)), math.pi / 2, atol=1e-6)
    assert p.length_m == pytest.approx(10.0, abs=0.01)
    # the spline (the library's default) overshoots: this is what the option exists for
    spline = WaypointPath(CORNER)
    assert _distance_to_polyline(_samples(spline), CORNER).max() > 0.3
    assert abs(spline.heading(0.0)) > math.radians(10)


@pytest.mark.parametrize(
    "pts, closed",
    [
        (CORNER, False),
        ([[0, 0], [3, 1], [6, -1], [9, 0.5], [12, 0]], False),
        ([[0, 0], [4, 0], [5, 3], [2, 5], [-1, 3]], True),
        ([[0, 0], [10, 0], [10, 10], [0, 10]], True),
    ],
)
def test_pchip_passes_through_every_waypoint(pts, closed):
    p = WaypointPath(pts, closed=closed, interpolation="pchip")
    xy = _samples(p, 20001)
    for q in np.asarray(pts, float):
        assert np.hypot(*(xy - q).T).min() < 1e-3
        assert abs(p.project(q)[1]) < p._ds  # between two table points at most
    # never outside the bounding box of the two waypoints it joins (no overshoot)
    lo, hi = np.min(pts, axis=0), np.max(pts, axis=0)
    assert np.all(xy >= lo - 1e-9) and np.all(xy <= hi + 1e-9)
    # arc-length parameterization and a continuous heading over a lap
    s = np.linspace(0.1, p.length_m - 0.1, 300)
    v = (p.position(s + 1e-3) - p.position(s - 1e-3)) / 2e-3
    np.testing.assert_allclose(np.hypot(*v.T), 1.0, atol=2e-3)
    if closed:
        assert p.heading(p.length_m) - p.heading(0.0) == pytest.approx(2 * math.pi, abs=1e-6)


def test_pchip_curvature_matches_the_heading():
    # the curvature table is the heading's derivative: its integral is the heading change
    p = WaypointPath([[0, 0], [3, 1], [6, -1], [9, 0.5], [12, 0]], interpolation="pchip")
    s = np.linspace(0.0, p.length_m, 20001)
    k = p.curvature(s)
    turned = np.sum(0.5 * (k[1:] + k[:-1]) * np.diff(s))
    assert turned == pytest.approx(p.heading(p.length_m) - p.heading(0.0), abs=1e-3)


def test_pchip_refuses_smoothing():
    with pytest.raises(ValueError, match="smoothing"):
        WaypointPath(CORNER, smoothing=1.0, interpolation="pchip")
    with pytest.raises(ValueError, match="interpolation"):
        WaypointPath(CORNER, interpolation="cubic")


def _scenario(path):
    return {
        "id": "w",
        "duration_s": 0.05,
        "dt_s": 0.01,
        "path": path,
        "initial_state": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0},
        "controller": {"horizon": 5, "Q": [1, 1, 1], "R": [1]},
    }


def test_scenario_files_default_to_pchip_and_smoothing_keeps_the_spline():
    spec = validate_scenario_data(_scenario({"type": "waypoints", "points": CORNER}), "s.yaml")
    assert spec.path.interpolation == "pchip"
    # the paper car cannot turn this corner: said where the scenario is loaded, naming the file
    with pytest.warns(ScenarioWarning, match="s.yaml: path.points"):
        warn_suspicious(spec, "s.yaml")
    exp = build_experiment(spec)
    assert exp.path.interpolation == "pchip" and abs(exp.path.heading(1.0)) < 1e-9
    smooth = validate_scenario_data(_scenario({"type": "waypoints", "points": CORNER, "smoothing": 0.5}), "s.yaml")
    assert smooth.path.interpolation == "spline"
    named = validate_scenario_data(
        _scenario({"type": "waypoints", "points": CORNER, "interpolation": "spline"}), "s.yaml"
    )
    assert build_experiment(named).path.interpolation == "spline"  # a wide arc: drivable, no warning
    # the resolved choice is written out, so a dumped scenario rebuilds the same path
    assert "interpolation: pchip" in dump_scenario(spec)


@pytest.mark.parametrize(
    "path, field, words",
    [
        ({"type": "waypoints", "points": CORNER, "smoothing": 0.5, "interpolation": "pchip"}, "path", "smoothing"),
        ({"type": "waypoints", "points": CORNER, "interpolation": "akima"}, "path.interpolation", "pchip"),
    ],
)
def test_bad_interpolation_is_one_line(path, field, words):
    with pytest.raises(ScenarioError) as e:
        validate_scenario_data(_scenario(path), "s.yaml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"s.yaml: {field}") and words in msg
