"""The scenario sections of the plant's steering (``plant.steering_actuator``) and of the verdict
(``verdict``), and how a validated scenario fills them in.

Resolved when a scenario is validated (the resolved ``scenario.yaml`` shows every value): the
plant's ``steering_actuator`` (values left out: the vehicle's steering system, its preset's, the
F1TENTH steering without one; ``ideal``: instant, at any rate, the paper's), the controller's
``max_steer_rate_deg_s`` (left out: the plant's rate limit, none for the projected gradient
solver, which handles input bounds only; it may be lower, never higher: the controller plans within
what the car can do) and ``verdict.max_final_lateral_error_m`` (left out: half the vehicle's
width). A value filled in this way is not marked as given (``model_fields_set``), so a scenario
made from a resolved one for another vehicle gets that vehicle's."""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel

from ..models.presets import steering_of
from ..sim.verdict import GOALS, LANE_TOLERANCE_M, STANDSTILL_SPEED_MPS
from .fields import NonNeg, Positive, Strict

#: ``plant.steering_actuator: ideal``: the wheels follow every command at once, at any rate (the
#: paper's steering)
IDEAL_STEERING = "ideal"


class ActuatorSpec(Strict):
    """Steering actuator of the plant: dead time, then a first-order lag (both in seconds), the
    wheels turning at up to ``max_rate_deg_s``. A value left out is the vehicle's
    (:func:`~mpcdrive.models.presets.steering_of`: its preset's steering, the F1TENTH steering
    without a preset)."""

    time_constant_s: NonNeg | None = None
    dead_time_s: NonNeg | None = None
    max_rate_deg_s: Positive | None = None


class VerdictSpec(Strict):
    """How the run is judged (:class:`~mpcdrive.sim.VerdictCriteria`): ``goal`` ``reach`` (the
    end of an open path, the laps of a closed one) or ``standstill`` (at most
    ``max_final_speed_mps`` at the end, e.g. stopped before an obstacle that blocks the road);
    ``max_final_lateral_error_m``: how far from the path the car may end [m] (default: half the
    vehicle's width, the path still under the body); ``max_lane_excess_m``: how far outside the
    road the body may get and still count as inside [m] (default 1 mm, the measurement's
    accuracy)."""

    goal: Literal[GOALS] = "reach"  # type: ignore[valid-type]
    max_final_lateral_error_m: NonNeg | None = None
    max_final_speed_mps: NonNeg = STANDSTILL_SPEED_MPS
    max_lane_excess_m: NonNeg = LANE_TOLERANCE_M


def resolve_steering_and_verdict(spec, *, commonroad: bool) -> str | None:
    """Fill in the steering and verdict values ``spec`` (a :class:`ScenarioSpec` being
    validated; ``commonroad``: its plant is a CommonRoad vehicle, which steers itself) leaves out;
    returns why its ``controller.max_steer_rate_deg_s`` is faster than the plant can steer, or None."""
    pl, c = spec.plant, spec.controller
    if commonroad:  # the CommonRoad vehicle's own servo
        plant_rate_deg = math.degrees(steering_of(f"commonroad_{pl.vehicle}").max_rate_rad_s)
        where = f"plant.vehicle {pl.vehicle}'s steering servo"
    else:
        act = pl.steering_actuator
        if act != IDEAL_STEERING:
            act = _resolved_actuator(act, spec.vehicle.preset)
            _set(spec, "plant", _constructed(pl, steering_actuator=act))
        plant_rate_deg = math.inf if act == IDEAL_STEERING else act.max_rate_deg_s
        where = "plant.steering_actuator (ideal)" if act == IDEAL_STEERING else "plant.steering_actuator.max_rate_deg_s"
    if spec.verdict.max_final_lateral_error_m is None:
        _set(spec, "verdict", _constructed(spec.verdict, max_final_lateral_error_m=0.5 * spec.vehicle.width_m))
    rate = c.max_steer_rate_deg_s
    # the projected gradient solver handles input bounds only: it plans without the rate limit
    # (the plant's actuator still limits the wheels; the run's verdict says so)
    pg = c.solver == "projected_gradient"
    if "max_steer_rate_deg_s" not in c.model_fields_set and rate is None:
        _set(
            spec,
            "controller",
            _constructed(c, max_steer_rate_deg_s=None if pg or plant_rate_deg == math.inf else plant_rate_deg),
        )
    elif not (pg and rate is None) and (math.inf if rate is None else rate) > plant_rate_deg * (1 + 1e-9):
        return (
            f"{'no limit' if rate is None else f'{rate:g} deg/s'} is faster than the car can steer "
            f"({plant_rate_deg:.6g} deg/s, {where}): the controller would plan steering the plant cannot "
            "follow; leave it out (the plant's rate) or give at most that"
        )
    return None


def _resolved_actuator(act: ActuatorSpec | None, preset: str | None) -> ActuatorSpec:
    """``act`` with every value it leaves out taken from the steering of the vehicle ``preset``
    (:func:`~mpcdrive.models.presets.steering_of`); those values are not marked as given."""
    sys = steering_of(preset)
    given = act if act is not None else ActuatorSpec()
    defaults = {
        "time_constant_s": sys.time_constant_s,
        "dead_time_s": sys.dead_time_s,
        "max_rate_deg_s": math.degrees(sys.max_rate_rad_s),
    }
    return _constructed(given, **{k: v for k, v in defaults.items() if getattr(given, k) is None})


def _constructed(model: BaseModel, **values) -> BaseModel:
    """``model`` with ``values`` filled in, its set fields (``model_fields_set``) unchanged."""
    return type(model).model_construct(_fields_set=set(model.model_fields_set), **{**dict(model), **values})


def _set(spec: BaseModel, name: str, value) -> None:
    """Replace field ``name`` of the (frozen) ``spec`` while it is being validated."""
    object.__setattr__(spec, name, value)
