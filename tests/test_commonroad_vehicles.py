"""CommonRoad's vehicle models (package commonroad-vehicle-models) as the plant, and CommonRoad
vehicles for the controller."""

import math

import pytest

from mpcdrive.adapters.commonroad_vehicles import available

if not available():
    pytest.skip("the commonroad extra (commonroad-vehicle-models) is not installed", allow_module_level=True)

from mpcdrive.adapters.commonroad_vehicles import (  # noqa: E402
    apply_vehicle, solution_vehicle_type, vehicle_parameters)
from mpcdrive.models.presets import PRESETS  # noqa: E402
from mpcdrive.scenarios.loader import ScenarioError, validate_scenario_data  # noqa: E402
from mpcdrive.scenarios.schema import ScenarioSpec  # noqa: E402

ROAD = {
    "id": "cr-straight",
    "dt_s": 0.1,
    "duration_s": 8.0,
    "vehicle": {"model": "kinematic4", "speed_mps": 10.0},
    "path": {"type": "straight", "start": [0.0, 0.0], "end": [200.0, 0.0]},
    "road": {"lane_width_m": 3.5},
    "initial_state": {"x_m": 0.0, "y_m": 0.5, "yaw_deg": 0.0, "v_mps": 8.0},
    "controller": {"horizon": 20, "Q": [1, 1, 2, 1], "R": [10, 0.1], "Rc": [100, 1],
                   "speed_limits_mps": [0.0, 15.0], "reference_speed_mps": 10.0, "horizon_step_m": 0.5},
}


@pytest.mark.parametrize("vehicle, num", [("ford_escort", 1), ("bmw_320i", 2), ("vw_vanagon", 3)])
def test_presets_are_the_commonroad_parameter_sets(vehicle, num):
    p = vehicle_parameters(vehicle)
    pre = PRESETS[f"commonroad_{vehicle}"]
    q = pre.params
    assert (q.lf_m, q.lr_m, q.mass_kg, q.yaw_inertia_kgm2, q.h_cg_m) == pytest.approx((p.a, p.b, p.m, p.I_z, p.h_s))
    assert q.friction == pytest.approx(p.tire.p_dy1)
    assert q.cs_front_per_rad == pytest.approx(-p.tire.p_ky1 / p.tire.p_dy1)
    assert (pre.max_steer_rad, pre.max_steer_rate_rad_s, pre.max_accel_mps2) == pytest.approx(
        (p.steering.max, p.steering.v_max, p.longitudinal.a_max))
    assert (pre.length_m, pre.width_m) == pytest.approx((p.l, p.w))
    assert pre.v_switch_mps == pytest.approx(p.longitudinal.v_switch)
    assert solution_vehicle_type(vehicle).value == num


def test_apply_vehicle_sets_controller_limits_and_plant():
    spec = apply_vehicle(ScenarioSpec.model_validate(ROAD), "bmw_320i", "st")
    p = vehicle_parameters("bmw_320i")
    v, c = spec.vehicle, spec.controller
    assert v.model == "kinematic4" and v.preset == "commonroad_bmw_320i"
    assert (v.lf_m + v.lr_m, v.length_m, v.width_m) == pytest.approx((p.a + p.b, p.l, p.w))
    assert math.radians(c.max_steer_deg) == pytest.approx(p.steering.max)
    assert math.radians(c.max_steer_rate_deg_s) == pytest.approx(p.steering.v_max)
    # above v_switch the acceleration limit falls as a_max v_switch / v: the bound holds up to 15 m/s
    assert c.accel_limits_mps2 == pytest.approx((-p.longitudinal.a_max, p.longitudinal.a_max * p.longitudinal.v_switch / 15.0))
    assert c.speed_limits_mps == (0.0, 15.0)
    assert (spec.plant.model, spec.plant.vehicle) == ("commonroad_st", "bmw_320i")
    # the rest of the scenario is untouched
    assert (spec.path, spec.road, spec.initial_state, c.Q, c.R) == (
        ScenarioSpec.model_validate(ROAD).path, ScenarioSpec.model_validate(ROAD).road,
        ScenarioSpec.model_validate(ROAD).initial_state, [1, 1, 2, 1], [10, 0.1])
    # without a plant the plant stays the controller's model
    assert apply_vehicle(ScenarioSpec.model_validate(ROAD), "vw_vanagon").plant.model == "same"


def test_apply_vehicle_rejects_unknown_names():
    spec = ScenarioSpec.model_validate(ROAD)
    with pytest.raises(ValueError, match="unknown CommonRoad vehicle 'beetle'"):
        apply_vehicle(spec, "beetle")
    with pytest.raises(ValueError, match="unknown CommonRoad plant model 'dyn'"):
        apply_vehicle(spec, "bmw_320i", "dyn")


@pytest.mark.parametrize("change, field, message", [
    ({"plant": {"model": "commonroad_st"}}, "plant", "needs plant.vehicle"),
    ({"plant": {"model": "commonroad_ks", "vehicle": "bmw_320i", "substeps": 4}}, "plant",
     "plant.substeps does not apply"),
    ({"plant": {"model": "same", "vehicle": "bmw_320i"}}, "plant", "plant.vehicle needs a CommonRoad plant model"),
    ({"plant": {"model": "commonroad_st", "vehicle": "bmw_320i"},
      "vehicle": {"model": "kinematic3", "speed_mps": 10.0},
      "controller": {"horizon": 20, "Q": [1, 1, 2], "R": [10]}}, "(top level)", "observed as kinematic4"),
    ({"plant": {"model": "commonroad_st", "vehicle": "bmw_320i"},
      "disturbance": {"distribution": "normal", "std": [0.0, 0.0, 0.0, 0.0]}}, "(top level)", "use measurement_noise"),
])
def test_bad_commonroad_plant_is_one_clear_line(change, field, message):
    with pytest.raises(ScenarioError) as e:
        validate_scenario_data({**ROAD, **change}, "f.yaml")
    line = str(e.value)
    assert "\n" not in line and message in line and field in line, line
