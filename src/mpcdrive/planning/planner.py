"""The maneuver planner: describe once, then replan in place.

:class:`ManeuverPlanner` is built once from the reference path, the road with its lanes, the
vehicle's limits, the wanted speed along the path and (optionally) the goal; it lays the road
out on a uniform grid and allocates every array a replanning uses. :meth:`ManeuverPlanner.plan`
then takes the car's state and the obstacles (their compiled table) and returns the chosen
:class:`Maneuver`; the sampling, checks and choice run in one compiled call
(:mod:`.kernels`, where the method is described).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..ocp.avoidance_compiled import ObstacleTable
from ..paths.compiled import PathArrays, path_arrays, path_eval
from ..paths.profile_compiled import np_interp
from ..paths.speed_profile import segment_times
from ..scene.road import Road
from . import kernels
from .config import PlannerConfig, VehicleLimits
from .frenet import heading_within, is_pass, lane_at
from .tracks import CACHE_COLS, obstacle_tracks
from .work import (
    road_windows,
    E_A,
    E_CURV,
    E_D,
    E_LANE,
    E_PREV_LANE,
    E_PREV_OFF,
    E_MOVE_END,
    E_MOVE_LANE,
    E_MOVE_OFF,
    E_S,
    E_SLOPE,
    E_T,
    E_V,
    G_D_HI,
    G_D_LO,
    G_HAS,
    G_HAS_YAW,
    G_S_HI,
    G_S_LO,
    G_T_HI,
    G_T_LO,
    G_V_HI,
    G_V_LO,
    G_YAW_HI,
    G_YAW_LO,
    LANE_ONCOMING,
    LANE_ROUTE,
    LANE_SAME,
    LON_NAMES,
    MAX_LANES,
    MAX_OBS,
    PLAN_TOLERANCE,
    P_A_COMF,
    P_A_MAX,
    P_BAND_K,
    P_C_CHANGE,
    P_C_GAP,
    P_C_GOAL,
    P_C_RATE,
    P_REAR,
    P_ROWS_EXCESS,
    P_C_OFFROUTE,
    P_C_ONCOMING,
    P_C_SWITCH,
    P_CO,
    P_CREEP,
    P_R_DISC,
    P_D_COMF,
    P_D_MAX,
    P_FRICTION,
    P_HL,
    P_HW,
    P_JERK_REF,
    P_KAPPA_MAX,
    P_KAPPA_RATE,
    P_LAT_MIN,
    P_LAT_REF,
    P_MARGIN,
    P_ONCOMING,
    P_ROAD_END,
    P_ROAD_MARGIN,
    P_ROAD_START,
    P_SHIFT,
    P_STANDSTILL,
    P_STOP_V,
    P_TIME_GAP,
    P_V_MAX,
    R_CHECKED,
    R_COMBOS,
    R_COST,
    R_GOAL,
    R_I,
    R_KIND,
    R_LANE,
    R_OFF,
    R_SAFE,
    R_SAFE_COUNT,
    R_TARGET,
    R_TTC,
    PlannerWork,
    new_work,
)

__all__ = ["LateralMove", "Maneuver", "ManeuverPlanner", "PlanningGoal"]

#: the grid step [m] the road is laid out on
GRID_M = 0.5
#: how far [m] the grid reaches past the path's ends (the road is constant beyond them)
GRID_PAST_M = 20.0
#: the time steps [count] of the obstacles' box cache (60 s at 0.1 s); later ones are computed
TRACK_CACHE_STEPS = 600
#: obstacles farther across the path than this [m] at every sample are not checked
LATERAL_RANGE_M = 25.0
#: no last move to go on with (lane, offset, end [m] of the ego's E_MOVE_* slots)
NO_MOVE = (-1.0, 0.0, math.nan)


def _state_at(m: Maneuver, tau: float) -> tuple[float, float, float, float]:
    """(s [m], v [m/s], a [m/s^2], d [m]) where maneuver ``m`` has the car ``tau`` [s] after its
    replanning (interpolated between its samples)."""
    t = m.t_s
    return (
        float(np_interp(tau, t, m.s_m)),
        float(np_interp(tau, t, m.v_mps)),
        float(np_interp(tau, t, m.a_mps2)),
        float(np_interp(tau, t, m.d_m)),
    )


def wanted_times(grid_s: np.ndarray, v_mps: np.ndarray, v_max_mps: float) -> np.ndarray:
    """The time [s] the wanted speed ``v_mps`` (G,) [m/s], at most ``v_max_mps``, takes from the
    grid's first point to each point of ``grid_s`` (G,) [m]: each step at constant acceleration
    (2 ds over the two ends' speeds); every point past a step between two standstills is
    ``inf`` (:func:`~mpcdrive.paths.speed_profile.segment_times`, as the speed profile's own
    times)."""
    v = np.minimum(np.asarray(v_mps, float), v_max_mps)
    return np.r_[0.0, np.cumsum(segment_times(np.diff(np.asarray(grid_s, float)), v))]


@dataclass(frozen=True)
class PlanningGoal:
    """Where and when the car should be, in the path's frame: its centre's arc length in
    ``arc_m`` [m] and lateral offset in ``offset_m`` [m], at a time in ``time_s`` [s] (the run's
    clock), at a speed in ``speed_mps`` [m/s] and (optionally) a heading in ``yaw_rad`` (absolute,
    counter-clockwise from east; an interval lo <= hi). Open ends are infinite."""

    arc_m: tuple[float, float]
    offset_m: tuple[float, float] = (-math.inf, math.inf)
    time_s: tuple[float, float] = (-math.inf, math.inf)
    speed_mps: tuple[float, float] = (0.0, math.inf)
    yaw_rad: tuple[float, float] | None = None

    def __post_init__(self):
        for name in ("arc_m", "offset_m", "time_s", "speed_mps") + (("yaw_rad",) if self.yaw_rad else ()):
            lo, hi = getattr(self, name)
            if math.isnan(lo) or math.isnan(hi) or lo > hi:
                raise ValueError(f"goal {name} must be an interval lo <= hi, got {(lo, hi)!r}")

    def reached(self, t_s: float, s_m: float, e_y_m: float, v_mps: float, yaw_rad: float | None = None) -> bool:
        """Whether a car at arc length ``s_m``, offset ``e_y_m``, speed ``v_mps`` at ``t_s`` is in the goal."""
        inside = (
            self.time_s[0] <= t_s <= self.time_s[1]
            and self.arc_m[0] <= s_m <= self.arc_m[1]
            and self.offset_m[0] <= e_y_m <= self.offset_m[1]
            and self.speed_mps[0] - 1e-6 <= v_mps <= self.speed_mps[1] + 1e-6
        )
        if inside and self.yaw_rad is not None and yaw_rad is not None:
            inside = heading_within.py_func(float(yaw_rad), *self.yaw_rad)
        return inside


@dataclass(frozen=True, eq=False)
class LateralMove:
    """The chosen lateral motion as offsets from the path: the quintic ``coef`` in ``s - s0_m``
    up to ``s0_m + length_m``, then the line ``line_m`` (on the road's knots ``knots_m``) plus
    ``offset_m``. Callable on arc lengths [m] (the controller's lateral reference)."""

    s0_m: float
    length_m: float
    coef: np.ndarray
    knots_m: np.ndarray
    line_m: np.ndarray
    offset_m: float
    samples_s: np.ndarray | None = None
    samples_d: np.ndarray | None = None

    def __call__(self, s_m) -> np.ndarray:
        s = np.asarray(s_m, float)
        if self.samples_s is not None and self.samples_d is not None:  # an evasive move's samples
            line = np.interp(s, self.knots_m, self.line_m) + self.offset_m
            inside = s <= self.samples_s[-1]
            return np.where(inside, np.interp(s, self.samples_s, self.samples_d), line)
        u = np.clip(s - self.s0_m, 0.0, self.length_m)
        c = self.coef
        poly = c[0] + u * (c[1] + u * (c[2] + u * (c[3] + u * (c[4] + u * c[5]))))
        line = np.interp(s, self.knots_m, self.line_m) + self.offset_m
        return np.where(s - self.s0_m < self.length_m, poly, line)

    def at(self, s_m: float) -> float:
        """The offset [m] at one arc length ``s_m`` [m]: ``self(s_m)`` without the arrays (the
        same arithmetic, a replanning's few lookups)."""
        s = float(s_m)
        if self.samples_s is not None and self.samples_d is not None:
            return float(self(s))
        if s - self.s0_m < self.length_m:
            u = min(max(s - self.s0_m, 0.0), self.length_m)
            c = self.coef
            return float(c[0] + u * (c[1] + u * (c[2] + u * (c[3] + u * (c[4] + u * c[5])))))
        return float(np.interp(s, self.knots_m, self.line_m)) + self.offset_m

    def curvature(self, s_m: float) -> float:
        """d''(s) [1/m] of the move at ``s_m`` (0 on the line past it)."""
        if self.samples_s is not None and self.samples_d is not None:
            ss, dd = self.samples_s, self.samples_d
            if len(ss) < 3 or not (ss[0] <= s_m <= ss[-1]):
                return 0.0
            k = int(np.clip(np.searchsorted(ss, s_m), 1, len(ss) - 2))
            h0, h1 = ss[k] - ss[k - 1], ss[k + 1] - ss[k]
            return float(2.0 * ((dd[k + 1] - dd[k]) / h1 - (dd[k] - dd[k - 1]) / h0) / (h0 + h1))
        u = float(s_m) - self.s0_m
        if u >= self.length_m:
            return 0.0
        u = max(u, 0.0)
        c = self.coef
        return float(2.0 * c[2] + u * (6.0 * c[3] + u * (12.0 * c[4] + u * 20.0 * c[5])))


@dataclass(frozen=True, eq=False)
class Maneuver:
    """A replanning's choice.

    t_s : (K+1,) times after the replanning [s]; s_m : the car's arc length along the path [m];
    v_mps, a_mps2 : its speed and acceleration (along its own way, which a lateral move slants
    against the path); d_m : the lateral offset [m]; lateral : the :class:`LateralMove`; lane : the
    lane it ends in (index into the road's lanes); offset_m : its offset from that lane's line;
    kind : the longitudinal profile's kind (``reference``, ``speed``, ``stop``, ``follow``,
    ``goal``) and target its number (speed [m/s], stop point [m], lane); safe : checked free of
    contact and inside the road over the horizon; ttc_s : when it would first hit (inf: never);
    cost_s : its cost [s]; goal : it reaches the goal; lanes : the lanes the body uses over the
    controller's horizon; candidates / checked / safe_count : pairs sampled, checked, found safe;
    relations (n, K+1) : per obstacle row (``obstacle_index``) and sample, REL_* of :mod:`.work`;
    plan_time_s : the replanning's wall time [s]."""

    t_s: np.ndarray
    s_m: np.ndarray
    v_mps: np.ndarray
    a_mps2: np.ndarray
    d_m: np.ndarray
    lateral: LateralMove
    lane: int
    offset_m: float
    kind: str
    target: float
    safe: bool
    ttc_s: float
    cost_s: float
    goal: bool
    lanes: tuple[int, ...]
    candidates: int
    checked: int
    safe_count: int
    relations: np.ndarray
    obstacle_index: np.ndarray
    plan_time_s: float


class ManeuverPlanner:
    """Samples, checks and chooses maneuvers on ``road`` (its lanes; a road without lanes is one
    lane) along ``path`` for a vehicle with ``limits``; ``wanted_speed`` is the speed [m/s] the
    car wants along the path (a callable of arc length, e.g. a speed profile's ``speed``, or a
    number); ``goal`` a :class:`PlanningGoal` or None; ``band_steps``: how many steps of the
    maneuver the controller's road (``Maneuver.lanes``) covers; ``cache_step_s``: the time step
    [s] the replannings come on (the control period), on whose grid the obstacles' boxes are
    kept between replannings (0: none kept); ``bend``: a callable of arc length, the inverse
    [s/m] of the speed above which the path bends faster than the car can steer (a speed
    profile's :meth:`~mpcdrive.paths.speed_profile.SpeedProfile.bend`; None: no such limit): a
    maneuver faster than that steers beyond the rate."""

    def __init__(
        self,
        path,
        road: Road,
        limits: VehicleLimits,
        config: PlannerConfig | None = None,
        wanted_speed=None,
        goal: PlanningGoal | None = None,
        band_steps: int | None = None,
        cache_step_s: float = 0.0,
        bend=None,
    ):
        cfg = config or PlannerConfig()
        self.config = cfg
        self.limits = limits
        self.path = path
        self.road = road
        self.goal = goal
        if getattr(path, "closed", False):
            raise ValueError("the maneuver planner drives open paths (a closed track has no lanes to change to)")
        pa = path_arrays(path)
        if pa is None:
            raise ValueError(
                f"the maneuver planner needs a straight, circle or waypoint path, got {type(path).__name__}"
            )
        self._pa: PathArrays = pa
        K = cfg.steps
        self.K = K
        s_lo = min(float(road.s_m[0]), 0.0) - GRID_PAST_M
        s_hi = max(float(road.s_m[-1]), float(path.length_m)) + GRID_PAST_M
        grid = np.arange(s_lo, s_hi + GRID_M, GRID_M)
        lanes = road.lanes
        if len(lanes) > MAX_LANES:
            raise ValueError(f"the maneuver planner takes at most {MAX_LANES} lanes, the road has {len(lanes)}")
        L = max(len(lanes), 1)
        arrays = new_work(K, grid, L)
        arrays["g_kappa"][:] = np.asarray(path.curvature(grid), float)
        arrays["g_heading"][:] = np.unwrap(np.asarray(path.heading(grid), float))
        if wanted_speed is None:
            raise ValueError("the maneuver planner needs the wanted speed along the path")
        if callable(wanted_speed):
            arrays["g_vref"][:] = np.asarray(wanted_speed(grid), float)
        else:
            arrays["g_vref"][:] = float(wanted_speed)
        if bend is not None:
            arrays["g_bend"][:] = np.asarray(bend(grid), float)
        left_road = np.interp(grid, road.s_m, road.left_m)
        right_road = np.interp(grid, road.s_m, road.right_m)
        if lanes:
            for i, ln in enumerate(lanes):
                arrays["lane_left"][i] = np.interp(grid, road.s_m, ln.left_m)
                arrays["lane_right"][i] = np.interp(grid, road.s_m, ln.right_m)
                oncoming = bool(getattr(ln, "oncoming", False))
                if i == road.route_lane:
                    kind = LANE_ROUTE
                    arrays["lane_line"][i] = 0.0  # the path itself (a route moving over a lane spans two)
                else:
                    kind = LANE_ONCOMING if oncoming else LANE_SAME
                    arrays["lane_line"][i] = np.interp(grid, road.s_m, ln.center_m)
                arrays["lane_kind"][i] = kind
            same = [i for i in range(len(lanes)) if arrays["lane_kind"][i] != LANE_ONCOMING]
            arrays["same_left"][:] = np.maximum(left_road, np.max(arrays["lane_left"][same], axis=0))
            arrays["same_right"][:] = np.minimum(right_road, np.min(arrays["lane_right"][same], axis=0))
            arrays["all_left"][:] = np.maximum(arrays["same_left"], np.max(arrays["lane_left"], axis=0))
            arrays["all_right"][:] = np.minimum(arrays["same_right"], np.min(arrays["lane_right"], axis=0))
        else:
            arrays["lane_left"][0] = left_road
            arrays["lane_right"][0] = right_road
            arrays["lane_line"][0] = 0.0
            arrays["lane_kind"][0] = LANE_ROUTE
            arrays["same_left"][:] = arrays["all_left"][:] = left_road
            arrays["same_right"][:] = arrays["all_right"][:] = right_road
        self._knots = road.s_m
        self._lines = [np.zeros_like(road.s_m) if i == road.route_lane else ln.center_m for i, ln in enumerate(lanes)]
        if not lanes:
            self._lines = [np.zeros_like(road.s_m)]
        par = arrays["par"]
        par[P_HL] = 0.5 * limits.length_m
        par[P_HW] = 0.5 * limits.width_m
        par[P_CO] = limits.center_offset_m
        par[P_KAPPA_MAX] = limits.max_curvature_1pm
        par[P_KAPPA_RATE] = limits.max_curvature_rate_1pms
        par[P_A_MAX] = limits.max_accel_mps2
        par[P_D_MAX] = limits.max_decel_mps2
        par[P_V_MAX] = limits.max_speed_mps
        arrays["g_tref"][:] = wanted_times(grid, arrays["g_vref"], limits.max_speed_mps)
        par[P_FRICTION] = limits.friction_mps2 if math.isfinite(limits.friction_mps2) else 1e9
        par[P_A_COMF] = min(cfg.comfort_accel_mps2, limits.max_accel_mps2)
        par[P_D_COMF] = min(cfg.comfort_decel_mps2, limits.max_decel_mps2)
        par[P_MARGIN] = cfg.margin_m
        par[P_ROAD_MARGIN] = max(road.margin_m, cfg.road_margin_m)
        par[P_TIME_GAP] = cfg.time_gap_s
        par[P_STANDSTILL] = cfg.standstill_m
        par[P_STOP_V] = cfg.stop_speed_mps
        par[P_CREEP] = cfg.creep_mps
        par[P_LAT_MIN] = cfg.lateral_min_m
        par[P_SHIFT] = cfg.lane_shift_m
        par[P_ONCOMING] = 1.0 if cfg.oncoming else 0.0
        par[P_C_CHANGE] = cfg.lane_change_s
        par[P_C_OFFROUTE] = cfg.off_route_s_per_s
        par[P_C_ONCOMING] = cfg.oncoming_s_per_s
        par[P_C_SWITCH] = cfg.switch_s
        par[P_C_GAP] = cfg.gap_cost_s_per_s
        par[P_C_GOAL] = cfg.goal_miss_s
        par[P_C_RATE] = cfg.rate_excess_s
        par[P_REAR] = limits.rear_axle_m
        # the controller's Frenet rows about an obstacle keep its Frenet box; a maneuver keeps the
        # planner's margin off its oriented box: those rows hold the maneuver (within the
        # tracking's tolerance) where the box exceeds the outline by less than that tolerance and
        # what the planner keeps beyond the rows' own margin
        par[P_ROWS_EXCESS] = max(cfg.margin_m - limits.disc_margin_m, 0.0) + cfg.rows_tolerance_m
        par[P_JERK_REF] = cfg.jerk_ref_mps3
        par[P_LAT_REF] = cfg.lat_accel_ref_mps2
        start, end = getattr(road, "start_m", None), getattr(road, "end_m", None)
        self._road_ends = (-math.inf if start is None else float(start), math.inf if end is None else float(end))
        par[P_ROAD_START], par[P_ROAD_END] = self._road_ends
        par[P_BAND_K] = K if band_steps is None else int(band_steps)
        arrays["lat_lengths_s"] = np.asarray(cfg.lateral_s, float)
        arrays["speed_s"] = np.asarray(cfg.speed_s, float)
        arrays["dt"][0] = cfg.dt_s
        if limits.disc_radius_m > 0.0:
            arrays["discs"] = np.asarray(limits.disc_offsets_m, float)
            par[P_R_DISC] = limits.disc_radius_m
        else:  # one disc round the whole body
            arrays["discs"] = np.array([limits.center_offset_m])
            par[P_R_DISC] = math.hypot(0.5 * limits.length_m, 0.5 * limits.width_m)
        road_windows(arrays)  # the edges at their tightest within the body's reach
        self.work = PlannerWork(**arrays)
        self._struct = self.work.struct()
        self._index = np.zeros(MAX_OBS, np.int64)
        self._t = cfg.dt_s * np.arange(K + 1)
        self.previous: Maneuver | None = None
        self._planned_t = 0.0
        self._move = NO_MOVE  # the last choice's move: lane, offset, end [m]
        #: the obstacles' boxes already projected, per obstacle and time step of ``cache_step_s``
        #: (the replanning period: a replanning shares all but its newest samples with the last)
        self.cache_step_s = cache_step_s
        self._cache = np.zeros((0, 0, 4))
        self._cache_of: ObstacleTable | None = None
        self._range_m = limits.max_speed_mps * cfg.horizon_s + 60.0
        self.set_goal(goal)
        # compile (or load) the kernels now, not in the first control step
        self._warm_up()

    def set_goal(self, goal: PlanningGoal | None) -> None:
        """Plan for ``goal`` from the next replanning on (None: no goal, e.g. once reached)."""
        self.goal = goal
        g = self.work.goal
        g[:] = 0.0
        if goal is None:
            return
        g[G_HAS] = 1.0
        g[G_S_LO], g[G_S_HI] = goal.arc_m
        g[G_D_LO], g[G_D_HI] = goal.offset_m
        g[G_T_LO], g[G_T_HI] = goal.time_s
        g[G_V_LO], g[G_V_HI] = goal.speed_mps
        if goal.yaw_rad is not None:
            g[G_HAS_YAW] = 1.0
            g[G_YAW_LO], g[G_YAW_HI] = goal.yaw_rad

    def _warm_up(self) -> None:
        from ..ocp.avoidance_compiled import table_of
        from ..scene.obstacles import Circle, Obstacle

        goal = self.goal
        tab = table_of([Obstacle(Circle(1.0), (0.0, 50.0, 0.0))], None)
        m = self.plan(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, tab)
        # and a second replanning, on that maneuver with the same obstacles: the code that goes
        # on from the last maneuver and reuses the tracks' cache runs first there
        t = self.cache_step_s
        s, v, a, d = _state_at(m, t)
        self.plan(t, s, d, v, 0.0, a, tab)
        self.previous = None
        self._move = NO_MOVE
        self._cache = np.zeros((0, 0, 4))
        self._cache_of = None
        self.set_goal(goal)

    def lane_at(self, s_m: float, d_m: float) -> int:
        """The lane holding offset ``d_m`` at ``s_m`` (else the one whose line is nearest)."""
        w = self.work
        return int(lane_at(w.grid, w.lane_left, w.lane_right, w.lane_line, w.lane_kind, float(s_m), float(d_m)))

    def _on_plan(self, t_s: float, s_m: float, e_y_m: float, v_mps: float):
        """(s, d, v, a, slope) where the last maneuver has the car at ``t_s``, when the
        car is that close to it (``PLAN_TOLERANCE``), else None: a controller tracking the plan
        is then replanned from the plan, so that successive choices stay consistent (a
        maneuver the controller lags a little behind is not dropped for it)."""
        m = self.previous
        if m is None:
            return None
        tau = t_s - self._planned_t
        if not (0.0 <= tau <= m.t_s[-1] - self.config.dt_s):
            return None
        s, v, a, d = _state_at(m, tau)
        tol_s, tol_d, tol_v = PLAN_TOLERANCE
        if abs(s - s_m) > tol_s or abs(d - e_y_m) > tol_d or abs(v - v_mps) > tol_v:
            return None
        h = 0.25
        d1 = (m.lateral.at(s + h) - m.lateral.at(s - h)) / (2.0 * h)
        return s, d, v, a, d1

    def plan(
        self,
        t_s: float,
        s_m: float,
        e_y_m: float,
        v_mps: float,
        slope: float,
        accel_mps2: float,
        obstacles: ObstacleTable,
        curvature_1pm: float = 0.0,
    ) -> Maneuver:
        """Replan for the car at time ``t_s`` [s], arc length ``s_m`` [m], offset ``e_y_m`` [m],
        speed ``v_mps`` [m/s] with heading slope ``slope`` (tan of its heading relative to the
        path), acceleration ``accel_mps2`` [m/s^2] and path curvature ``curvature_1pm`` [1/m] (its
        steering's: tan(delta) / wheelbase), among the ``obstacles`` (their compiled
        table, on the same clock)."""
        t0 = time.perf_counter()
        w = self.work
        cfg = self.config
        prev = self.previous
        e = w.ego
        on = self._on_plan(t_s, s_m, e_y_m, v_mps)
        lag = 0.0
        if on is not None:  # on the last maneuver: go on from where it has the car (consistent choices)
            lag = on[0] - s_m
            s_m, e_y_m, v_mps, accel_mps2, slope = on
        if self.goal is not None:
            # the goal is for the car, which is ``lag`` [m] behind where the plan has it: its
            # region is judged that much further along the plan's way
            w.goal[G_S_LO] = self.goal.arc_m[0] + lag
            w.goal[G_S_HI] = self.goal.arc_m[1] + lag
        # so are the road's ends, where the car must stop with its body inside: a car ahead of
        # the plan (lag < 0) meets the end that much sooner, one behind it leaves the start later
        w.par[P_ROAD_START] = self._road_ends[0] + max(lag, 0.0)
        w.par[P_ROAD_END] = self._road_ends[1] + min(lag, 0.0)
        # the lateral move starts at the car's curvature relative to the path's (as d''), within
        # what the vehicle can turn at its speed
        top = min(self.limits.max_curvature_1pm, self.limits.friction_mps2 / max(v_mps, 1.0) ** 2)
        pa = self._pa
        px, py, ph, pk = path_eval(pa.kind, pa.geo, pa.tab_s, pa.tab_xy, pa.tab_h, pa.tab_k, float(s_m))
        kappa = min(max(curvature_1pm, -top), top) - pk
        curv = kappa * (1.0 + min(slope * slope, 1.0)) ** 1.5
        e[E_S], e[E_D], e[E_V], e[E_T] = s_m, e_y_m, max(v_mps, 0.0), t_s
        e[E_SLOPE] = min(max(slope, -1.0), 1.0)
        e[E_A] = min(max(accel_mps2, -self.limits.max_decel_mps2), self.limits.max_accel_mps2)
        e[E_CURV] = curv
        e[E_LANE] = self.lane_at(s_m, e_y_m)
        e[E_PREV_LANE] = -1.0 if prev is None else prev.lane
        e[E_PREV_OFF] = 0.0 if prev is None else prev.offset_m
        e[E_MOVE_LANE], e[E_MOVE_OFF], e[E_MOVE_END] = self._move if on is not None else NO_MOVE
        x, y = px - math.sin(ph) * e_y_m, py + math.cos(ph) * e_y_m  # the car, e_y_m left of the path
        if obstacles is not self._cache_of:  # other obstacles (fresh predictions): a new cache
            self._cache = np.full((len(obstacles.obstacles), TRACK_CACHE_STEPS, CACHE_COLS), np.nan)
            self._cache_of = obstacles
        n = obstacle_tracks(
            obstacles, self._pa, t_s, cfg.dt_s, s_m, (x, y), self._range_m, LATERAL_RANGE_M, w.ob_s, w.ob_e, w.ob_hl,
            w.ob_hw, self._index, self._cache, self.cache_step_s, w.ob_or,
        )  # fmt: skip
        w.ob_n[0] = n
        kernels.plan(self._struct)
        r = w.result.tolist()  # the result's slots as Python numbers (each read once below)
        i = int(r[R_I])
        if i < 0:
            raise RuntimeError("the maneuver planner found no candidate (no lane and no speed profile to sample)")
        lane = int(r[R_LANE])
        # the move to go on with at the next replanning (a quintic's, or a pass's move out)
        length = float(w.lat_len[i])
        coef = w.lat_coef[i]
        end = s_m + length if length > 0.0 else math.nan
        self._move = (float(w.lat_lane[i]), float(w.lat_off[i]), end)
        if length > 0.0 and not is_pass.py_func(coef, length):
            lateral = LateralMove(float(s_m), length, coef.copy(), self._knots, self._lines[lane], r[R_OFF])
        else:  # an evasive move or a pass: its samples along the maneuver
            keep = np.r_[True, np.diff(w.plan_s) > 1e-3]
            lateral = LateralMove(
                float(s_m), 0.0, np.zeros(6), self._knots, self._lines[lane], r[R_OFF],
                samples_s=w.plan_s[keep], samples_d=w.plan_d[keep],
            )  # fmt: skip
        m = Maneuver(
            t_s=self._t,
            s_m=w.plan_s.copy(),
            v_mps=w.plan_v.copy(),
            a_mps2=w.plan_a.copy(),
            d_m=w.plan_d.copy(),
            lateral=lateral,
            lane=lane,
            offset_m=r[R_OFF],
            kind=LON_NAMES[int(r[R_KIND])],
            target=r[R_TARGET],
            safe=bool(r[R_SAFE]),
            ttc_s=r[R_TTC],
            cost_s=r[R_COST],
            goal=bool(r[R_GOAL]),
            lanes=tuple(np.flatnonzero(w.plan_lanes).tolist()),
            candidates=int(r[R_COMBOS]),
            checked=int(r[R_CHECKED]),
            safe_count=int(r[R_SAFE_COUNT]),
            relations=w.relation[:n].copy(),
            obstacle_index=self._index[:n].copy(),
            plan_time_s=0.0,
        )
        object.__setattr__(m, "plan_time_s", time.perf_counter() - t0)
        self.previous = m
        self._planned_t = t_s
        return m
