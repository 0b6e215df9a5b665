"""Run metrics (``metrics.json``), computed from a SimResult only.

:func:`compute_metrics` returns a :class:`Metrics`: a frozen dataclass with one typed field per
key of ``metrics.json``, and at the same time a read-only mapping whose items are that JSON view
(``m["collisions"]``, ``dict(m)``, ``m.get("commonroad")``; :meth:`Metrics.as_dict`)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..scene.footprint import Footprint
from ..types import FALLBACK_KINDS, STATUS_HELD, STATUS_INACCURATE, STATUS_OK, SimResult
from .actuator import SteeringActuator
from .verdict import LANE_TOLERANCE_M, SATURATION_TOLERANCE, RunVerdict, VerdictCriteria, goal_condition, run_verdict

__all__ = [
    "LANE_TOLERANCE_M",
    "CollisionEvent",
    "CommonRoadCheck",
    "Metrics",
    "SolveTimes",
    "WholeDriveCheck",
    "apply_goal_region",
    "compute_metrics",
    "lane_excess_per_step",
]


@dataclass(frozen=True)
class CollisionEvent:
    """One contact of the body with an obstacle (``metrics.json["collision_events"]``, from
    ``SimResult.meta["collision_events"]``).

    obstacle : index of the obstacle in the scenario's list (traffic follows the obstacles);
    name : its name (``""`` when it has none); step : the first overlapping logged step, or the
    one before the contact when it began between two steps (the motion between them is
    checked, :mod:`mpcdrive.sim.contact`); t_s : when it began [s]; steps : logged steps in
    contact (their intervals included); depth_m : the deepest penetration [m] (> 0)."""

    obstacle: int
    name: str
    step: int
    t_s: float
    steps: int
    depth_m: float

    def as_dict(self) -> dict[str, Any]:
        """The JSON object of ``metrics.json`` (keys in field order)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


@dataclass(frozen=True)
class SolveTimes:
    """Solve-time percentiles [µs] over the real solves of a run (``held`` steps left out):
    ``p50`` (median), ``p99`` and ``max``. They vary from run to run with the machine's load."""

    p50: float
    p99: float
    max: float

    def as_dict(self) -> dict[str, float]:
        """``{"p50": ..., "p99": ..., "max": ...}``, as in ``metrics.json``."""
        return {"p50": self.p50, "p99": self.p99, "max": self.max}


@dataclass(frozen=True)
class WholeDriveCheck:
    """The drivability checker's verdicts on the whole drive, step 0 to the end of the run
    (``metrics.json["commonroad"]["whole_drive"]``): a drive that reaches the goal and then
    collides or leaves the road has not passed.

    collision_free : against the scenario's obstacles; road_compliant : inside the road boundary
    and not past the mapped road's start or end (the boundary the checker builds does not close
    the road's ends: the body's reach past them is mpcdrive's measure, ``past_road_end_m``);
    feasible : every state reachable from the one before under the solution's model;
    states_checked : the states judged; collision_t_s, off_road_t_s, infeasible_t_s : the time
    [s] of the first state that failed each check (None: none did); past_road_end_m : how far
    [m] the body reached behind the road's start or past its end (0 inside; None: the road has
    no ends along the route); goal_t_s : when the goal was reached [s] (None: never), so a
    failure reads as before or after it."""

    collision_free: bool
    road_compliant: bool
    feasible: bool
    states_checked: int
    collision_t_s: float | None = None
    off_road_t_s: float | None = None
    infeasible_t_s: float | None = None
    past_road_end_m: float | None = None
    goal_t_s: float | None = None

    @property
    def passed(self) -> bool:
        """Collision-free, on the road and feasible from start to end."""
        return self.collision_free and self.road_compliant and self.feasible

    def as_dict(self) -> dict[str, Any]:
        """The JSON object of ``metrics.json["commonroad"]["whole_drive"]`` (``passed`` included)."""
        d: dict[str, Any] = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["passed"] = self.passed
        return d


