"""Scenario files: YAML validated by pydantic.

SI units unless the key names another unit (``yaw_deg``, ``max_steer_deg``). Unknown keys are
rejected, every number must be finite and a number (not a quoted string or a boolean), integers
must be integers, and values outside anything sensible (an initial position kilometres from the
path, a lane narrower than the car) are rejected with the reason.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal, NoReturn

from pydantic import Field, ValidationError, field_validator, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError

from ..models.presets import PRESETS
from ..control.fallback import DEFAULT_LADDER, check_ladder
from ..control.mpc import MpcConfig
from ..planning.config import PlannerConfig
from ..ocp.avoidance import AvoidanceConfig
from ..sim.closed_loop import solve_interval
from .fields import Coord, Finite, Int, Length, NonNeg, Point, Positive, Speed
from .fields import Strict as _Strict
from .steering import ActuatorSpec, VerdictSpec, resolve_steering_and_verdict
from ..solvers.osqp_backend import OsqpSettings

#: the core's defaults, which the scenario schema repeats
_AV = AvoidanceConfig()

#: largest distance [m] between the initial position and the path
MAX_INITIAL_DISTANCE_M = 1000.0
FallbackName = Literal["relax", "shifted_plan", "brake", "hold_last"]


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
    """Curve through ``points`` [m] (at least two distinct points).

    ``interpolation``: ``pchip`` (shape-preserving: through every point, no overshoot, straight
    legs stay straight and corners stay corners) or ``spline`` (a cubic spline, smooth but it
    overshoots at corners; ``smoothing`` > 0 is its smoothing factor). When omitted: ``spline``
    if ``smoothing`` > 0, else ``pchip``.
    """

    type: Literal["waypoints"]
    points: list[Point] = Field(min_length=2)
    closed: bool = False
    smoothing: NonNeg = 0.0
    interpolation: Literal["pchip", "spline"] = "pchip"
    ds_m: Positive | None = None  # table spacing [m] (default: length / 20000, within 2 mm .. 0.1 m)

    @model_validator(mode="before")
    @classmethod
    def _default_interpolation(cls, data):
        # smoothing belongs to the spline: a file that smooths without naming a curve gets one
        if isinstance(data, dict) and "interpolation" not in data:
            sm = data.get("smoothing", 0.0)
            if isinstance(sm, (int, float)) and not isinstance(sm, bool) and sm > 0:
                data = {**data, "interpolation": "spline"}
        return data

    @model_validator(mode="after")
    def _distinct(self):
        if self.interpolation == "pchip" and self.smoothing > 0:
            raise ValueError(f"smoothing {self.smoothing} applies to interpolation: spline only, not pchip")
        pts = [p for i, p in enumerate(self.points) if i == 0 or math.dist(p, self.points[i - 1]) > 1e-9]
        if self.closed and len(pts) > 2 and math.dist(pts[0], pts[-1]) <= 1e-9:
            pts = pts[:-1]
        need = 3 if self.closed else 2
        if len(pts) < need:
            raise ValueError(
                f"{'a closed' if self.closed else 'an open'} path needs at least {need} distinct points, got {len(pts)}"
            )
        return self


class CsvPathSpec(_Strict):
    """Track from a CSV waypoint file (columns x_m, y_m and optionally w_tr_right_m, w_tr_left_m):
    ``file`` is a packaged track name (``raceway``, ``hairpins``) or a path, relative to the
    scenario file; ``closed``: None decides from the data; ``smoothing``: spline smoothing factor."""

    type: Literal["csv"]
    file: str = Field(min_length=1)
    closed: bool | None = None
    smoothing: NonNeg = 0.0


PathSpec = Annotated[StraightSpec | CircleSpec | WaypointsSpec | CsvPathSpec, Field(discriminator="type")]

ModelName = Literal["kinematic3", "kinematic4", "dynamic_linear", "dynamic_pacejka"]
PresetName = Literal[tuple(PRESETS)]  # type: ignore[valid-type]
_PRESET_KEYS = (
    "lf_m",
    "lr_m",
    "mass_kg",
    "yaw_inertia_kgm2",
    "friction",
    "cs_front_per_rad",
    "cs_rear_per_rad",
    "h_cg_m",
    "pacejka_c",
    "pacejka_e",
    "length_m",
    "width_m",
)


#: CommonRoad plant models; the closed loop observes them as kinematic4 (x, y, yaw, v at the CoG)
COMMONROAD_PLANTS = ("commonroad_ks", "commonroad_st", "commonroad_mb")
CommonRoadVehicle = Literal["ford_escort", "bmw_320i", "vw_vanagon"]


def model_size(model: str) -> tuple[int, int]:
    """(nx, nu) of a model name (a CommonRoad plant: the size of the state it is observed in)."""
    if model in COMMONROAD_PLANTS:
        return 4, 2
    return {"kinematic3": (3, 1), "kinematic4": (4, 2)}.get(model, (6, 2))


class VehicleSpec(_Strict):
    """Vehicle model (the controller's) and parameters. ``kinematic3``: constant ``speed_mps``;
    ``kinematic4``: speed is a state driven by acceleration; ``dynamic_linear`` /
    ``dynamic_pacejka``: dynamic bicycle (x, y, yaw, vx, vy, r) with linear / magic-formula tires.

    ``preset`` (``f1tenth``, ``commonroad_ford_escort``, ``commonroad_bmw_320i``,
    ``commonroad_vw_vanagon``) fills every parameter not given explicitly. The dynamic parameters
    (mass, yaw inertia, friction, cornering stiffness coefficients C_S per rad, CoG height, magic
    formula C and E, speeds of the kinematic-to-dynamic blend) default to the F1TENTH car's."""

    model: ModelName = "kinematic3"
    preset: PresetName | None = None
    lf_m: Length = 0.17
    lr_m: Length = 0.16
    speed_mps: Annotated[Speed, Field(gt=0)] = 1.0
    length_m: Length = 0.50
    width_m: Length = 0.27
    footprint_discs: Int = Field(3, ge=1, le=10)
    mass_kg: Positive = 3.74
    yaw_inertia_kgm2: Positive = 0.04712
    friction: Positive = 1.0489
    cs_front_per_rad: Positive = 4.718
    cs_rear_per_rad: Positive = 5.4562
    h_cg_m: NonNeg = 0.074
    pacejka_c: Annotated[float, Field(gt=0, lt=2, allow_inf_nan=False)] = 1.3507
    pacejka_e: Annotated[float, Field(lt=1, allow_inf_nan=False)] = -0.0074722
    v_blend_low_mps: Positive = 0.5
    v_blend_high_mps: Positive = 1.0

    @model_validator(mode="before")
    @classmethod
    def _fill_from_preset(cls, data):
        if isinstance(data, dict) and isinstance(data.get("preset"), str) and data["preset"] in PRESETS:
            pre = PRESETS[data["preset"]]
            p = pre.params
            values = {
                "lf_m": p.lf_m,
                "lr_m": p.lr_m,
                "mass_kg": p.mass_kg,
                "yaw_inertia_kgm2": p.yaw_inertia_kgm2,
                "friction": p.friction,
                "cs_front_per_rad": p.cs_front_per_rad,
                "cs_rear_per_rad": p.cs_rear_per_rad,
                "h_cg_m": p.h_cg_m,
                "pacejka_c": p.pacejka_c,
                "pacejka_e": p.pacejka_e,
                "length_m": pre.length_m,
                "width_m": pre.width_m,
            }
            data = {**{k: values[k] for k in _PRESET_KEYS}, **data}
        return data

    @model_validator(mode="after")
    def _blend_order(self):
        if self.v_blend_low_mps >= self.v_blend_high_mps:
            raise ValueError("v_blend_low_mps must be below v_blend_high_mps")
        return self


class TrajectorySpec(_Strict):
    """A recorded obstacle trajectory: world positions ``points`` [m] (and optional ``yaw_deg``)
    at times ``t_s`` [s]."""

    t_s: list[Finite] = Field(min_length=1)
    points: list[Point]
    yaw_deg: list[Finite] | None = None

    @model_validator(mode="after")
    def _consistent(self):
        if len(self.points) != len(self.t_s):
            raise ValueError("points needs one entry per time in t_s")
        if self.yaw_deg is not None and len(self.yaw_deg) != len(self.t_s):
            raise ValueError("yaw_deg needs one entry per time in t_s")
        if any(b <= a for a, b in zip(self.t_s, self.t_s[1:])):
            raise ValueError("t_s must be strictly increasing")
        return self


class ObstacleSpec(_Strict):
    """An obstacle: ``circle`` (radius_m), ``rectangle`` (length_m, width_m) or convex ``polygon``
    (points in the obstacle frame) at ``position`` [m] with ``yaw_deg``; static, moving at
    ``velocity_mps`` (vx, vy) or along a recorded ``trajectory``; present over ``lifetime_s``
    ([start, end] in s, default always: outside it the obstacle is neither avoided nor hit)."""

    shape: Literal["circle", "rectangle", "polygon"]
    position: Point | None = None
    yaw_deg: Finite = 0.0
    radius_m: Positive | None = None
    length_m: Positive | None = None
    width_m: Positive | None = None
    points: list[Point] | None = None
    velocity_mps: Point | None = None
    trajectory: TrajectorySpec | None = None
    name: str = ""
    lifetime_s: tuple[Finite, Finite] | None = None

    @model_validator(mode="after")
    def _complete(self):
        if self.lifetime_s is not None and self.lifetime_s[1] < self.lifetime_s[0]:
            raise ValueError(f"lifetime_s must be [start, end] with start <= end, got {list(self.lifetime_s)}")
        need = {"circle": ("radius_m",), "rectangle": ("length_m", "width_m"), "polygon": ("points",)}[self.shape]
        for key in need:
            if getattr(self, key) is None:
                raise ValueError(f"a {self.shape} obstacle needs {key}")
        if self.velocity_mps is not None and self.trajectory is not None:
            raise ValueError("give either velocity_mps or trajectory, not both")
        if self.position is None and self.trajectory is None:
            raise ValueError("an obstacle needs a position (or a trajectory)")
        return self


class AvoidanceSpec(_Strict):
    """How obstacles enter the MPC (see mpcdrive.ocp.avoidance; the defaults are
    :class:`~mpcdrive.ocp.avoidance.AvoidanceConfig`'s). ``follow_gap_s``: behind an obstacle
    blocking the lane the references trail it by that time gap (car following, on both
    backends)."""

    formulation: Literal["hard", "corridor", "potential", "gaussian"] = _AV.formulation
    margin_m: NonNeg = _AV.margin_m
    weight: NonNeg = _AV.weight
    epsilon_m2: Positive = _AV.epsilon_m2
    sigma_m: tuple[Positive, Positive] = _AV.sigma_m
    influence_m: Positive = _AV.influence_m
    max_obstacles: int = Field(_AV.max_obstacles, ge=1, le=50)
    detour: Literal["none", "trapezoid"] = _AV.detour
    detour_ramp_m: Positive = _AV.detour_ramp_m
    follow_gap_s: Positive | None = _AV.follow_gap_s
    follow_decel_mps2: Positive = _AV.follow_decel_mps2
    sqp_max_iterations: int = Field(1, ge=1, le=100)
    sqp_tol: Positive = 1e-4
    sqp_max_time_s: Positive | None = None  # real-time mode (opt-in): a wall-time cap per step [s]


class InitialState(_Strict):
    """Initial pose and speed."""

    x_m: Coord = 0.0
    y_m: Coord = 0.0
    yaw_deg: Annotated[float, Field(strict=True, ge=-3600, le=3600, allow_inf_nan=False)] = 0.0
    v_mps: Annotated[Speed, Field(ge=0)] | None = None


class LaneRowsSpec(_Strict):
    """One lane beside the route lane: its edges as rows ``[s_m, left_m, right_m]`` of lateral
    offsets [m] from the path (positive left) at increasing arc lengths, linear in between (a
    lane that has ended or not begun has no width there); ``oncoming``: it goes the other way."""

    name: str = Field(min_length=1)
    oncoming: bool = False
    rows: list[tuple[Finite, Finite, Finite]]

    @model_validator(mode="after")
    def _rows(self):
        if not self.rows:
            raise ValueError(f"lane {self.name}: rows needs at least one row [s_m, left_m, right_m]")
        s = [r[0] for r in self.rows]
        if any(b <= a for a, b in zip(s, s[1:])):
            raise ValueError(f"lane {self.name}: the arc lengths s_m must increase from row to row")
        if any(r[1] < r[2] for r in self.rows):
            raise ValueError(f"lane {self.name}: left_m must not be right of right_m")
        return self


class RoadSpec(_Strict):
    """The road around the reference path; the controller keeps the body ``margin_m`` inside it.
    One of: ``lane_width_m`` (a lane centred on the path), ``left_width_m`` and ``right_width_m``
    (the edges' distances to either side of the path), or ``widths`` (rows ``[s_m, left_width_m,
    right_width_m]`` at increasing arc lengths, linear in between: a road that narrows or widens
    is followed exactly). The road's other lanes, which the maneuver planner (the scenario's
    ``planner`` settings) changes into: ``neighbours`` (rows ``[s_m, left_m, right_m]``): how far
    lanes going the same way reach beyond the road's left / right edge (0 where there is none:
    one lane each side), or ``lane_rows``: each lane beside the route lane with its edges and
    direction (a CommonRoad import gives every lane of the carriageway and the first oncoming
    lane). ``start_m`` / ``end_m``
    [m] (optional): the arc lengths along the path where the mapped road begins / ends (a lane
    without a predecessor / successor); a body behind the start or past the end is off the road
    (the edges are held constant up to them; None: the road goes on)."""

    lane_width_m: Positive | None = None
    left_width_m: NonNeg | None = None
    right_width_m: NonNeg | None = None
    widths: list[tuple[NonNeg, NonNeg, NonNeg]] | None = None
    neighbours: list[tuple[NonNeg, NonNeg, NonNeg]] | None = None
    lane_rows: list[LaneRowsSpec] | None = None
    margin_m: NonNeg = 0.05
    start_m: Finite | None = None
    end_m: Finite | None = None

    @model_validator(mode="after")
    def _one_form(self):
        forms = [
            self.lane_width_m is not None,
            self.left_width_m is not None or self.right_width_m is not None,
            self.widths is not None,
        ]
        if sum(forms) != 1:
            raise ValueError("give the road as one of: lane_width_m, left_width_m + right_width_m, or widths")
        if forms[1] and (self.left_width_m is None or self.right_width_m is None):
            raise ValueError("left_width_m and right_width_m go together")
        if self.widths is not None:
            if len(self.widths) < 1:
                raise ValueError("widths needs at least one row [s_m, left_width_m, right_width_m]")
            s = [w[0] for w in self.widths]
            if any(b <= a for a, b in zip(s, s[1:])):
                raise ValueError("widths: the arc lengths s_m must increase from row to row")
        if self.neighbours is not None:
            s = [w[0] for w in self.neighbours]
            if not s or any(b <= a for a, b in zip(s, s[1:])):
                raise ValueError("neighbours: rows [s_m, left_m, right_m] with increasing s_m")
        if self.min_width_m <= 0:
            raise ValueError("the road has no width somewhere (left + right width is 0)")
        if self.neighbours is not None and self.lane_rows:
            raise ValueError("give the road's other lanes as one of: neighbours or lane_rows")
        if self.start_m is not None and self.end_m is not None and not self.start_m < self.end_m:
            raise ValueError(f"the road's start_m {self.start_m:g} m must be before its end_m {self.end_m:g} m")
        return self

    @property
    def min_width_m(self) -> float:
        """The narrowest width of the road [m]."""
        if self.lane_width_m is not None:
            return self.lane_width_m
        if self.widths is not None:
            return min(w[1] + w[2] for w in self.widths)
        assert self.left_width_m is not None and self.right_width_m is not None
        return self.left_width_m + self.right_width_m


class SpeedProfileSpec(_Strict):
    """Reference speed along the path limited by curvature and friction and by acceleration and
    braking (the car slows before bends): lateral acceleration <= ``lateral_accel_fraction`` *
    friction * g (or ``lateral_accel_max_mps2`` when given), forward / braking acceleration <=
    ``accel_max_mps2`` / ``decel_max_mps2`` (shared with the lateral one on the friction circle),
    speed <= ``v_max_mps``; ``v_start_mps`` / ``v_end_mps`` pin the ends of an open path,
    ``v_start_mps`` at ``start_m`` [m] along it (where the car starts when the path begins behind it);
    ``top_speed_until`` rows ``[s_until_m, v_mps]`` cap the top speed at ``v_mps`` up to arc length
    ``s_until_m`` (a slower approach, then on at ``v_max_mps``); ``curvature_rate_max_1pms``: the
    fastest change of curvature the steering follows [1/(m s)] (speed <= it over |d kappa / d s|)."""

    lateral_accel_fraction: Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)] = 0.8
    lateral_accel_max_mps2: Positive | None = None
    accel_max_mps2: Positive = 4.0
    decel_max_mps2: Positive = 4.0
    v_max_mps: Positive = 8.0
    v_start_mps: NonNeg | None = None
    v_end_mps: NonNeg | None = None
    curvature_window_m: NonNeg = 0.3
    friction_circle: bool = True
    start_m: NonNeg = 0.0
    top_speed_until: list[tuple[NonNeg, Positive]] = []
    curvature_rate_max_1pms: Positive | None = None


