"""Physical steering by default: every vehicle steers through its steering system (a rate limit, an
actuator lag and dead time, per preset, each with its source), the controller plans within that
rate, the paper's scenarios keep the paper's ideal steering and say so, and the summary says how
often the steering sat at its limits."""

import json
import math
import subprocess
import sys
import warnings

import numpy as np
import pytest
import yaml

from mpcdrive.models import PRESETS
from mpcdrive.scenarios import ScenarioError, build_experiment, builtin_ids, dump_scenario, load_scenario
from mpcdrive.scenarios import run_experiment, validate_scenario_data
from mpcdrive.sim import SteeringActuator, compute_metrics

# the 1:10 car (no preset) at 1 m/s around a 90-degree corner with little steering penalty: without
# a rate limit its steering jumped at up to 95 rad/s
CORNER = {
    "id": "corner",
    "dt_s": 0.01,
    "duration_s": 6.0,
    "vehicle": {"model": "kinematic3", "speed_mps": 1.0},
    "path": {"type": "waypoints", "points": [[0, 0], [2, 0], [2, 2]]},
    "initial_state": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0},
    "controller": {"horizon": 10, "Q": [1, 1, 1], "R": [0.01], "max_steer_deg": 60},
}
F1TENTH_RATE_RAD_S = 3.2  # F1TENTH gym's sv_max


def cli(*args):
    return subprocess.run([sys.executable, "-m", "mpcdrive.cli", *args], capture_output=True, text=True)