@dataclass(frozen=True)
class CommonRoadCheck:
    """The CommonRoad block of a run's metrics (``metrics.json["commonroad"]``, written by the
    CommonRoad adapter, docs/commonroad.md): the drivability checker's verdicts on the drive and
    CommonRoad's solution checker on the solution written.

    file : the scenario file's name; route_lanelets : the route's lanelet ids; plan : how the
    goal is driven, in words (None without a plan); goal_reached, goal_step : the first step
    whose state is in the planning problem's goal (None: never); collision_free, road_compliant :
    the drive up to the goal (else all of it) against the obstacles and the road boundary;
    ks_feasible : the solution trajectory is feasible for its model (``vehicle_model``);
    states_checked : the states judged; passed : all of these, ``solution_valid`` and the whole
    drive's checks; solution : the solution file's name; vehicle_type : CommonRoad's vehicle
    type; vehicle_model : the model of the solution's states (``KS``, ``ST``); solution_valid,
    solution_check : CommonRoad's solution checker's verdict and message; whole_drive : the
    checks of the whole drive, start to end of the run (:class:`WholeDriveCheck`; None where
    they were not made); goal_miss : where the goal was missed, why in words (the goal's parts
    the closest state misses, :func:`~mpcdrive.adapters.commonroad_goal.goal_miss`; None when reached)."""

    file: str
    route_lanelets: tuple[int, ...]
    plan: str | None
    goal_reached: bool
    goal_step: int | None
    collision_free: bool
    road_compliant: bool
    ks_feasible: bool
    states_checked: int
    passed: bool
    solution: str
    vehicle_type: str
    vehicle_model: str
    solution_valid: bool
    solution_check: str
    whole_drive: WholeDriveCheck | None = None
    goal_miss: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """The JSON object of ``metrics.json["commonroad"]`` (keys in field order)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["route_lanelets"] = list(self.route_lanelets)
        d["whole_drive"] = None if self.whole_drive is None else self.whole_drive.as_dict()
        return d


def _plain(value: Any) -> Any:
    """A field's value as it appears in ``metrics.json`` (nested records as dicts, a fresh copy
    of a dict)."""
    if isinstance(value, (CollisionEvent, SolveTimes, CommonRoadCheck, VerdictCriteria, RunVerdict)):
        return value.as_dict()
    if isinstance(value, SteeringActuator):
        return {
            "time_constant_s": value.time_constant_s,
            "dead_time_s": value.dead_time_s,
            "max_rate_rad_s": None if value.max_rate_rad_s == math.inf else value.max_rate_rad_s,
        }
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return dict(value)
    return value


@dataclass(frozen=True, eq=False)
class Metrics(Mapping[str, Any]):
    """The metrics of one run (:func:`compute_metrics`): one field per key of ``metrics.json``,
    units in the names ([m], [s], [rad], [rad/s], [µs]); ``None`` where a figure can be absent.

    Tracking (the path's lateral error ``e_y`` and heading error ``e_psi``, per plant step):

    steps : plant steps run; duration_s : steps x dt [s]; rms_lateral_error_m,
    max_abs_lateral_error_m, final_lateral_error_m : RMS, largest and last |e_y| [m];
    converged_rms_lateral_error_m, converged_max_abs_lateral_error_m : the same over the second
    half of the run [m]; rms_heading_error_rad : RMS of e_psi [rad].

    Steering (rates include the first step's change from the initial steering angle,
    ``meta["initial_steer_rad"]``, 0 by default: the wheels start straight):

    max_abs_steer_rad : largest |steering angle| [rad]; max_abs_steer_rate_rad_s : largest
    |steering rate| [rad/s]; steer_total_variation_rad : sum of |steering changes| [rad] (the
    smoothing study).

    Safety:

    min_obstacle_clearance_m : smallest footprint-to-obstacle distance [m] (negative: overlap;
    None without obstacles); collisions : contacts with obstacles (a stretch of steps in contact
    counts once; at least 1 when the plant reported a crash); collision_events : each contact
    (:class:`CollisionEvent`), in time order, ``()`` without one; first_collision : the
    first event or None (follows ``collision_events``; not an argument); road_given : False when
    no road or lane was given; max_lane_excess_m : the body's largest excess outside the road
    [m] (0 inside; the road's own rule).

    Solver (``solver_failures`` and ``solve_time_us`` count real solves only: the plant steps
    between the solves of a controller slower than the plant, status ``held``, are neither):

    solver_failures : solves that failed; fallbacks : steps that used a fallback rung;
    fallback_counts : steps per fallback rung, every rung listed (``relax``, ``shifted_plan``,
    ``brake``, ``hold_last``); solve_time_us : solve-time percentiles (:class:`SolveTimes`).

    Outcome:

    goal_region_reached : the raw test of the goal (``criteria.goal``): for ``reach`` the end
    of an open path or the laps were reached (``SimResult.goal_reached``; None: the run has no
    goal region), for ``standstill`` the car was standing at the end; goal_reached : the
    verdict's goal part where there is a goal region -- reached, inside the road, without
    collision and ending within ``criteria.max_final_lateral_error_m`` of the path (None: no
    goal region; for CommonRoad the planning problem's goal and the checker's verdicts,
    :func:`apply_goal_region`); not an argument; termination : how the run ended
    (``completed``: it ran its steps, ``path_end_reached``, ``laps_completed``,
    ``aborted_off_path``, ``diverged``, or an episodic plant's reason); controller_backend : the
    MPC implementation that ran (``fast``: the condensed solver, ``osqp``, or ``pg``: projected
    gradient; from ``meta["backend"]``; None if not recorded).

    Steering limits and saturation (against the limits the controller had, ``meta["steer_limits_rad"]``
    and ``meta["steer_rate_limit_rad_s"]``; over the solves, a rate being the change of the
    command from one solve to the next over the control period; a command within
    :data:`~mpcdrive.sim.verdict.SATURATION_TOLERANCE` of a limit is at it):

    final_speed_mps : |speed| at the last logged step [m/s]; steer_limit_rad : the steering
    angle limit [rad] (None: not recorded); steer_rate_limit_rad_s : the steering-rate limit
    [rad/s] (None: none); steer_saturated_fraction, steer_rate_saturated_fraction : the fraction
    of solves whose command sat at the angle / rate limit (None: no such limit);
    steering_actuator : the plant's steering (:class:`~mpcdrive.sim.SteeringActuator` as
    ``{time_constant_s, dead_time_s, max_rate_rad_s}``, ``max_rate_rad_s`` None for no limit;
    all 0 / None: ideal, the paper's; None: a plant that steers itself, not recorded).

    Verdict:

    criteria : the :class:`~mpcdrive.sim.VerdictCriteria` the run was judged by (goal, final
    lateral error and standstill speed allowed, lane tolerance); verdict : the run's
    :class:`~mpcdrive.sim.RunVerdict` (:func:`~mpcdrive.sim.run_verdict` of these metrics;
    not an argument), ``metrics.json["verdict"]``.

    External checkers:

    commonroad : the CommonRoad block (:class:`CommonRoadCheck`) of a run of a CommonRoad file,
    None otherwise (then the key is absent from ``metrics.json``).

    Maneuver planner (a run on a road with lanes, docs/planning.md):

    planner : ``{replannings, unsafe, sampled: {p50, max}, checked: {p50, max}, plan_time_us:
    {p50, p99, max}}``: the replannings, those without a safe maneuver, the candidate pairs each
    sampled and checked, and its wall time [µs] (from ``meta["planner"]``); None without a
    planner (then the key is absent from ``metrics.json``).

    The JSON view: :meth:`as_dict` gives ``metrics.json``'s dict (nested records as dicts,
    ``collision_events`` a list, no ``commonroad`` / ``planner`` key when it is None). A Metrics is also a
    read-only :class:`~collections.abc.Mapping` over that view, so code written for the dict works:
    ``m["collisions"]``, ``m["solve_time_us"]["p50"]``, ``m.get("commonroad")``, ``dict(m)``,
    ``{**m}``, ``json.dumps(dict(m))``; items are fresh copies (changing one changes nothing).
    It equals any mapping with the same items. Typed code uses the attributes
    (``m.solve_time_us.p50``, ``m.collision_events[0].t_s``)."""

    steps: int
    duration_s: float
    rms_lateral_error_m: float
    max_abs_lateral_error_m: float
    final_lateral_error_m: float
    converged_rms_lateral_error_m: float
    converged_max_abs_lateral_error_m: float
    rms_heading_error_rad: float
    max_abs_steer_rad: float
    max_abs_steer_rate_rad_s: float
    steer_total_variation_rad: float
    min_obstacle_clearance_m: float | None
    collisions: int
    collision_events: tuple[CollisionEvent, ...]
    first_collision: CollisionEvent | None = field(init=False)
    road_given: bool
    max_lane_excess_m: float
    solver_failures: int
    fallbacks: int
    fallback_counts: dict[str, int]
    solve_time_us: SolveTimes
    goal_region_reached: bool | None
    goal_reached: bool | None = field(init=False)
    termination: str
    controller_backend: str | None
    final_speed_mps: float
    steer_limit_rad: float | None
    steer_rate_limit_rad_s: float | None
    steer_saturated_fraction: float | None
    steer_rate_saturated_fraction: float | None
    steering_actuator: SteeringActuator | None
    criteria: VerdictCriteria = VerdictCriteria(max_final_lateral_error_m=0.5 * Footprint().width_m)
    commonroad: CommonRoadCheck | None = None
    planner: dict | None = None
    verdict: RunVerdict = field(init=False)

    def __post_init__(self) -> None:
        events = tuple(self.collision_events)
        object.__setattr__(self, "collision_events", events)
        object.__setattr__(self, "first_collision", events[0] if events else None)
        object.__setattr__(self, "goal_reached", None)  # run_verdict does not read it
        v = run_verdict(self)
        object.__setattr__(self, "goal_reached", None if self.goal_region_reached is None else v.goal_reached)
        object.__setattr__(self, "verdict", v)

    def as_dict(self) -> dict[str, Any]:
        """The run's ``metrics.json`` as a dict of plain JSON types (numbers, bools, strings,
        None, lists, dicts), keys in the order of the fields (``commonroad`` and ``planner`` only
        when given)."""
        return {k: self[k] for k in self}

    # -- the read-only Mapping over the JSON view -------------------------------------------------
    def __getitem__(self, key: str) -> Any:
        if key not in _FIELD_NAMES or (key in _OPTIONAL and getattr(self, key) is None):
            raise KeyError(key)
        return _plain(getattr(self, key))

    def __iter__(self) -> Iterator[str]:
        return (k for k in _KEYS if k not in _OPTIONAL or getattr(self, k) is not None)

    def __len__(self) -> int:
        return len(_KEYS) - sum(getattr(self, k) is None for k in _OPTIONAL)


#: the keys of ``metrics.json`` in order (``commonroad`` only for CommonRoad runs, ``verdict`` last)
_KEYS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(Metrics))
_FIELD_NAMES = frozenset(_KEYS)
_OPTIONAL = ("commonroad", "planner")  # keys absent from metrics.json when None


def lane_excess_per_step(result: SimResult) -> np.ndarray | None:
    """(K,) distance [m] by which the body was outside the road at each step (0 inside), measured
    in the run by the road's measure (:meth:`~mpcdrive.scene.road.Road.measure_excess_m`); None
    without a road."""
    return result.lane_excess_m


def _lane_excess(result: SimResult) -> float:
    """Largest distance [m] by which the body left the road (0 inside)."""
    e = lane_excess_per_step(result)
    return 0.0 if e is None or e.size == 0 else float(np.max(e))


def apply_goal_region(metrics: Metrics, region_reached: bool, commonroad: CommonRoadCheck | None = None) -> Metrics:
    """``metrics`` judged on another goal region (a CommonRoad planning problem's):
    ``goal_region_reached`` becomes ``region_reached`` and, with ``commonroad``, the metrics hold
    that checker's block; the goal and the verdict follow (:func:`~mpcdrive.sim.run_verdict`),
    with the checker's collision and road verdicts as the authority: mpcdrive's own lane there
    (one width along the route's centre line) is a proxy that a lane change or a wider lanelet
    exceeds."""
    cr = metrics.commonroad if commonroad is None else commonroad
    return dataclasses.replace(metrics, goal_region_reached=bool(region_reached), commonroad=cr)


def _rms(a) -> float:
    a = np.asarray(a, float)
    return float(np.sqrt(np.mean(a * a))) if a.size else float("nan")


def compute_metrics(result: SimResult, criteria: VerdictCriteria | None = None) -> Metrics:
    """The metrics of one run (:class:`Metrics`, whose :meth:`~Metrics.as_dict` is the run's
    ``metrics.json``), from ``result`` alone: its log and ``result.meta`` (collisions and their
    events, obstacle clearance, termination, backend, initial steering angle, the steering limits
    and actuator, the car's width), judged by ``criteria`` (default: ``meta["criteria"]``, a
    scenario's, else :class:`~mpcdrive.sim.VerdictCriteria`'s defaults; a final-error tolerance
    of None is half the car's width)."""
    K = result.steps
    ey = result.e_y_m
    half = ey[K // 2 :]
    steer = result.steer_rad
    # steering is 0 before the first step (the controller starts from u_prev = 0)
    steer0 = np.r_[result.meta.get("initial_steer_rad", 0.0), steer]
    rate = np.diff(steer0) / result.dt_s
    solved = np.array([s != STATUS_HELD for s in result.status], dtype=bool)
    st = np.asarray(result.solve_time_s, float)[solved] * 1e6
    failures = sum(1 for s in result.status if s not in (STATUS_OK, STATUS_INACCURATE, STATUS_HELD))
    collisions = int(result.meta.get("collisions", 0))
    events = tuple(CollisionEvent(**e) for e in result.meta.get("collision_events", ()))
    lane_excess = _lane_excess(result)
    clearance = result.meta.get("min_obstacle_clearance_m")
    if criteria is None:
        criteria = VerdictCriteria.from_mapping(result.meta.get("criteria"))
    criteria = criteria.resolved(result.meta.get("footprint_width_m", Footprint().width_m))
    final_speed = float(abs(result.v_mps[-1])) if K else math.nan
    return Metrics(
        steps=int(K),
        duration_s=float(K * result.dt_s),
        rms_lateral_error_m=_rms(ey),
        max_abs_lateral_error_m=float(np.max(np.abs(ey))),
        final_lateral_error_m=float(abs(ey[-1])),
        converged_rms_lateral_error_m=_rms(half),
        converged_max_abs_lateral_error_m=float(np.max(np.abs(half))),
        rms_heading_error_rad=_rms(result.e_psi_rad),
        max_abs_steer_rad=float(np.max(np.abs(steer))),
        max_abs_steer_rate_rad_s=float(np.max(np.abs(rate))),
        steer_total_variation_rad=float(np.sum(np.abs(np.diff(steer0)))),
        min_obstacle_clearance_m=None if clearance is None else float(clearance),
        collisions=collisions,
        collision_events=events,
        road_given=result.lane_excess_m is not None,
        max_lane_excess_m=lane_excess,
        solver_failures=int(failures),
        fallbacks=int(sum(1 for f in result.fallback if f)),
        fallback_counts=_fallback_counts(result.fallback),
        solve_time_us=SolveTimes(
            p50=float(np.percentile(st, 50)),
            p99=float(np.percentile(st, 99)),
            max=float(np.max(st)),
        ),
        goal_region_reached=goal_condition(criteria, result.goal_reached, final_speed),
        termination=result.meta.get("termination", "completed"),
        controller_backend=result.meta.get("backend") or None,
        final_speed_mps=final_speed,
        **dataclasses.asdict(_saturation(result, steer0, solved)),
        steering_actuator=result.meta.get("steering_actuator"),
        criteria=criteria,
        planner=result.meta.get("planner"),
    )


@dataclass
class _Saturation:
    steer_limit_rad: float | None = None
    steer_rate_limit_rad_s: float | None = None
    steer_saturated_fraction: float | None = None
    steer_rate_saturated_fraction: float | None = None


def _saturation(result: SimResult, steer0: np.ndarray, solved: np.ndarray) -> _Saturation:
    """The steering limits the controller had (``meta["steer_limits_rad"]``, ``(lo, hi)`` [rad],
    and ``meta["steer_rate_limit_rad_s"]``) and the fraction of solves whose command sat at each
    (within :data:`SATURATION_TOLERANCE` of it): a rate is the command's change since the
    previous solve over the control period."""
    limits = result.meta.get("steer_limits_rad")
    rate_limit = result.meta.get("steer_rate_limit_rad_s")
    out = _Saturation(steer_rate_limit_rad_s=None if rate_limit is None else float(rate_limit))
    u = steer0[1:][solved]
    n = int(u.size)
    if limits is not None:
        lo, hi = (float(b) for b in limits)
        out.steer_limit_rad = max(abs(lo), abs(hi))
        if n:
            at = (u >= hi - SATURATION_TOLERANCE * abs(hi)) | (u <= lo + SATURATION_TOLERANCE * abs(lo))
            out.steer_saturated_fraction = float(np.count_nonzero(at)) / n
    if rate_limit is not None and n:
        period = float(result.meta.get("control_period_s", result.dt_s))
        rate = np.abs(u - np.r_[steer0[0], u[:-1]]) / period
        out.steer_rate_saturated_fraction = float(np.count_nonzero(rate >= (1 - SATURATION_TOLERANCE) * rate_limit)) / n
    return out
    if limits is not None:
        lo, hi = (float(b) for b in limits)
        out["steer_limit_rad"] = max(abs(lo), abs(hi))
        at = (u >= hi - SATURATION_TOLERANCE * abs(hi)) | (u <= lo + SATURATION_TOLERANCE * abs(lo))
        out["steer_saturated_fraction"] = float(np.count_nonzero(at)) / n
    if rate_limit is not None:
        period = float(result.meta.get("control_period_s", result.dt_s))
        prev = np.r_[steer0[0], u[:-1]]
        rate = np.abs(u - prev) / period
        out["steer_rate_saturated_fraction"] = (
            float(np.count_nonzero(rate >= (1 - SATURATION_TOLERANCE) * rate_limit)) / n
        )
    return out


def _fallback_counts(fallback) -> dict[str, int]:
    counts = {k: 0 for k in FALLBACK_KINDS}
    for f in fallback:
        if f:
            counts[f] = counts.get(f, 0) + 1
    return counts