class ControllerSpec(_Strict):
    """LTV-MPC settings; weights are diagonals in the model's state / input order.

    ``backend``: ``fast`` (the default controller: the stage QP assembled by the compiled step and
    solved by the condensed solver, each replaced with a warning naming the reason where it does
    not cover the problem -- by the Python assembly, by OSQP with the ``osqp_*`` settings) or
    ``osqp`` (the reference: the stage QP assembled in Python, solved by OSQP).

    ``speed_profile`` replaces the constant reference speed; ``solver``: ``osqp`` or the paper's
    ``projected_gradient`` (input bounds only; ``pg_*`` settings); ``delay_compensation``: predict the
    state over the plant's steering dead time before solving (needs ``plant.steering_actuator``).

    ``period_s``: the controller's period [s] (default: the scenario's ``dt_s``, the plant step),
    a whole multiple of ``dt_s`` and the horizon step of its problem; between two solves the
    plant gets, per ``between_solves``, the last command (``hold``) or the plan's inputs followed
    in time (``plan``; :func:`~mpcdrive.sim.simulate`)."""

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
    discretization: Literal["rk4", "euler", "exp"] = "rk4"
    prediction_substeps: int = Field(1, ge=1, le=100)
    horizon_reference: Literal["arc_length", "paper"] = "arc_length"
    horizon_step_m: Positive = 0.025
    feedforward: Literal["curvature", "none"] = "curvature"
    # above this speed [m/s] the steering's weights in R and Rc grow as (v / it)^4, holding the
    # lateral loop's bandwidth at that of this speed (mpcdrive.control.MpcConfig); None: constant
    steer_weight_speed_mps: Positive | None = None
    lane_slack_weight: NonNeg = 1e4
    lane_slack_weight_l1: NonNeg = 1e3
    # the tyres' friction circle [m/s^2] as per-stage steering and acceleration bounds at the
    # planned speed (mpcdrive.ocp.friction); None: only the input bounds
    friction_accel_mps2: Positive | None = None
    osqp_eps: Positive = OsqpSettings.eps_abs
    speed_profile: SpeedProfileSpec | None = None
    solver: Literal["osqp", "projected_gradient"] = "osqp"
    pg_max_iter: int = Field(2000, ge=1)
    pg_tol: Positive = 1e-6
    pg_accelerated: bool = True
    delay_compensation: bool = False
    osqp_max_iter: Int = Field(OsqpSettings.max_iter, ge=1)
    fallback: list[FallbackName] = Field(default_factory=lambda: list(DEFAULT_LADDER))
    brake_decel_mps2: Positive | None = None  # None: the vehicle's full braking (accel_limits_mps2[0])
    brake_steering: Literal["hold", "straighten"] = "hold"
    relax_slack_factor: Annotated[float, Field(strict=True, ge=1, allow_inf_nan=False)] = 100.0
    check_plans: bool = True  # a fallback rung's plan is applied only if it is safer than braking
    projection_window_m: Positive = (
        MpcConfig.projection_window_m
    )  # how far along the path the car is looked for from the last step [m]
    osqp_polish: bool = OsqpSettings.polish
    osqp_adaptive_rho: bool = OsqpSettings.adaptive_rho
    osqp_time_limit_s: NonNeg = OsqpSettings.time_limit_s  # 0: none
    period_s: Positive | None = None
    between_solves: Literal["hold", "plan"] = "hold"

    @field_validator("fallback")
    @classmethod
    def _ladder(cls, v):
        check_ladder(v)
        return v

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