def write(tmp_path, data, name="s.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data))
    return p


def test_every_preset_has_a_sourced_steering_system():
    from mpcdrive.models import DEFAULT_STEERING, steering_of

    for name, pre in PRESETS.items():
        st = pre.steering
        assert st.source and st.max_rate_rad_s > 0 and st.time_constant_s >= 0 and st.dead_time_s >= 0, name
        assert pre.max_steer_rate_rad_s == st.max_rate_rad_s
    f1 = PRESETS["f1tenth"].steering
    assert (f1.max_rate_rad_s, f1.time_constant_s, f1.dead_time_s) == (3.2, 0.0, 0.02)
    for name in ("commonroad_ford_escort", "commonroad_bmw_320i", "commonroad_vw_vanagon"):
        assert (PRESETS[name].steering.max_rate_rad_s, PRESETS[name].steering.dead_time_s) == (0.4, 0.0)
    # a vehicle without a preset is the paper's F1TENTH-class car
    assert steering_of(None) is DEFAULT_STEERING is PRESETS["f1tenth"].steering


def test_a_vehicle_without_preset_steers_at_the_f1tenth_rate_and_the_controller_plans_within_it(tmp_path):
    spec = load_scenario(write(tmp_path, CORNER))
    act = spec.plant.steering_actuator
    assert act.max_rate_deg_s == pytest.approx(math.degrees(F1TENTH_RATE_RAD_S))
    assert (act.time_constant_s, act.dead_time_s) == (0.0, 0.02)
    assert spec.controller.max_steer_rate_deg_s == act.max_rate_deg_s  # the limits agree
    exp = build_experiment(spec)
    a = exp.plant.actuator
    assert (a.time_constant_s, a.dead_time_s, a.max_rate_rad_s) == (0.0, 0.02, pytest.approx(F1TENTH_RATE_RAD_S))
    assert exp.mpc.problem.du_max_per_s[0] == pytest.approx(F1TENTH_RATE_RAD_S)
    m = compute_metrics(run_experiment(exp))
    # every command within the rate limit (to rounding), and the run says how often it sat there
    assert m.max_abs_steer_rate_rad_s <= F1TENTH_RATE_RAD_S * (1 + 1e-9)
    assert m.steer_rate_limit_rad_s == pytest.approx(F1TENTH_RATE_RAD_S)
    assert 0.2 < m.steer_rate_saturated_fraction < 0.8
    assert m.goal_reached is True and m.verdict.passed
    # the resolved scenario shows every steering value and loads back to the same scenario
    text = dump_scenario(spec)
    assert "max_rate_deg_s: 183.3" in text and "max_steer_rate_deg_s: 183.3" in text
    assert validate_scenario_data(yaml.safe_load(text), "again") == spec


def test_the_controller_may_not_plan_steering_faster_than_the_plant(tmp_path):
    data = {**CORNER, "controller": {**CORNER["controller"], "max_steer_rate_deg_s": 360}}
    with pytest.raises(ScenarioError, match=r"controller\.max_steer_rate_deg_s: 360 deg/s is faster than the car"):
        load_scenario(write(tmp_path, data))
    r = cli("run", str(write(tmp_path, data, "fast.yaml")), "--out", str(tmp_path / "out"), "-q")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "controller.max_steer_rate_deg_s" in r.stderr and not (tmp_path / "out").exists()
    # slower than the plant is fine, and so is any rate on an ideal plant
    ok = {**data, "controller": {**data["controller"], "max_steer_rate_deg_s": 90}}
    assert load_scenario(write(tmp_path, ok, "ok.yaml")).plant.steering_actuator.max_rate_deg_s > 183
    ideal = {**data, "plant": {"steering_actuator": "ideal"}}
    assert load_scenario(write(tmp_path, ideal, "ideal.yaml")).controller.max_steer_rate_deg_s == 360


def test_a_preset_vehicle_steers_as_its_preset_and_another_vehicle_gets_its_own():
    spec = validate_scenario_data({**CORNER, "vehicle": {"model": "kinematic3", "preset": "commonroad_bmw_320i"}}, "x")
    assert spec.plant.steering_actuator.max_rate_deg_s == pytest.approx(math.degrees(0.4))
    assert spec.controller.max_steer_rate_deg_s == pytest.approx(math.degrees(0.4))
    # the filled-in values are not marked as given: a spec made from this one for another
    # vehicle gets that vehicle's steering
    pytest.importorskip("vehiclemodels")
    from mpcdrive.adapters.commonroad_vehicles import apply_vehicle

    base = validate_scenario_data(
        {
            **CORNER,
            "vehicle": {"model": "kinematic4"},
            "controller": {**CORNER["controller"], "Q": [1, 1, 1, 1], "R": [1, 1]},
        },
        "x",
    )
    assert base.plant.steering_actuator.max_rate_deg_s == pytest.approx(math.degrees(3.2))
    bmw = apply_vehicle(base, "bmw_320i")
    assert bmw.plant.steering_actuator.max_rate_deg_s == pytest.approx(math.degrees(0.4))


@pytest.mark.parametrize("sid", [s for s in builtin_ids() if s.startswith("paper-")])
def test_paper_scenarios_keep_the_papers_ideal_steering_and_say_so(sid):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        spec = load_scenario(sid)
    assert spec.plant.steering_actuator == "ideal" and spec.controller.max_steer_rate_deg_s is None
    resolved = yaml.safe_load(dump_scenario(spec))
    assert resolved["plant"]["steering_actuator"] == "ideal"
    assert resolved["controller"]["max_steer_rate_deg_s"] is None
    exp = build_experiment(spec)
    assert exp.plant.actuator is None and np.isinf(exp.mpc.problem.du_max_per_s[0])


def test_paper_run_says_its_steering_is_the_papers_ideal_one(tmp_path):
    out = tmp_path / "out"
    r = cli("run", "paper-exp3", "--out", str(out), "-q")
    assert r.returncode == 0, r.stderr
    line = r.stdout.splitlines()[0]
    assert "ideal steering (the paper's: no rate limit, no lag; up to " in line, line
    m = json.loads((out / "metrics.json").read_text())
    assert m["steer_rate_limit_rad_s"] is None and m["steer_rate_saturated_fraction"] is None
    assert m["steering_actuator"] == {"time_constant_s": 0.0, "dead_time_s": 0.0, "max_rate_rad_s": None}
    assert "ideal steering (the paper&#x27;s: no rate limit" in (out / "report.html").read_text()
    assert "steering_actuator: ideal" in (out / "scenario.yaml").read_text()


def test_saturation_is_measured_against_the_limits_the_run_had(tmp_path):
    """The fractions in metrics.json and the summary follow from trajectory.csv and the limits."""
    from mpcdrive.sim.verdict import SATURATION_TOLERANCE

    data = {**CORNER, "duration_s": 3.0, "controller": {**CORNER["controller"], "max_steer_deg": 30}}
    out = tmp_path / "out"
    r = cli("run", str(write(tmp_path, data)), "--out", str(out), "-q")
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "metrics.json").read_text())
    rows = np.genfromtxt(out / "trajectory.csv", delimiter=",", names=True)
    steer = rows["steer"]
    limit, rate_limit = math.radians(30), F1TENTH_RATE_RAD_S
    assert m["steer_limit_rad"] == pytest.approx(limit) and m["steer_rate_limit_rad_s"] == pytest.approx(rate_limit)
    at_angle = np.abs(steer) >= (1 - SATURATION_TOLERANCE) * limit
    rate = np.abs(np.diff(np.r_[0.0, steer])) / data["dt_s"]
    at_rate = rate >= (1 - SATURATION_TOLERANCE) * rate_limit
    assert m["steer_saturated_fraction"] == pytest.approx(at_angle.mean())
    assert m["steer_rate_saturated_fraction"] == pytest.approx(at_rate.mean())
    assert at_angle.any() and at_rate.any()
    angle_pct, rate_pct = 100 * at_angle.mean(), 100 * at_rate.mean()

    def pct(p):
        return f"{p:.0f} %" if p >= 10 else f"{p:.2g} %"

    phrase = f"steering at its angle limit {pct(angle_pct)} and at its rate limit {pct(rate_pct)} of the time"
    assert phrase in r.stdout.splitlines()[0], r.stdout
    assert m["verdict"]["notes"]["steering"] == phrase


