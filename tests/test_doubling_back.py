"""A path that doubles back onto its own band of road is bad input (one line naming the file,
``path.points`` and where; exit 2): its positions there have two arc lengths, and the lane
excess measured from the wrong one was metres. Curves, corners, hairpins that keep their legs
apart, closed tracks and every shipped scenario, track and CommonRoad file are accepted."""

from __future__ import annotations

import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from mpcdrive.paths import CirclePath, WaypointPath
from mpcdrive.scenarios import ScenarioError, build_experiment, builtin_ids, load_scenario, validate_scenario_data
from mpcdrive.scenarios.build import build_path, build_road, load_track, path_doubles_back

# the drive: out 5 m and straight back along the same line, in a 1 m lane
UTURN = """\
id: uturn
dt_s: 0.01
duration_s: 30.0
vehicle: {model: kinematic3, speed_mps: 1.0, lf_m: 0.17, lr_m: 0.16}
path: {type: waypoints, points: [[0, 0], [5, 0], [0, 0]]}
road: {lane_width_m: 1.0, margin_m: 0.05}
initial_state: {x_m: 0.0, y_m: 0.0, yaw_deg: 0}
controller: {horizon: 10, Q: [1, 1, 1], R: [1], max_steer_deg: 60}
"""

CR = Path(__file__).resolve().parent / "data"


def _spec(points, road=None, closed=False):
    data = {
        "id": "p",
        "dt_s": 0.05,
        "duration_s": 1.0,
        "vehicle": {"model": "kinematic3", "speed_mps": 1.0},
        "path": {"type": "waypoints", "points": points, "closed": closed},
        "initial_state": {"x_m": float(points[0][0]), "y_m": float(points[0][1]), "yaw_deg": 0.0},
        "controller": {"horizon": 5, "Q": [1, 1, 1], "R": [1]},
    }
    if road is not None:
        data["road"] = road
    return validate_scenario_data(data, "p.yaml")


def _problem(spec):
    path = build_path(spec.path)
    return path_doubles_back(spec, path, build_road(spec.road, path))


def test_the_cli_rejects_a_path_that_doubles_back(tmp_path):
    f = tmp_path / "uturn.yaml"
    f.write_text(UTURN)
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "mpcdrive.cli", "run", str(f), "--out", str(out)], capture_output=True, text=True
    )
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, lines  # the error alone: no curvature warning before it
    assert lines[0].startswith(f"mpcdrive: {f}: path.points: the path doubles back at point 1 (5, 0) m")
    assert not out.exists()


def test_the_library_rejects_it_naming_the_field():
    spec = _spec([[0, 0], [5, 0], [0, 0]], {"lane_width_m": 1.0})
    with pytest.raises(ValueError, match=r"^path.points: the path doubles back at point 1 \(5, 0\) m"):
        build_experiment(spec)


def test_loading_it_is_a_scenario_error(tmp_path):
    f = tmp_path / "uturn.yaml"
    f.write_text(UTURN)
    with pytest.raises(ScenarioError) as e:
        load_scenario(f)
    assert e.value.field == "path.points" and "point 1" in e.value.problem


@pytest.mark.parametrize(
    "points, road, closed, doubles",
    [
        ([[0, 0], [5, 0], [0, 0]], None, False, True),  # straight back, even without a road (the body)
        ([[0, 0], [5, 0], [0, 0.3]], {"lane_width_m": 1.0}, False, True),  # back 0.3 m to the side
        ([[0, 0], [5, 0], [5, 0.4], [0, 0.4]], {"lane_width_m": 1.0}, False, "pchip"),  # a U-turn onto the lane
        # (the spline through those points swings out into a loop 4 m wide: it does not)
        ([[0, 0], [5, 0], [5, 3], [0, 3]], {"lane_width_m": 1.0}, False, False),  # legs 3 m apart
        ([[0, 0], [5, 0], [5, 5]], {"lane_width_m": 1.0}, False, False),  # a 90 deg corner
        ([[0, 0], [5, 0], [0, 1.5]], {"lane_width_m": 1.0}, False, True),  # a 163 deg turn: legs overlap
        ([[0, 0], [5, 0], [0, 4]], {"lane_width_m": 1.0}, False, False),  # a 141 deg turn
        ([[0, 0], [5, 0], [5, 5], [0, 5]], {"lane_width_m": 1.0}, True, False),  # a closed square
        ([[0, 0], [20, 0], [20, 20], [0, 20], [0, 0.6]], {"lane_width_m": 1.0}, False, False),  # around a block
    ],
)
def test_what_doubles_back(points, road, closed, doubles):
    """``doubles``: for both curves through the points, neither, or only the one named."""
    for interpolation in ("pchip", "spline"):
        spec = _spec(points, road, closed)
        spec = spec.model_copy(update={"path": spec.path.model_copy(update={"interpolation": interpolation})})
        expected = doubles if isinstance(doubles, bool) else doubles == interpolation
        assert (_problem(spec) is not None) == expected, (points, interpolation)


def test_the_rule_on_paths():
    assert CirclePath(radius_m=1.5).doubling_back(0.5) is None  # a curve of any radius
    assert CirclePath(radius_m=0.3).doubling_back(0.5) is None  # even inside its own band
    back = WaypointPath([[0, 0], [5, 0], [0, 0]], interpolation="pchip").doubling_back(0.5)
    assert back is not None and back.distance_m < 1e-6 and back.band_m == 1.0
    assert back.s_m < 5.0 < back.s_back_m and math.hypot(back.xy[0] - 5.0, back.xy[1]) < 0.1
    # a figure of eight crosses itself far along the path: no doubling back
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    eight = WaypointPath(np.column_stack([10 * np.sin(t), 5 * np.sin(2 * t)]), closed=True)
    assert eight.doubling_back(lambda s: np.full(np.shape(s), 0.5)) is None


def test_no_shipped_scenario_or_track_doubles_back():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for sid in builtin_ids():
            spec = load_scenario(sid)  # would raise
            track = load_track(spec.path) if spec.path.type == "csv" else None
            path = track.path if track is not None else build_path(spec.path)
            assert path_doubles_back(spec, path, build_road(spec.road, path, track)) is None, sid


@pytest.mark.parametrize(
    "file", sorted(p.name for d in ("commonroad", "commonroad_cases") for p in (CR / d).glob("*.xml*"))
)
def test_no_commonroad_file_in_the_tests_doubles_back(file):
    pytest.importorskip("commonroad")
    from mpcdrive.adapters.commonroad import load_commonroad

    path = next(p for d in ("commonroad", "commonroad_cases") for p in [CR / d / file] if p.exists())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        spec = load_commonroad(path).spec
    built = build_path(spec.path)
    assert path_doubles_back(spec, built, build_road(spec.road, built)) is None
