"""Scenario files: YAML validated by pydantic.

SI units unless the key names another unit (``yaw_deg``, ``max_steer_deg``). Unknown keys are
rejected, every number must be finite.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNeg = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Point = tuple[Finite, Finite]


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


PathSpec = Annotated[StraightSpec | CircleSpec | WaypointsSpec, Field(discriminator="type")]


class VehicleSpec(_Strict):
    """Vehicle model and geometry. ``kinematic3``: constant ``speed_mps``; ``kinematic4``: speed is a
    state driven by acceleration."""

    model: Literal["kinematic3", "kinematic4"] = "kinematic3"
    lf_m: Positive = 0.17
    lr_m: Positive = 0.16
    speed_mps: Finite = 1.0
    length_m: Positive = 0.50
    width_m: Positive = 0.27


class InitialState(_Strict):
    """Initial pose and speed."""

    x_m: Finite = 0.0
    y_m: Finite = 0.0
    yaw_deg: Finite = 0.0
    v_mps: NonNeg | None = None


class RoadSpec(_Strict):
    """A lane centred on the reference path."""

    lane_width_m: Positive


class ControllerSpec(_Strict):
    """LTV-MPC settings; weights are diagonals in the model's state / input order.

    ``backend``: ``fast`` (the whole step compiled; falls back to ``osqp`` with a warning for a
    problem it does not cover) or ``osqp`` (the sparse QP solved by OSQP, the reference)."""

    horizon: int = Field(30, ge=1, le=1000)
    Q: list[NonNeg]
    R: list[NonNeg]
    QN: list[NonNeg] | None = None
    Rc: list[NonNeg] | None = None
    max_steer_deg: Positive = 60.0
    max_steer_rate_deg_s: Positive | None = None
    accel_limits_mps2: tuple[Finite, Finite] | None = None
    speed_limits_mps: tuple[Finite, Finite] | None = None
    reference_speed_mps: Finite | None = None
    linearization: Literal["trajectory", "paper"] = "trajectory"
    discretization: Literal["rk4", "euler"] = "rk4"
    horizon_reference: Literal["arc_length", "paper"] = "arc_length"
    horizon_step_m: Positive = 0.025
    feedforward: Literal["curvature", "none"] = "curvature"
    lane_slack_weight: NonNeg = 1e4
    lane_slack_weight_l1: NonNeg = 1e3
    osqp_eps: Positive = 1e-5
    osqp_max_iter: int = Field(4000, ge=1)
    backend: Literal["osqp", "fast"] = "fast"

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


class PlantSpec(_Strict):
    """The simulated vehicle: ``same`` model as the controller, integrated with ``integrator``."""

    model: Literal["same"] = "same"
    integrator: Literal["rk4", "euler"] = "rk4"
    substeps: int = Field(1, ge=1, le=100)


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
    seed: int = 0
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
        return self
