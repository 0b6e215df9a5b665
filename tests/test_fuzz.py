"""Fuzzing the closed loop: random paths, initial states (far off the path, facing backwards, at
standstill) and parameters. Nothing but ValueError (for invalid input) escapes; commands are
finite and within their bounds; every failed solve is reported and answered by a fallback."""

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mpcdrive.control.fallback import FALLBACK_KINDS
from mpcdrive.scenarios import ScenarioError, build_experiment, run_experiment, validate_scenario_data
from mpcdrive.sim import compute_metrics
from mpcdrive.types import STATUS_FAILED, STATUS_INACCURATE, STATUS_INFEASIBLE, STATUS_MAX_ITER, STATUS_OK

STATUSES = {STATUS_OK, STATUS_INACCURATE, STATUS_INFEASIBLE, STATUS_MAX_ITER, STATUS_FAILED}
coord = st.floats(-8, 8, allow_nan=False)


@st.composite
def paths(draw):
    kind = draw(st.sampled_from(["straight", "circle", "waypoints", "waypoints"]))
    if kind == "straight":
        return {"type": "straight", "start": [draw(coord), draw(coord)], "end": [draw(coord), draw(coord)]}
    if kind == "circle":
        return {
            "type": "circle",
            "center": [draw(coord), draw(coord)],
            "radius_m": draw(st.floats(0.2, 10)),
            "ccw": draw(st.booleans()),
            "start_angle_deg": draw(st.floats(-360, 360)),
        }
    pts = draw(st.lists(st.tuples(coord, coord), min_size=2, max_size=6))
    return {
        "type": "waypoints",
        "points": [list(p) for p in pts],
        "closed": draw(st.booleans()),
        "smoothing": draw(st.sampled_from([0.0, 0.0, 0.1, 2.0])),
    }


ladders = st.sampled_from(
    [
        ["relax", "shifted_plan", "brake"],
        ["shifted_plan", "hold_last"],
        ["brake"],
        ["relax", "hold_last"],
        ["hold_last"],
        ["shifted_plan", "relax", "brake"],
    ]
)


