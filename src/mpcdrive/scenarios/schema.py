"""Scenario files: YAML validated by pydantic.

SI units unless the key names another unit (``yaw_deg``, ``max_steer_deg``). Unknown keys are
rejected, every number must be finite and a number (not a quoted string or a boolean), integers
must be integers, and values outside anything sensible (an initial position kilometres from the
path, a lane narrower than the car) are rejected with the reason.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from ..control.fallback import DEFAULT_LADDER, check_ladder

Finite = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Positive = Annotated[float, Field(strict=True, gt=0, allow_inf_nan=False)]
NonNeg = Annotated[float, Field(strict=True, ge=0, allow_inf_nan=False)]
#: a coordinate [m]; beyond a thousand kilometres float64 loses the millimetres
Coord = Annotated[float, Field(strict=True, ge=-1e6, le=1e6, allow_inf_nan=False)]
#: a vehicle dimension [m]
Length = Annotated[float, Field(strict=True, gt=0, le=100, allow_inf_nan=False)]
#: a speed [m/s] (360 km/h at most)
Speed = Annotated[float, Field(strict=True, ge=-100, le=100, allow_inf_nan=False)]
Int = Annotated[int, Field(strict=True)]
Point = tuple[Coord, Coord]
#: largest distance [m] between the initial position and the path
MAX_INITIAL_DISTANCE_M = 1000.0
FallbackName = Literal["relax", "shifted_plan", "brake", "hold_last"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class StraightSpec(_Strict):
    """Straight path from ``start`` to ``end`` [m]."""

    type: Literal["straight"]
    start: Point
    end: Point

    @model_validator(mode="after")
    def _distinct(self):
        if math.dist(self.start, self.end) <= 0:
            raise ValueError("start and end must differ")
        return self


class CircleSpec(_Strict):
    """Circle of ``radius_m`` around ``center`` [m], starting at polar angle ``start_angle_deg``."""

    type: Literal["circle"]
    center: Point = (0.0, 0.0)
    radius_m: Positive
    ccw: bool = True
    start_angle_deg: Finite = 0.0


class WaypointsSpec(_Strict):
    """Smoothed spline through ``points`` [m] (at least two distinct points)."""

    type: Literal["waypoints"]
    points: list[Point] = Field(min_length=2)
    closed: bool = False
    smoothing: NonNeg = 0.0

    @model_validator(mode="after")
    def _distinct(self):
        pts = [p for i, p in enumerate(self.points) if i == 0 or math.dist(p, self.points[i - 1]) > 1e-9]
        if self.closed and len(pts) > 2 and math.dist(pts[0], pts[-1]) <= 1e-9:
            pts = pts[:-1]
        need = 3 if self.closed else 2
        if len(pts) < need:
            raise ValueError(f"{'a closed' if self.closed else 'an open'} path needs at least {need} distinct "
                             f"points, got {len(pts)}")
        return self


PathSpec = Annotated[StraightSpec | CircleSpec | WaypointsSpec, Field(discriminator="type")]


class VehicleSpec(_Strict):
    """Vehicle model and geometry. ``kinematic3``: constant ``speed_mps``; ``kinematic4``: speed is a
    state driven by acceleration."""

    model: Literal["kinematic3", "kinematic4"] = "kinematic3"
    lf_m: Length = 0.17
    lr_m: Length = 0.16
    speed_mps: Annotated[Speed, Field(gt=0)] = 1.0
    length_m: Length = 0.50
    width_m: Length = 0.27


class InitialState(_Strict):
    """Initial pose and speed."""

    x_m: Coord = 0.0
    y_m: Coord = 0.0
    yaw_deg: Annotated[float, Field(strict=True, ge=-3600, le=3600, allow_inf_nan=False)] = 0.0
    v_mps: Annotated[Speed, Field(ge=0)] | None = None


class RoadSpec(_Strict):
    """A lane centred on the reference path."""

    lane_width_m: Positive


class ControllerSpec(_Strict):
    """LTV-MPC settings; weights are diagonals in the model's state / input order."""

    horizon: Int = Field(30, ge=1, le=1000)
    Q: list[NonNeg]
    R: list[NonNeg]
    QN: list[NonNeg] | None = None
    Rc: list[NonNeg] | None = None
    max_steer_deg: Positive = 60.0
    max_steer_rate_deg_s: Positive | None = None
    accel_limits_mps2: tuple[Finite, Finite] | None = None
    speed_limits_mps: tuple[Finite, Finite] | None = None
    reference_speed_mps: Speed | None = None
    linearization: Literal["trajectory", "paper"] = "trajectory"
    discretization: Literal["rk4", "euler"] = "rk4"
    horizon_reference: Literal["arc_length", "paper"] = "arc_length"
    horizon_step_m: Positive = 0.025
    feedforward: Literal["curvature", "none"] = "curvature"
    lane_slack_weight: NonNeg = 1e4
    lane_slack_weight_l1: NonNeg = 1e3
    osqp_eps: Positive = 1e-5
    osqp_max_iter: Int = Field(4000, ge=1)
    fallback: list[FallbackName] = Field(default_factory=lambda: list(DEFAULT_LADDER))
    brake_decel_mps2: Positive = 1.0
    brake_steering: Literal["hold", "straighten"] = "hold"
    relax_slack_factor: Annotated[float, Field(strict=True, ge=1, allow_inf_nan=False)] = 100.0

    @field_validator("fallback")
    @classmethod
    def _ladder(cls, v):
        check_ladder(v)
        return v

    @field_validator("max_steer_deg")
    @classmethod
    def _steer_range(cls, v):
        if v >= 90:
            raise ValueError("must be below 90 degrees")
        return v

    @field_validator("accel_limits_mps2", "speed_limits_mps")
    @classmethod
    def _ordered(cls, v):
        if v is not None and v[0] > v[1]:
            raise ValueError(f"lower limit {v[0]} exceeds upper limit {v[1]}")
        return v

    @field_validator("accel_limits_mps2")
    @classmethod
    def _accel_holds_speed(cls, v):
        if v is not None and not (v[0] <= 0 <= v[1]):
            raise ValueError(f"limits [{v[0]}, {v[1]}] must include 0 (else the speed can never be held)")
        return v

    @field_validator("speed_limits_mps")
    @classmethod
    def _can_drive(cls, v):
        if v is not None and v[1] <= 0:
            raise ValueError(f"upper limit {v[1]} must be positive (the car must be able to drive forward)")
        return v