class ParamScaleSpec(_Strict):
    """Factors by which the plant's parameters differ from the vehicle's (the controller's belief):
    1.2 = the true car has 20 % more. Dynamic plants only."""

    mass: Positive = 1.0
    yaw_inertia: Positive = 1.0
    cornering_stiffness_front: Positive = 1.0
    cornering_stiffness_rear: Positive = 1.0
    friction: Positive = 1.0


class PlantSpec(_Strict):
    """The simulated vehicle: ``same`` model as the controller or another one (model mismatch),
    parameters scaled by ``param_scale``, integrated with ``integrator`` in ``substeps`` per control
    step, steering through ``steering_actuator``.

    ``commonroad_ks | commonroad_st | commonroad_mb``: CommonRoad's kinematic single-track,
    single-track or multi-body model of the CommonRoad ``vehicle`` (``ford_escort``, ``bmw_320i``,
    ``vw_vanagon``), steered through a rate-limited servo and integrated by the plant itself
    (see :mod:`mpcdrive.adapters.commonroad_vehicles`); needs a ``kinematic4`` controller."""

    model: Literal[
        "same", "kinematic4", "dynamic_linear", "dynamic_pacejka", "commonroad_ks", "commonroad_st", "commonroad_mb"
    ] = "same"
    vehicle: CommonRoadVehicle | None = None
    integrator: Literal["rk4", "euler"] = "rk4"
    substeps: int = Field(1, ge=1, le=100)
    param_scale: ParamScaleSpec | None = None
    # None: the vehicle's steering (resolved when the scenario is validated; stays None for a
    # CommonRoad plant, whose vehicle steers itself); ``ideal``: instant, at any rate (the paper's)
    steering_actuator: ActuatorSpec | Literal["ideal"] | None = None
    lf_m: Length | None = None
    lr_m: Length | None = None
    speed_mps: Annotated[Speed, Field(gt=0)] | None = None

    @model_validator(mode="after")
    def _commonroad(self):
        if self.model in COMMONROAD_PLANTS:
            if self.vehicle is None:
                raise ValueError(f"plant.model {self.model} needs plant.vehicle (ford_escort, bmw_320i or vw_vanagon)")
            other = sorted(
                self.model_fields_set
                & {"integrator", "substeps", "param_scale", "steering_actuator", "lf_m", "lr_m", "speed_mps"}
            )
            if other:
                raise ValueError(
                    f"plant.{other[0]} does not apply to plant.model {self.model} (the CommonRoad "
                    "vehicle has its own parameters, steering servo and integrator)"
                )
        elif self.vehicle is not None:
            raise ValueError(
                f"plant.vehicle needs a CommonRoad plant model ({', '.join(COMMONROAD_PLANTS)}), "
                f"got plant.model {self.model}"
            )
        return self


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