@st.composite
def scenarios(draw):
    model = draw(st.sampled_from(["kinematic3", "kinematic4"]))
    nx, nu = (3, 1) if model == "kinematic3" else (4, 2)
    near = draw(st.booleans())
    spread = 1.0 if near else 25.0  # far off the path, too
    steer = draw(st.floats(5, 80))
    c = {
        "horizon": draw(st.integers(1, 25)),
        "Q": draw(st.lists(st.floats(0, 50), min_size=nx, max_size=nx)),
        "R": draw(st.lists(st.floats(1e-3, 10), min_size=nu, max_size=nu)),
        "max_steer_deg": steer,
        "fallback": draw(ladders),
        "brake_steering": draw(st.sampled_from(["hold", "straighten"])),
        "osqp_max_iter": draw(st.sampled_from([4000, 4000, 25])),  # 25: solver failures on purpose
        "linearization": draw(st.sampled_from(["trajectory", "paper"])),
    }
    if draw(st.booleans()):
        c["max_steer_rate_deg_s"] = draw(st.floats(10, 180))  # the plant's (F1TENTH) 183 deg/s at most
    init = {
        "x_m": draw(st.floats(-spread, spread)),
        "y_m": draw(st.floats(-spread, spread)),
        # any heading: facing backwards included
        "yaw_deg": draw(st.floats(-720, 720)),
    }
    vehicle = {
        "model": model,
        "lf_m": draw(st.floats(0.05, 0.5)),
        "lr_m": draw(st.floats(0.05, 0.5)),
        "speed_mps": draw(st.floats(0.1, 5)),
    }
    if model == "kinematic4":
        init["v_mps"] = draw(st.sampled_from([0.0, 0.0, 0.5, 3.0, 6.0]))  # standstill, above the limit
        c["speed_limits_mps"] = [0.0, draw(st.floats(0.5, 4))]
        if draw(st.booleans()):
            c["accel_limits_mps2"] = [-draw(st.floats(0.05, 5)), draw(st.floats(0.05, 5))]
    data = {
        "id": "fuzz",
        "dt_s": draw(st.sampled_from([0.01, 0.05, 0.1])),
        "duration_s": 0.4,
        "seed": draw(st.integers(0, 2**31)),
        "vehicle": vehicle,
        "path": draw(paths()),
        "initial_state": init,
        "controller": c,
        "plant": {"lr_m": vehicle["lr_m"] * draw(st.floats(0.8, 1.2))},
    }
    # the plant's steering: the vehicle's (F1TENTH: 183 deg/s, 0.02 s dead time), ideal, or another
    steering = draw(
        st.sampled_from([None, "ideal", {"time_constant_s": 0.05}, {"dead_time_s": 0.03, "max_rate_deg_s": 200.0}])
    )
    if steering is not None:
        data["plant"]["steering_actuator"] = steering
    if draw(st.booleans()):
        data["road"] = {"lane_width_m": draw(st.floats(0.3, 3))}
    if draw(st.booleans()):
        data["disturbance"] = {
            "distribution": "normal",
            "std": [0.01] * (nx - 1) + [0.05] if nx == 3 else [0.01, 0.01, 0.05, 0.05],
        }
    return data


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=scenarios())
def test_no_exception_escapes_and_commands_stay_within_bounds(data):
    try:
        spec = validate_scenario_data(data, "fuzz")
        exp = build_experiment(spec)
    except ValueError:  # ScenarioError included: invalid input is refused with a clear error
        return
    r = run_experiment(exp)
    pb = exp.controller.problem
    u = r.u
    assert np.all(np.isfinite(u))
    assert np.all(u >= pb.u_min - 1e-12) and np.all(u <= pb.u_max + 1e-12)
    du = np.diff(np.vstack([np.zeros((1, u.shape[1])), u]), axis=0)
    assert np.all(np.abs(du) <= pb.du_max_per_s * pb.dt_s + 1e-9)
    assert set(r.status) <= STATUSES
    for status, fb in zip(r.status, r.fallback):
        ok = status in (STATUS_OK, STATUS_INACCURATE)
        assert (fb == "") == ok  # every failure answered by a named fallback, and only failures
        assert fb == "" or fb in FALLBACK_KINDS
        assert fb == "" or fb in spec.controller.fallback
    m = compute_metrics(r)
    assert m["termination"] in ("completed", "path_end_reached", "laps_completed", "aborted_off_path", "diverged")
    assert m["fallbacks"] == sum(m["fallback_counts"].values())
    assert m["solver_failures"] == sum(1 for s in r.status if s not in (STATUS_OK, STATUS_INACCURATE))
    for k in ("rms_lateral_error_m", "max_abs_steer_rad", "max_lane_excess_m"):
        assert math.isfinite(m[k])


@settings(max_examples=25, deadline=None)
@given(
    pts=st.lists(st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)), min_size=0, max_size=5),
    closed=st.booleans(),
    smoothing=st.floats(-1, 1e3),
)
def test_waypoint_scenarios_are_valid_or_refused_with_a_scenario_error(pts, closed, smoothing):
    data = {
        "id": "w",
        "duration_s": 0.05,
        "path": {"type": "waypoints", "points": [list(p) for p in pts], "closed": closed, "smoothing": smoothing},
        "initial_state": {"x_m": pts[0][0] if pts else 0.0, "y_m": pts[0][1] if pts else 0.0},
        "controller": {"horizon": 3, "Q": [1, 1, 1], "R": [1]},
    }
    try:
        spec = validate_scenario_data(data, "w")
    except ScenarioError as e:
        assert "\n" not in str(e)
        return
    try:
        exp = build_experiment(spec)
    except ValueError as e:
        assert "\n" not in str(e)
        return
    r = run_experiment(exp)
    assert np.all(np.isfinite(r.u))