class PlantSpec(_Strict):
    """The simulated vehicle: ``same`` model as the controller, integrated with ``integrator``.

    ``lf_m``, ``lr_m`` (and ``speed_mps`` of a constant-speed model) give the true vehicle's
    parameters when they differ from the controller's (``vehicle``): a model error. None = same."""

    model: Literal["same"] = "same"
    integrator: Literal["rk4", "euler"] = "rk4"
    substeps: Int = Field(1, ge=1, le=100)
    lf_m: Length | None = None
    lr_m: Length | None = None
    speed_mps: Annotated[Speed, Field(gt=0)] | None = None


class NoiseSpec(_Strict):
    """Seeded random noise per state component (x m, y m, yaw rad[, v m/s]).

    ``uniform``: each component in [low, high]; ``normal``: zero mean, ``std``."""

    distribution: Literal["uniform", "normal"]
    low: list[Finite] | None = None
    high: list[Finite] | None = None
    std: list[NonNeg] | None = None

    @model_validator(mode="after")
    def _complete(self):
        if self.distribution == "uniform":
            if self.low is None or self.high is None:
                raise ValueError("uniform noise needs low and high")
            if len(self.low) != len(self.high):
                raise ValueError("low and high must have the same length")
            if any(a > b for a, b in zip(self.low, self.high)):
                raise ValueError("low exceeds high")
        elif self.std is None:
            raise ValueError("normal noise needs std")
        return self


class ScenarioSpec(_Strict):
    """A complete, self-contained closed-loop experiment."""

    id: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    description: str = ""
    dt_s: Positive = 0.01
    duration_s: Positive
    seed: Int = Field(0, ge=0, lt=2**63)
    stop_at_path_end: bool = True
    vehicle: VehicleSpec = VehicleSpec()
    path: PathSpec
    road: RoadSpec | None = None
    initial_state: InitialState = InitialState()
    controller: ControllerSpec
    plant: PlantSpec = PlantSpec()
    disturbance: NoiseSpec | None = None
    measurement_noise: NoiseSpec | None = None

    @model_validator(mode="after")
    def _sizes(self):
        nx, nu = (3, 1) if self.vehicle.model == "kinematic3" else (4, 2)
        c = self.controller
        for name, w, n in (("Q", c.Q, nx), ("QN", c.QN, nx), ("R", c.R, nu), ("Rc", c.Rc, nu)):
            if w is not None and len(w) != n:
                raise ValueError(f"controller.{name} needs {n} entries for {self.vehicle.model}, got {len(w)}")
        for name, spec in (("disturbance", self.disturbance), ("measurement_noise", self.measurement_noise)):
            if spec is not None:
                for field in ("low", "high", "std"):
                    v = getattr(spec, field)
                    if v is not None and len(v) != nx:
                        raise ValueError(f"{name}.{field} needs {nx} entries (one per state), got {len(v)}")
        if self.duration_s / self.dt_s > 1_000_000:
            raise ValueError("duration_s / dt_s exceeds 1,000,000 steps")
        if self.vehicle.model != "kinematic3" and self.plant.speed_mps is not None:
            raise ValueError("plant.speed_mps is only for the constant-speed model kinematic3 "
                             f"({self.vehicle.model} has the speed as a state)")
        if self.duration_s < self.dt_s:
            raise ValueError(f"duration_s {self.duration_s} is shorter than one step dt_s {self.dt_s}")
        if self.road is not None and self.road.lane_width_m <= self.vehicle.width_m:
            raise ValueError(f"road.lane_width_m {self.road.lane_width_m} m is not wider than the car "
                             f"(vehicle.width_m {self.vehicle.width_m} m)")
        d = _distance_to_path(self.path, (self.initial_state.x_m, self.initial_state.y_m))
        if d > MAX_INITIAL_DISTANCE_M:
            raise ValueError(f"initial_state: position ({self.initial_state.x_m}, {self.initial_state.y_m}) is "
                             f"{d:.4g} m from the path (more than {MAX_INITIAL_DISTANCE_M:g} m): check the "
                             "coordinates and their units")
        return self


def _segment_distance(p, a, b) -> float:
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    dd = dx * dx + dy * dy
    t = 0.0 if dd == 0 else max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / dd))
    return math.hypot(p[0] - ax - t * dx, p[1] - ay - t * dy)


def _distance_to_path(path, p) -> float:
    """Distance [m] from point ``p`` to the path (to the waypoint polygon for waypoint paths)."""
    if path.type == "straight":
        return _segment_distance(p, path.start, path.end)
    if path.type == "circle":
        return abs(math.dist(p, path.center) - path.radius_m)
    pts = list(path.points) + ([path.points[0]] if path.closed else [])
    return min(_segment_distance(p, a, b) for a, b in zip(pts[:-1], pts[1:]))