Interval = tuple[Finite, Finite]
#: an interval whose ends may be open (null: unbounded on that side)
OpenInterval = tuple[Finite | None, Finite | None]


class GoalSpec(_Strict):
    """Where and when the car should be (the maneuver planner plans for it): its reference
    point's arc length along the path in ``arc_m`` [m], its lateral offset from the path in
    ``offset_m`` [m], at a time in ``time_s`` [s], a speed in ``speed_mps`` [m/s] and a heading in
    ``yaw_deg`` [deg] (absolute, counter-clockwise from east). Each is ``[lo, hi]``; ``null`` for
    an end (or the whole entry) leaves it open."""

    arc_m: OpenInterval
    offset_m: OpenInterval | None = None
    time_s: OpenInterval | None = None
    speed_mps: OpenInterval | None = None
    yaw_deg: Interval | None = None

    @model_validator(mode="after")
    def _ordered(self):
        for name in ("arc_m", "offset_m", "time_s", "speed_mps", "yaw_deg"):
            v = getattr(self, name)
            if v is not None and v[0] is not None and v[1] is not None and v[0] > v[1]:
                raise ValueError(f"goal {name}: [lo, hi] needs lo <= hi, got {list(v)}")
        return self


def _planner_settings(v: dict | None) -> dict | None:
    """``planner`` settings by the names of :class:`~mpcdrive.planning.config.PlannerConfig`
    (plus ``replan_s``), checked by the config itself."""
    if v is None:
        return v
    known = set(PlannerConfig.__dataclass_fields__) | {"replan_s"}
    unknown = sorted(set(v) - known)
    if unknown:
        raise ValueError(f"unknown planner setting(s) {unknown}; known: {sorted(known)}")
    replan = v.get("replan_s", 0.0)
    if not (isinstance(replan, (int, float)) and not isinstance(replan, bool) and 0.0 <= replan <= 0.5):
        raise ValueError(f"replan_s must be between 0 and 0.5 s, got {replan!r}")
    cfg = {k: (tuple(x) if isinstance(x, list) else x) for k, x in v.items() if k != "replan_s"}
    PlannerConfig(**cfg)  # its own checks, with its own messages
    return v