# -- the actuator ---------------------------------------------------------------------------------------
def test_rate_limited_servo_turns_at_its_rate_until_it_is_there():
    act = SteeringActuator(max_rate_rad_s=2.0)  # no lag: a servo at its rate limit
    st = act.start(0.0).issue(0.0, 0.3)
    mean, st = act.advance(st, 0.0, 0.1)  # 0.2 rad at 2 rad/s: a ramp all the way
    assert st.steer_rad == pytest.approx(0.2) and mean == pytest.approx(0.1)
    mean, st = act.advance(st, 0.1, 0.1)  # there after 0.05 s, then held
    assert st.steer_rad == pytest.approx(0.3)
    assert mean == pytest.approx((0.05 * 0.25 + 0.05 * 0.3) / 0.1)


def test_rate_limited_lag_is_integrated_exactly_over_any_substeps():
    """A lag of 0.05 s whose rate saturates at 1 rad/s, a dead time of 0.013 s that ends inside a
    substep: one coarse step and 100 fine ones give the same wheel angle and the same mean."""
    act = SteeringActuator(time_constant_s=0.05, dead_time_s=0.013, max_rate_rad_s=1.0)
    st0 = act.start(0.0).issue(0.0, 0.2)
    coarse_mean, coarse = act.advance(st0, 0.0, 0.1)
    st, total = st0, 0.0
    for i in range(100):
        m, st = act.advance(st, i * 0.001, 0.001)
        total += m * 0.001
    assert coarse.steer_rad == pytest.approx(st.steer_rad, abs=1e-12)
    assert coarse_mean == pytest.approx(total / 0.1, abs=1e-12)
    # the exact motion: held 0.013 s, at 1 rad/s while the lag would be faster (until 0.15 rad
    # from the command, r T = 0.05 rad), then exponential
    t_ramp = 0.15
    assert 0.013 + t_ramp > 0.1  # still on the ramp at the end of the step
    assert coarse.steer_rad == pytest.approx(1.0 * (0.1 - 0.013))
    with pytest.raises(ValueError, match="max_rate_rad_s"):
        SteeringActuator(max_rate_rad_s=0.0)
