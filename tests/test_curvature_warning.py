"""A path that turns tighter than the vehicle can is said in one warning line (the run goes on)."""

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from mpcdrive.scenarios import builtin_ids, load_scenario, validate_scenario_data
from mpcdrive.scenarios.build import build_path, load_track, warn_if_path_too_curved
from mpcdrive.types import ScenarioWarning

DIR = Path(__file__).resolve().parent / "data" / "commonroad"


def _spec(path, **controller):
    return validate_scenario_data(
        {
            "id": "c",
            "duration_s": 0.05,
            "dt_s": 0.01,
            "path": path,
            "vehicle": {"model": "kinematic3", "lf_m": 0.17, "lr_m": 0.16},
            "initial_state": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 90.0},
            "controller": {"horizon": 5, "Q": [1, 1, 1], "R": [1], **controller},
        },
        "c.yaml",
    )


def _path_of(spec):
    return load_track(spec.path).path if spec.path.type == "csv" else build_path(spec.path)


def _check(spec, source=None):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ScenarioWarning)
        worst = warn_if_path_too_curved(spec, _path_of(spec), source)
    return worst, [str(w.message) for w in caught if issubclass(w.category, ScenarioWarning)]


def _circle(radius_m):
    return {"type": "circle", "center": [-radius_m, 0.0], "radius_m": radius_m}


def test_the_slip_angle_limit_is_used_not_tan_over_wheelbase():
    # lf 0.17 m, lr 0.16 m, 60 deg: tan(60 deg) / 0.33 m = 5.25 1/m at the rear axle (radius 0.19 m);
    # the centre of gravity's tightest circle: sin(atan(lr / L tan 60 deg)) / lr = 4.02 1/m (0.249 m)
    lq = 0.16 / 0.33
    kappa_max = math.sin(math.atan(lq * math.tan(math.radians(60)))) / 0.16
    assert 1 / kappa_max == pytest.approx(0.249, abs=1e-3)
    worst, lines = _check(_spec(_circle(0.22)), "c.yaml")
    assert worst == pytest.approx(1 / 0.22, rel=1e-3)
    assert len(lines) == 1 and "\n" not in lines[0]
    assert lines[0].startswith("c.yaml: path: ") and "4.02 1/m" in lines[0] and "max_steer_deg 60" in lines[0]
    assert _check(_spec(_circle(0.26))) == (None, [])
    # more steering makes the same circle drivable
    assert _check(_spec(_circle(0.22), max_steer_deg=70)) == (None, [])


def test_a_sharp_waypoint_corner_warns_and_names_the_points_field():
    spec = _spec({"type": "waypoints", "points": [[0, 0], [0, 5], [-5, 5]]})
    worst, lines = _check(spec)
    assert worst is not None and len(lines) == 1
    assert lines[0].startswith("scenario 'c': path.points: ") and "(0, 4.9" in lines[0]
    # the same turn rounded with a 1 m radius is drivable
    arc = [[-1 + math.cos(a), 4 + math.sin(a)] for a in np.linspace(0, math.pi / 2, 20)]
    assert _check(_spec({"type": "waypoints", "points": [[0, 0], *arc, [-5, 5]]})) == (None, [])


@pytest.mark.parametrize("sid", builtin_ids())
def test_no_builtin_scenario_warns(sid):
    assert _check(load_scenario(sid)) == (None, [])


def _commonroad_files():
    return sorted(p.name for p in DIR.iterdir() if p.name.endswith((".xml", ".xml.gz")))


@pytest.mark.parametrize("name", _commonroad_files())
def test_no_commonroad_route_warns(name):
    pytest.importorskip("commonroad")
    from mpcdrive.adapters.commonroad import load_commonroad

    imp = load_commonroad(DIR / name)  # every test file imports (tests/test_commonroad.py)
    worst, lines = _check(imp.spec)
    # (USA_US101-3_1's route once turned 90 deg within 1.5 m and jumped 30 m, and this warned)
    assert (worst, lines) == (None, [])
