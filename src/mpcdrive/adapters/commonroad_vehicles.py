"""CommonRoad's vehicle models as the simulated vehicle (the plant), and CommonRoad vehicles for
the controller.

Optional extra ``commonroad`` (the ``commonroad-vehicle-models`` package, ``vehiclemodels``);
imported lazily, only when a CommonRoad plant is built or a vehicle's parameters are read.

:class:`CommonRoadPlant` integrates the package's unmodified right-hand sides
``vehicle_dynamics_ks`` (kinematic single track, 5 states), ``vehicle_dynamics_st`` (single
track with linear tyres, 7 states) and ``vehicle_dynamics_mb`` (multi-body, 29 states) with the
parameter sets 1, 2, 3 (Ford Escort, BMW 320i, VW Vanagon); their input limits (steering angle
and steering velocity, longitudinal acceleration with its ``a_max v_switch / v`` fall-off above
``v_switch``, speed range) are applied by the right-hand sides themselves.

:func:`apply_vehicle` sets a scenario's controller vehicle and limits from a CommonRoad vehicle
(and, optionally, the plant), :func:`solution_vehicle_type` gives the vehicle's ``VehicleType``
for CommonRoad solution files.
"""

from __future__ import annotations

import math



#: CommonRoad vehicle name -> parameter set number (``parameters_vehicle<N>``)
VEHICLES: dict[str, int] = {"ford_escort": 1, "bmw_320i": 2, "vw_vanagon": 3}
#: plant model name (scenario files) -> CommonRoad model
PLANT_MODELS: dict[str, str] = {"commonroad_ks": "ks", "commonroad_st": "st", "commonroad_mb": "mb"}
_SHORT = {"ks": "commonroad_ks", "st": "commonroad_st", "mb": "commonroad_mb"}


def available() -> bool:
    """True when ``commonroad-vehicle-models`` (``vehiclemodels``) is installed."""
    try:
        import vehiclemodels  # noqa: F401
    except ImportError:
        return False
    return True


def _require():
    try:
        import vehiclemodels  # noqa: F401
    except ImportError:
        raise ValueError("CommonRoad vehicle models need the commonroad extra: "
                         "pip install 'mpcdrive[commonroad]' (package commonroad-vehicle-models)") from None


def _check_vehicle(vehicle: str) -> int:
    if vehicle not in VEHICLES:
        raise ValueError(f"unknown CommonRoad vehicle {vehicle!r} (known: {', '.join(VEHICLES)})")
    return VEHICLES[vehicle]


def vehicle_parameters(vehicle: str):
    """The ``vehiclemodels`` parameter set of ``vehicle`` (``ford_escort``, ``bmw_320i``,
    ``vw_vanagon``)."""
    num = _check_vehicle(vehicle)
    _require()
    from vehiclemodels.vehicle_parameters import setup_vehicle_parameters

    return setup_vehicle_parameters(vehicle_id=num)


def preset_name(vehicle: str) -> str:
    """The mpcdrive vehicle preset (``models.presets``) of a CommonRoad vehicle."""
    _check_vehicle(vehicle)
    return f"commonroad_{vehicle}"


def solution_vehicle_type(vehicle: str):
    """CommonRoad's ``VehicleType`` enum member of ``vehicle`` (for solution files)."""
    num = _check_vehicle(vehicle)
    try:
        from commonroad.common.solution import VehicleType
    except ImportError:
        raise ValueError("CommonRoad solution files need the commonroad extra: pip install 'mpcdrive[commonroad]'") from None
    return VehicleType(num)


def accel_limit_mps2(vehicle: str, v_max_mps: float) -> float:
    """The largest forward acceleration [m/s^2] the vehicle reaches at every speed up to
    ``v_max_mps`` [m/s]: ``a_max`` up to ``v_switch``, ``a_max v_switch / v`` above it (the
    CommonRoad longitudinal limit), so ``a_max min(1, v_switch / v_max)``."""
    lon = vehicle_parameters(vehicle).longitudinal
    return float(lon.a_max * min(1.0, lon.v_switch / max(v_max_mps, 1e-9)))


def apply_vehicle(spec, vehicle: str, plant: str | None = None):
    """``spec`` (a :class:`ScenarioSpec`) with the controller's vehicle and limits taken from the
    CommonRoad ``vehicle`` (``ford_escort``, ``bmw_320i``, ``vw_vanagon``) and, with ``plant``
    (``ks``, ``st``, ``mb``), the plant set to that CommonRoad model of the vehicle.

    Vehicle: the ``commonroad_<vehicle>`` preset (wheelbase split lf/lr, footprint length and
    width, the dynamic parameters); controller: steering limit, steering-rate limit, acceleration
    limits ``[-a_max, a_max min(1, v_switch / v_top)]`` with ``v_top`` the controller's upper speed
    limit (else the larger of the reference and initial speeds plus 2 m/s), and the upper speed
    limit capped at the vehicle's ``v_max``. The controller's model is kept (a ``kinematic4``
    controller is needed for a CommonRoad plant). ValueError for an unknown vehicle or plant."""
    from ..scenarios.schema import ScenarioSpec

    p = vehicle_parameters(vehicle)
    if plant is not None and plant not in _SHORT:
        raise ValueError(f"unknown CommonRoad plant model {plant!r} (known: {', '.join(_SHORT)})")
    data = spec.model_dump(mode="python", exclude_unset=True)
    veh = {k: v for k, v in spec.vehicle.model_dump(exclude_unset=True).items()
           if k in ("model", "speed_mps", "footprint_discs", "v_blend_low_mps", "v_blend_high_mps")}
    veh["preset"] = preset_name(vehicle)
    data["vehicle"] = veh
    c = spec.controller
    v_ref = c.reference_speed_mps if c.reference_speed_mps is not None else spec.vehicle.speed_mps
    v0 = spec.initial_state.v_mps if spec.initial_state.v_mps is not None else v_ref
    lon = p.longitudinal
    if c.speed_limits_mps is not None:
        s_lo, s_hi = c.speed_limits_mps[0], min(c.speed_limits_mps[1], float(lon.v_max))
        v_top = s_hi
    else:
        s_lo, s_hi = None, None
        v_top = max(v_ref, v0) + 2.0
    a_hi = float(lon.a_max) * min(1.0, float(lon.v_switch) / v_top)
    ctrl = dict(data["controller"])
    ctrl["max_steer_deg"] = math.degrees(min(float(p.steering.max), -float(p.steering.min)))
    ctrl["max_steer_rate_deg_s"] = math.degrees(min(float(p.steering.v_max), -float(p.steering.v_min)))
    ctrl["accel_limits_mps2"] = (-float(lon.a_max), a_hi)
    if s_hi is not None:
        ctrl["speed_limits_mps"] = (s_lo, s_hi)
    data["controller"] = ctrl
    if plant is not None:
        data["plant"] = {"model": _SHORT[plant], "vehicle": vehicle}
    elif spec.plant.model in PLANT_MODELS:
        data["plant"] = {**spec.plant.model_dump(exclude_unset=True), "vehicle": vehicle}
    return ScenarioSpec.model_validate(data)