class ScenarioSpec(_Strict):
    """A complete, self-contained closed-loop experiment. The plant's steering, the controller's
    steering-rate limit and the verdict's final-error tolerance are filled in when it is validated
    (:mod:`mpcdrive.scenarios.steering`)."""

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
    obstacles: list[ObstacleSpec] = Field(default_factory=list)
    avoidance: AvoidanceSpec | None = None
    laps: Positive | None = None
    verdict: VerdictSpec = VerdictSpec()
    #: the maneuver planner's settings (:class:`~mpcdrive.planning.config.PlannerConfig` names and
    #: ``replan_s``): it drives every road with lanes (``road.neighbours`` or ``road.lane_rows``),
    #: and a road without when the scenario gives settings (``planner: {}``)
    planner: dict[str, float | bool | list[float]] | None = None
    goal: GoalSpec | None = None

    @field_validator("planner")
    @classmethod
    def _planner(cls, v):
        return _planner_settings(v)

    @property
    def control_period_s(self) -> float:
        """The controller's period [s]: ``controller.period_s``, else the plant step ``dt_s``."""
        p = self.controller.period_s
        return self.dt_s if p is None else p

    @field_validator("controller")
    @classmethod
    def _period(cls, c, info):
        dt = info.data.get("dt_s")
        if dt is None:  # dt_s itself was rejected
            return c
        try:
            solve_interval(dt, c.period_s, name="period_s")
        except ValueError as e:
            _raise_at(("period_s",), c.period_s, str(e))
        if c.between_solves == "plan" and c.delay_compensation:
            _raise_at(
                ("between_solves",),
                c.between_solves,
                "plan cannot be combined with delay_compensation "
                "(the compensator predicts with held commands): use hold",
            )
        return c

    @property
    def plant_model(self) -> str:
        """The plant's model name (``same`` resolved)."""
        return self.vehicle.model if self.plant.model == "same" else self.plant.model

    @model_validator(mode="after")
    def _resolve_steering_and_verdict(self):
        problem = resolve_steering_and_verdict(self, commonroad=self.plant_model in COMMONROAD_PLANTS)
        if problem is not None:
            _raise_at(("controller", "max_steer_rate_deg_s"), self.controller.max_steer_rate_deg_s, problem)
        return self

    @model_validator(mode="after")
    def _sizes(self):
        """What holds between fields of several sections; each problem is raised at the field to
        change (``controller.Q``, ``laps``, ...), so the message names it."""
        nx, nu = model_size(self.vehicle.model)
        c = self.controller
        for name, w, n in (("Q", c.Q, nx), ("QN", c.QN, nx), ("R", c.R, nu), ("Rc", c.Rc, nu)):
            if w is not None and len(w) != n:
                _raise_at(("controller", name), w, f"needs {n} entries for {self.vehicle.model}, got {len(w)}")
        plant_nx, plant_nu = model_size(self.plant_model)
        if self.plant_model in COMMONROAD_PLANTS:
            if self.vehicle.model != "kinematic4":
                _raise_at(
                    ("vehicle", "model"),
                    self.vehicle.model,
                    f"plant.model {self.plant_model} is observed as kinematic4 (x, y, yaw, v at the "
                    f"centre of gravity); {self.vehicle.model} cannot be; use kinematic4",
                )
            if self.disturbance is not None:
                _raise_at(
                    ("disturbance",),
                    None,
                    f"not supported with plant.model {self.plant_model} (it is added to the plant "
                    "state); use measurement_noise",
                )
        if plant_nu != nu:
            _raise_at(
                ("plant", "model"),
                self.plant.model,
                f"{self.plant_model} has inputs of size {plant_nu} but the controller's "
                f"{self.vehicle.model} has {nu}; use a model with steering and acceleration",
            )
        if self.plant.param_scale is not None and not self.plant_model.startswith("dynamic"):
            _raise_at(("plant", "param_scale"), None, "needs a dynamic plant model")
        act = self.plant.steering_actuator
        if c.delay_compensation and not (isinstance(act, ActuatorSpec) and act.dead_time_s):
            _raise_at(
                ("controller", "delay_compensation"),
                True,
                "needs a steering dead time to compensate (plant.steering_actuator.dead_time_s > 0)",
            )
        for name, spec in (("disturbance", self.disturbance), ("measurement_noise", self.measurement_noise)):
            if spec is not None:
                for field in ("low", "high", "std"):
                    v = getattr(spec, field)
                    if v is not None and len(v) != plant_nx:
                        _raise_at((name, field), v, f"needs {plant_nx} entries (one per plant state), got {len(v)}")
        if self.laps is not None and self.path.type in ("straight",):
            _raise_at(("laps",), self.laps, "needs a closed path")
        if self.avoidance is not None and self.avoidance.formulation == "corridor" and self.road is None:
            _raise_at(("avoidance", "formulation"), "corridor", "corridor needs a road (road.lane_width_m)")
        if self.duration_s / self.dt_s > 1_000_000:
            _raise_at(("duration_s",), self.duration_s, f"more than 1,000,000 steps of dt_s {self.dt_s}")
        if self.vehicle.model != "kinematic3" and self.plant.speed_mps is not None:
            _raise_at(
                ("plant", "speed_mps"),
                self.plant.speed_mps,
                f"only for the constant-speed model kinematic3 ({self.vehicle.model} has the speed as a state)",
            )
        if self.duration_s < self.dt_s:
            _raise_at(("duration_s",), self.duration_s, f"{self.duration_s} is shorter than one step dt_s {self.dt_s}")
        if self.road is not None and self.road.min_width_m <= self.vehicle.width_m:
            _raise_at(
                ("road",),
                None,
                f"the road ({self.road.min_width_m:g} m where narrowest) is not wider than the car "
                f"(vehicle.width_m {self.vehicle.width_m} m)",
            )
        d = _distance_to_path(self.path, (self.initial_state.x_m, self.initial_state.y_m))
        if d > MAX_INITIAL_DISTANCE_M:
            _raise_at(
                ("initial_state",),
                None,
                f"position ({self.initial_state.x_m}, {self.initial_state.y_m}) is "
                f"{d:.4g} m from the path (more than {MAX_INITIAL_DISTANCE_M:g} m): check the "
                "coordinates and their units",
            )
        return self


def _raise_at(loc: tuple, value, problem: str) -> NoReturn:
    """Raise a validation error at ``loc`` (inside the field being validated, or from a model
    validator of the whole scenario) so the message names e.g. ``controller.period_s``, not the
    enclosing model."""
    err = PydanticCustomError("value_error", "{problem}", {"problem": problem})
    raise ValidationError.from_exception_data("ScenarioSpec", [InitErrorDetails(type=err, loc=loc, input=value)])


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
    if not hasattr(path, "points"):  # a track file: checked when it is loaded
        return 0.0
    pts = list(path.points) + ([path.points[0]] if path.closed else [])
    return min(_segment_distance(p, a, b) for a, b in zip(pts[:-1], pts[1:]))
