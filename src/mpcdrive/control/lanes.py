"""A small lane decision layer: which lane to drive in, and the lateral reference to get there.

The usual approach of sampling-based reactive planners (CommonRoad's, for one: candidates per
lane, each checked against the predicted traffic), reduced to one candidate per lane. Every
call looks at the lanes of a :class:`~mpcdrive.scene.road.Road` (lateral offset tables [m] on
the road's arc-length knots, positive left; ``route_lane`` the preferred one), the ego's Frenet
state on the road's reference path and the obstacles' predicted poses over ``horizon_s``,
projected onto that path (``path.project``; an obstacle counts only inside its lifetime).

Per lane it predicts the *free distance* [m]: the smallest gap, over the horizon, between the
ego (driving its current speed, accelerating at ``accel_mps2`` up to the desired speed) and the
obstacles ahead of it that are in that lane at that time (an obstacle counts in every lane its
lateral extent overlaps, so a car changing lanes is in both); negative when the ego would run
into one at that speed (how far: the more negative, the slower the lane), capped at the
look-ahead. A lane is *blocked* when that gap falls below ``standstill_m + time_gap_s *
v_desired``. The ego's own lane is *free* when it is not blocked; a neighbour lane is *free*
(to change into) when, during the change (the ego at its current speed ``v_ego``), the
obstacles ahead in it keep ``standstill_m + rear_time_gap_s * v_ego`` of gap and the traffic
behind the ego in it keeps ``standstill_m + rear_time_gap_s * v_follower`` (a car closing in
fast from behind makes the lane not free). Traffic behind the ego in its own lane is ignored.

Rules (:func:`decide_lane`):

* keep the current lane unless it is blocked and a free neighbour gives at least
  ``min_gain_m`` more free distance (then ``change`` to the best such neighbour);
* out of the route lane, return (``change``) towards it as soon as the neighbour towards it is
  free and at least as free as the current lane (``min_gain_m`` over the blocked threshold when
  the current lane is not blocked);
* blocked and no free neighbour: ``stop`` (with the distance ``stop_m`` to ``standstill_m``
  behind the nearest obstacle ahead now: the car follows or stops in its lane);
* a change past an obstacle ahead that its ramp, driven at the current speed, does not clear
  by ``pass_margin_m`` is capped at ``turn_out_mps`` (braking hard to it) until the ego is past
  the obstacle: an evasive change too close to swerve round at speed eases out while braking;
* a change keeps its target until the ego arrives (or is in the target lane with the pass
  over: the lane home clear over the whole look-ahead), unless the target stops being free while
  the ego is still in its origin lane (then it returns: the only change not held back by the
  dwell time); no voluntary change starts within ``min_dwell_s`` of the previous one.

The lateral reference (:class:`LateralRamp`) is a quintic ramp from the ego's offset where the
decision was taken to the target lane's line (:func:`lane_line`: the path itself in the route
lane, whose table may be wider than the lane the path is in, e.g. a route that moves over a
lane; a neighbour's centre), over the distance driven at the current speed
in the time that keeps the peak lateral acceleration and jerk within bounds, no steeper than
``max_slope`` and no shorter than ``turn_out_m``. numpy, with the obstacles' tracks along the
path compiled (:func:`_tracks_kernel`) where the obstacles and the path have a compiled form.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numba import njit

from ..ocp.avoidance_compiled import SHAPE_CIRCLE, ObstacleTable, pose_at, table_of
from ..paths.compiled import PathArrays, path_arrays, path_eval, path_project
from ..scene.obstacles import Circle, Obstacle
from ..scene.road import Road
from ..scene.world import Scene

__all__ = ["LaneConfig", "LaneDecision", "LateralRamp", "decide_lane", "lane_line", "lane_of"]

#: the gap [m] kept to an obstacle standing behind in a lane changed into (a parked car passed)
BEHIND_CLEARANCE_M = 1.0
#: peak |w''| and |w'''| of the quintic smoothstep w(x) = 10x^3 - 15x^4 + 6x^5 on [0, 1]
_PEAK_ACC, _PEAK_JERK = 10.0 / math.sqrt(3.0), 60.0
#: what the stop room leaves of the braking distance for the car not braking at once [m]
_STOP_SLACK_M = 1.0
#: peak slope of the smoothstep per unit of rise over run: w'(1/2) = 15/8
_PEAK_SLOPE = 15.0 / 8.0


@dataclass(frozen=True)
class LaneConfig:
    """Tuning of :func:`decide_lane` (SI units).

    horizon_s / dt_s : prediction horizon and its sampling [s]; desired_speed_mps : the speed
    the ego wants to drive [m/s] (None: its current speed); accel_mps2 : acceleration assumed
    up to it; time_gap_s / standstill_m : the gap ahead a lane must keep free [s, m];
    rear_time_gap_s : the time gap a follower in the target lane must keep [s];
    min_gain_m : extra free distance a change must bring [m]; min_dwell_s : least time between
    two voluntary changes [s]; min_return_s : least time in a lane before returning from it
    to the route lane when that is clear over the whole look-ahead [s] (a pass ends as soon as
    the obstacle is behind); max_lat_accel_mps2 / max_lat_jerk_mps3 : bounds of the ramp;
    min_change_s : shortest ramp [s]; arrive_m : |e_y - centre| that ends a change [m];
    range_m : obstacles further along the path than this are ignored [m];
    ego_length_m / ego_width_m : the ego's body [m]; creep_mps : below this speed [m/s] the car
    counts as stopped (its stop line stays put); turn_out_m : the shortest ramp [m], and the room
    the car keeps before an obstacle when it stops in its lane (:class:`LaneChoosingMpc`) so that
    it can still turn out of the lane from standstill; max_slope : the ramp's steepest slope
    (lateral per forward metre: a slow change is not a sharp turn); pass_margin_m : the room
    [m] beside an obstacle ahead in the ego's lane that a change's ramp, driven at the current
    speed, must give the body to pass it at speed; turn_out_mps : the speed cap [m/s] of a
    change whose ramp does not (an obstacle too close to swerve round at this speed): the MPC
    brakes to it at full deceleration while easing out, and passes slowly, its rows steering
    round the obstacle, until the ego is past it.
    """

    horizon_s: float = 8.0
    dt_s: float = 0.5
    desired_speed_mps: float | None = None
    accel_mps2: float = 1.0
    time_gap_s: float = 1.5
    standstill_m: float = 8.0
    rear_time_gap_s: float = 1.0
    min_gain_m: float = 15.0
    min_dwell_s: float = 3.0
    min_return_s: float = 1.0
    max_lat_accel_mps2: float = 3.0
    max_lat_jerk_mps3: float = 10.0
    min_change_s: float = 2.0
    arrive_m: float = 0.4
    range_m: float = 300.0
    ego_length_m: float = 5.0
    ego_width_m: float = 2.0
    creep_mps: float = 1.0
    turn_out_m: float = 10.0
    max_slope: float = 0.3
    pass_margin_m: float = 0.3
    turn_out_mps: float = 2.0

    def __post_init__(self):
        for name in (
            "horizon_s",
            "dt_s",
            "time_gap_s",
            "max_lat_accel_mps2",
            "max_lat_jerk_mps3",
            "max_slope",
            "turn_out_mps",
            "min_change_s",
            "arrive_m",
            "range_m",
            "ego_length_m",
            "ego_width_m",
            "accel_mps2",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be positive, got {v!r}")
        for name in (
            "standstill_m",
            "rear_time_gap_s",
            "min_gain_m",
            "min_dwell_s",
            "min_return_s",
            "creep_mps",
            "turn_out_m",
            "pass_margin_m",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be >= 0, got {v!r}")


@dataclass(frozen=True, eq=False)
class LateralRamp:
    """Lateral reference e_y(s) [m] on the road's path: ``e0_m`` at ``s0_m`` [m], the target
    lane's line (:func:`lane_line`, table ``center_m`` on knots ``knots_m``) from ``s1_m`` on, a
    quintic blend (zero slope and curvature at both ends) between."""

    s0_m: float
    s1_m: float
    e0_m: float
    knots_m: np.ndarray
    center_m: np.ndarray

    def offset(self, s_m) -> np.ndarray:
        """e_y [m] of the reference at arc length(s) ``s_m`` [m]."""
        s = np.asarray(s_m, float)
        x = np.clip((s - self.s0_m) / (self.s1_m - self.s0_m), 0.0, 1.0)
        w = x**3 * (10.0 - 15.0 * x + 6.0 * x * x)
        return (1.0 - w) * self.e0_m + w * np.interp(s, self.knots_m, self.center_m)


@dataclass(frozen=True, eq=False)
class LaneDecision:
    """The result of :func:`decide_lane`.

    lane : target lane index (into ``road.lanes``); current : the lane the ego is in;
    action : ``keep``, ``change`` (towards ``lane``) or ``stop`` (blocked, no free lane);
    free_m : (n_lanes,) predicted free distance ahead per lane [m] (capped at the look-ahead);
    free : (n_lanes,) whether each lane is free (own lane: not blocked ahead);
    ramp : the lateral reference to track; band : the lanes the body may use now (current and
    target, and any other the body overlaps now); band_m : their (right, left) edges at the ego
    [m]; stop_m : distance [m] to the stop point (``stop`` only, else None); since_s : when the target last changed [s] (-inf:
    never, the ego keeps the lane it started in); gap_m : bumper-to-bumper distance [m] to the
    nearest obstacle ahead in the ego's lane now (inf: none); called_back : the change is a
    called-back one, back to the lane a change left (it is driven home, never called back itself);
    origin : the lane a change started from (else ``current``); speed_cap_mps : the speed [m/s]
    the MPC's references keep to (a turn-out past an obstacle its ramp does not clear: see
    ``LaneConfig.turn_out_mps``), None: no cap.
    """

    lane: int
    current: int
    action: Literal["keep", "change", "stop"]
    free_m: tuple[float, ...]
    free: tuple[bool, ...]
    ramp: LateralRamp
    band: tuple[int, ...]
    band_m: tuple[float, float]
    stop_m: float | None
    since_s: float
    gap_m: float = math.inf
    called_back: bool = False
    origin: int = -1
    speed_cap_mps: float | None = None

    def __post_init__(self):
        if self.origin < 0:  # not a change: the lane the ego is in
            object.__setattr__(self, "origin", self.current)


def lane_line(road: Road, lane: int) -> np.ndarray:
    """The line [m] (offset from the road's path, on its knots) that the ego drives in ``lane``:
    the path itself (zeros) in the route lane -- the route's lanelets side by side where the
    route moves over a lane make that lane's table wider than the lane the path is in, and its
    middle no line to drive -- and the lane's centre in the others."""
    return np.zeros_like(road.s_m) if lane == road.route_lane else road.lanes[lane].center_m


def lane_of(road: Road, s_m: float, e_y_m: float) -> int:
    """The lane whose edges hold ``e_y_m`` [m] at ``s_m`` [m] (else the one with the nearest centre)."""
    if not road.lanes:
        raise ValueError("the road has no lanes")
    c = [float(np.interp(s_m, road.s_m, ln.center_m)) for ln in road.lanes]
    inside = [
        i
        for i, ln in enumerate(road.lanes)
        if np.interp(s_m, road.s_m, ln.right_m) <= e_y_m <= np.interp(s_m, road.s_m, ln.left_m)
    ]
    pool = inside or range(len(c))
    return min(pool, key=lambda i: abs(c[i] - e_y_m))


def _extent(ob: Obstacle, dyaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Half extents (along, across) [m] of the obstacle's shape yawed ``dyaw`` (K,) [rad] from
    the path, arrays (K,)."""
    if isinstance(ob.shape, Circle):
        r = np.full(len(dyaw), ob.shape.radius_m)
        return r, r
    p = ob.shape.points
    c, s = np.cos(dyaw)[:, None], np.sin(dyaw)[:, None]
    return np.max(np.abs(c * p[:, 0] - s * p[:, 1]), axis=1), np.max(np.abs(s * p[:, 0] + c * p[:, 1]), axis=1)


#: the search margin [m] of each later pose of a track beyond the distance from the one before
#: (``ReferencePath.project_track``)
_TRACK_MARGIN_M = 2.0


def _tracks(
    path,
    obstacles,
    t_s: float,
    taus: np.ndarray,
    s_m: float,
    range_m: float,
    compiled: tuple[ObstacleTable, PathArrays] | None = None,
):
    """The obstacles within range (judged where first present), one row each: arrays (n, K) of
    s, e, half length, half width (NaN where absent) and presence over ``taus`` (K,).
    ``compiled``: (ObstacleTable of ``obstacles``, PathArrays of ``path``) to compute them in
    compiled code."""
    if compiled is not None:
        return _tracks_compiled(compiled[0], compiled[1], t_s, taus, s_m, range_m)
    out: list[tuple] = []
    t = t_s + taus
    for ob in obstacles:
        present = np.asarray(ob.present(t), bool)
        if not present.any():
            continue
        ks = np.flatnonzero(present)
        poses = ob.poses_at(t[ks])
        # the first pose searched within range of the car, each later one near the one before
        s_p, e_p = path.project_track(poses[:, :2], s_m, range_m, _TRACK_MARGIN_M)
        if abs(s_p[0] - s_m) > range_m:
            continue  # out of range now
        S, E, HL, HW = (np.full(len(taus), np.nan) for _ in range(4))
        S[ks], E[ks] = s_p, e_p
        HL[ks], HW[ks] = _extent(ob, poses[:, 2] - np.asarray(path.heading(s_p), float))
        out.append((S, E, HL, HW, present))
    if not out:
        return (*(np.zeros((0, len(taus))) for _ in range(4)), np.zeros((0, len(taus)), bool))
    return tuple(np.array(a) for a in zip(*out))


def _tracks_compiled(tab: ObstacleTable, pa: PathArrays, t_s: float, taus: np.ndarray, s_m: float, range_m: float):
    """:func:`_tracks` of the obstacles ``tab`` describes on the path ``pa`` describes, compiled."""
    n, K = len(tab.obstacles), len(taus)
    if n == 0:
        return (*(np.zeros((0, K)) for _ in range(4)), np.zeros((0, K), bool))
    tr = np.empty((n, 4, K))
    present = np.empty((n, K), np.bool_)
    keep = np.empty(n, np.bool_)
    _tracks_kernel(
        pa.kind, pa.geo, pa.tab_s, pa.tab_xy, pa.tab_h, pa.tab_k, float(t_s), np.ascontiguousarray(taus, dtype=float),
        float(s_m), float(range_m), _TRACK_MARGIN_M, *tab.motion, tab.life, tab.has_life, tab.shape, tab.radius,
        tab.verts, tab.nverts, tr, present, keep,
    )  # fmt: skip
    tr, present = tr[keep], present[keep]
    return tr[:, 0], tr[:, 1], tr[:, 2], tr[:, 3], present


@njit(cache=True)
def _tracks_kernel(
    kind, geo, tab_s, tab_xy, tab_h, tab_k, t_s, taus, s_m, range_m, margin_m, pose, vel, tr_lo, tr_hi, tr_t, tr_d,
    life, has_life, shape, radius, verts, nverts, tr, present, keep,
):  # fmt: skip
    """:func:`_tracks` of every obstacle of an ``ObstacleTable``: ``tr`` (n, 4, K) (s, e, half
    length, half width; NaN where absent), ``present`` (n, K) and ``keep`` (n,) (present at
    some time and within range)."""
    K = taus.shape[0]
    for j in range(pose.shape[0]):
        keep[j] = False
        guess, window, px, py, first = s_m, range_m, 0.0, 0.0, True
        for k in range(K):
            t = t_s + taus[k]
            ok = not has_life[j] or (life[j, 0] <= t and t <= life[j, 1])
            present[j, k] = ok
            for f in range(4):
                tr[j, f, k] = math.nan
            if not ok:
                continue
            x, y, yaw = pose_at(j, t, pose, vel, tr_lo, tr_hi, tr_t, tr_d)
            if not first:
                window = math.hypot(x - px, y - py) + margin_m
            s, e = path_project(kind, geo, tab_s, tab_xy, guess, window, x, y)
            if first:
                if abs(s - s_m) > range_m:
                    break  # out of range now
                keep[j] = True
                first = False
            guess, px, py = s, x, y
            tr[j, 0, k] = s
            tr[j, 1, k] = e
            if shape[j] == SHAPE_CIRCLE:
                tr[j, 2, k] = radius[j]
                tr[j, 3, k] = radius[j]
                continue
            d = yaw - path_eval(kind, geo, tab_s, tab_xy, tab_h, tab_k, s)[2]
            c, sn = math.cos(d), math.sin(d)
            hl, hw = 0.0, 0.0
            for m in range(nverts[j]):
                vx, vy = verts[j, m, 0], verts[j, m, 1]
                hl = max(hl, abs(c * vx - sn * vy))
                hw = max(hw, abs(sn * vx + c * vy))
            tr[j, 2, k] = hl
            tr[j, 3, k] = hw


def decide_lane(
    road: Road,
    path,
    s_m: float,
    e_y_m: float,
    speed_mps: float,
    obstacles,
    t_s: float,
    previous: LaneDecision | None = None,
    config: LaneConfig = LaneConfig(),
    desired_speed_mps: float | None = None,
    return_by_s: float | None = None,
    *,
    compiled: tuple[ObstacleTable, PathArrays] | None = None,
) -> LaneDecision:
    """Decide the lane for the ego at arc length ``s_m`` [m], lateral offset ``e_y_m`` [m] and
    speed ``speed_mps`` [m/s] on ``path`` (the road's reference path: ``project``, ``heading``)
    at time ``t_s`` [s], given ``obstacles`` (:class:`~mpcdrive.scene.obstacles.Obstacle`, their
    poses on the same clock) and the ``previous`` decision (None at the start): see the module.
    ``desired_speed_mps`` [m/s], when given, replaces the config's (e.g. the MPC's reference
    speed here: a car stopped behind an obstacle still looks as far ahead as it wants to drive).
    ``return_by_s`` [s]: the ego must be back in the route lane by then (a goal on it): from the
    route lane no change starts whose way out and back (two ramps at the current speed) ends later.
    ``compiled``: the obstacles' ``ObstacleTable`` and the path's ``PathArrays``, to track the
    obstacles along the path in compiled code (the same numbers as without)."""
    if not road.lanes:
        raise ValueError("the road has no lanes")
    cfg, n = config, len(road.lanes)
    v = max(float(speed_mps), 0.0)
    want = desired_speed_mps if desired_speed_mps is not None else cfg.desired_speed_mps
    v_des = max(v, want if want is not None and math.isfinite(want) else v)
    taus = np.arange(0.0, cfg.horizon_s + 1e-9, cfg.dt_s)
    # the ego's predicted arc length: current speed, accelerating to the desired speed
    t_acc = (v_des - v) / cfg.accel_mps2
    tt = np.minimum(taus, t_acc)
    s_ego = s_m + v * tt + 0.5 * cfg.accel_mps2 * tt**2 + v_des * (taus - tt)
    s_keep = s_m + v * taus  # during a change: at its current speed
    half_l = 0.5 * cfg.ego_length_m
    need = cfg.standstill_m + cfg.time_gap_s * v_des
    look = v_des * cfg.horizon_s + need
    cur = lane_of(road, s_m, e_y_m)
    edges = [(np.interp(s_m, road.s_m, ln.right_m), np.interp(s_m, road.s_m, ln.left_m)) for ln in road.lanes]
    centres = [float(np.interp(s_m, road.s_m, lane_line(road, i))) for i in range(n)]

    def change_s(lane: int) -> float:
        """Duration [s] of the ramp to ``lane``: peak lateral acceleration and jerk within bounds."""
        d = abs(centres[lane] - e_y_m)
        return max(
            math.sqrt(_PEAK_ACC * d / cfg.max_lat_accel_mps2),
            (_PEAK_JERK * d / cfg.max_lat_jerk_mps3) ** (1.0 / 3.0),
            cfg.min_change_s,
        )

    during = [taus <= change_s(i) + 1e-9 for i in range(n)]
    enter_gap = cfg.standstill_m + cfg.rear_time_gap_s * v
    free_m = np.full(n, look)
    enter_ok = np.ones(n, bool)

    def ramp_m(lane: int) -> float:
        """Length [m] of the ramp to ``lane``: its duration at the current speed, no steeper than
        ``max_slope`` and at least ``turn_out_m``."""
        d = abs(centres[lane] - e_y_m)
        return max(max(v, 1.0) * change_s(lane), _PEAK_SLOPE * d / cfg.max_slope, cfg.turn_out_m)

    gap_now = math.inf  # nearest obstacle ahead in the ego's lane now, bumper to bumper
    blockers: list[list] = [[] for _ in range(n)]  # per lane, the tracks of the obstacles ahead in it
    # the obstacles' tracks, one row each (n_obs, K): judged ahead or behind where first present
    S, E, HL, HW, present = _tracks(path, obstacles, t_s, taus, s_m, cfg.range_m, compiled)
    if len(S):  # (no obstacle in range: every lane free over the whole look-ahead)
        rows = np.arange(len(S))
        k0 = np.argmax(present, axis=1)
        ahead = S[rows, k0] >= s_ego[k0]
        gap_ahead = S - s_ego - HL - half_l
        gap_enter = S - s_keep - HL - half_l
        gap_behind = s_keep - S - HL - half_l
        if len(taus) > 1:  # the speed along the path of a follower present all along, else the ego's
            v_follow = np.gradient(S, taus, axis=1)
            v_follow[~np.isfinite(S).all(axis=1)] = v
        else:
            v_follow = np.full(S.shape, v)
        # a follower keeps its time gap; one standing still (a parked car passed) only needs the
        # body's clearance
        vf = np.maximum(v_follow, 0.0)
        gap_follow = np.minimum(cfg.standstill_m, BEHIND_CLEARANCE_M + vf) + cfg.rear_time_gap_s * vf
        with np.errstate(invalid="ignore"):  # NaN where an obstacle is absent: never in the lane
            for i, (lo, hi) in enumerate(edges):
                inlane = present & (np.minimum(E + HW, hi) - np.maximum(E - HW, lo) > 0.1)
                there = inlane.any(axis=1)
                front = np.flatnonzero(there & ahead)
                if len(front):
                    il = inlane[front]
                    free_m[i] = min(free_m[i], float(np.where(il, gap_ahead[front], np.inf).min()))
                    blockers[i].extend((S[r], E[r], HL[r], HW[r], inlane[r]) for r in front)
                    if np.any((gap_enter[front] < enter_gap) & il & during[i]):
                        enter_ok[i] = False
                    if i == cur and il[:, 0].any():
                        gap_now = min(gap_now, float(gap_ahead[front][il[:, 0], 0].min()))
                if i != cur:  # behind, in a neighbour lane: the follower must keep its gap
                    back = there & ~ahead
                    if np.any((gap_behind < gap_follow)[back] & inlane[back] & during[i]):
                        enter_ok[i] = False
    blocked = free_m < need
    free = np.where(np.arange(n) == cur, ~blocked, enter_ok)
    # a neighbour narrower than the ego here (a lane that has ended or not begun) is not free
    free &= (np.array([hi - lo for lo, hi in edges]) >= cfg.ego_width_m) | (np.arange(n) == cur)
    order = np.argsort([0.5 * (lo + hi) for lo, hi in edges])  # right to left
    pos = int(np.flatnonzero(order == cur)[0])
    neighbours = [int(order[j]) for j in (pos - 1, pos + 1) if 0 <= j < n]

    def ramp_to(lane: int) -> LateralRamp:
        return LateralRamp(s_m, s_m + ramp_m(lane), e_y_m, road.s_m, lane_line(road, lane))

    def clears(lane: int, ramp: LateralRamp, origin: int, speed: float) -> bool:
        """Whether ``ramp`` (to ``lane``), driven at ``speed`` [m/s], keeps the body
        ``pass_margin_m`` beside every obstacle ahead in lane ``origin`` while passing it (on a
        0.05 s grid: a fast pass is not stepped over)."""
        if not blockers[origin]:
            return True
        side = 1.0 if centres[lane] > e_y_m else -1.0
        tf = np.arange(0.0, cfg.horizon_s + 1e-9, 0.05)
        s_f = s_m + speed * tf
        off = side * ramp.offset(s_f)
        for S, E, HL, HW, inlane in blockers[origin]:
            k = np.flatnonzero(inlane)
            if len(k) > 1:
                Sf, Ef, HLf, HWf = (np.interp(tf, taus[k], a[k], left=np.nan, right=np.nan) for a in (S, E, HL, HW))
            else:  # one sample: held over its time step
                Sf, Ef, HLf, HWf = (
                    np.where(np.abs(tf - taus[k[0]]) <= 0.5 * cfg.dt_s, a[k[0]], np.nan) for a in (S, E, HL, HW)
                )
            beside = (s_f + half_l > Sf - HLf) & (s_f - half_l < Sf + HLf)
            if np.any(off[beside] < (side * Ef + HWf)[beside] + 0.5 * cfg.ego_width_m + cfg.pass_margin_m):
                return False
        return True

    def turn_out_cap(lane: int, ramp: LateralRamp, origin: int) -> float | None:
        """The speed cap of a change to ``lane`` along ``ramp`` from lane ``origin``: ``turn_out_mps``
        while the ramp, driven at the current speed (at least that cap: a car starting from
        standstill is judged as it will drive), does not clear the obstacles ahead in the origin
        lane."""
        return None if clears(lane, ramp, origin, max(v, cfg.turn_out_mps)) else cfg.turn_out_mps

    def result(
        lane: int, action, ramp=None, stop_m=None, called_back: bool = False, origin: int = -1, cap=None
    ) -> LaneDecision:
        changed = previous is None or lane != previous.lane
        # when the target last changed: a first decision to keep the lane the ego is in is no change
        if previous is None:
            since = t_s if lane != cur else -math.inf
        else:
            since = t_s if lane != previous.lane else previous.since_s
        if ramp is None:
            ramp = ramp_to(lane) if changed else previous.ramp  # type: ignore[union-attr]
        # the body may use the current and the target lane, and every lane it overlaps now (a
        # change called back with the body across the line keeps the lane it is leaving)
        hw = 0.5 * cfg.ego_width_m
        band = {cur, lane} | {i for i, (lo_i, hi_i) in enumerate(edges) if e_y_m - hw < hi_i and e_y_m + hw > lo_i}
        lo = min(edges[i][0] for i in band)
        hi = max(edges[i][1] for i in band)
        return LaneDecision(
            lane,
            cur,
            action,
            tuple(float(f) for f in free_m),
            tuple(bool(f) for f in free),
            ramp,
            tuple(sorted(band)),
            (float(lo), float(hi)),
            stop_m,
            since,
            gap_now,
            called_back,
            origin,
            cap,
        )

    def home_lane() -> int:
        """The neighbour of the ego's lane towards the route lane (the ego out of it)."""
        return int(order[pos + (1 if int(np.flatnonzero(order == road.route_lane)[0]) > pos else -1)])

    def pass_over() -> bool:
        """Out of the route lane with the lane home free and clear over the whole look-ahead."""
        if cur == road.route_lane:
            return False
        home = home_lane()
        return bool(free[home]) and free_m[home] >= look - 1e-6

    if previous is not None and previous.action == "change":
        tgt = previous.lane
        c_t = centres[tgt]
        # held until the ego arrives, or is in its target lane with the pass over (no need to
        # settle on the lane's centre before heading home)
        if not (cur == tgt and (abs(e_y_m - c_t) < cfg.arrive_m or pass_over())):
            if not free[tgt] and cur != tgt and not previous.called_back:
                # the target closed before the ego got there: back (and that return is not called
                # back in turn when the body's centre swings over the line: no flip-flop)
                return result(cur, "change", called_back=True)
            cap = None
            if previous.speed_cap_mps is not None:  # a turn-out: slow until past the obstacle
                cap = turn_out_cap(tgt, previous.ramp, previous.origin)
            return result(tgt, "change", called_back=previous.called_back, origin=previous.origin, cap=cap)
    dwell_ok = previous is None or t_s - previous.since_s >= cfg.min_dwell_s - 1e-9
    if cur != road.route_lane:
        home = home_lane()
        # back early (min_return_s) once the lane home is clear over the whole look-ahead: a pass is over
        early = pass_over() and (previous is None or t_s - previous.since_s >= cfg.min_return_s - 1e-9)
        if (dwell_ok or early) and free[home] and free_m[home] >= min(free_m[cur], need + cfg.min_gain_m):
            return result(home, "change")
    if blocked[cur]:
        options = [j for j in neighbours if free[j]]
        if return_by_s is not None and cur == road.route_lane:  # out and back in time
            options = [j for j in options if t_s + 2.0 * ramp_m(j) / max(v, cfg.creep_mps) <= return_by_s]
        if not options:
            stop_m = max(gap_now - cfg.standstill_m, 0.0) if math.isfinite(gap_now) else float(free_m[cur])
            return result(cur, "stop", stop_m=stop_m)
        best = max(options, key=lambda j: free_m[j])
        if dwell_ok and free_m[best] >= free_m[cur] + cfg.min_gain_m:
            ramp = ramp_to(best)
            return result(best, "change", ramp=ramp, origin=cur, cap=turn_out_cap(best, ramp, cur))
    return result(cur, "keep")


class LaneChoosingMpc:
    """An MPC (:class:`~mpcdrive.control.mpc.LtvMpc` or the compiled one, built with
    ``MpcProblem(road=...)``) driving a road with lanes: before each step :func:`decide_lane`
    picks the lane, and the MPC's road becomes the lanes the decision lets the body use (the
    current lane alone when keeping it; the current and the target lane during a change or a
    pass: :meth:`Road.band`) and its lateral reference the decision's ramp to the target lane's
    line (the path itself once the car is home in the route lane). Everything else is the
    MPC's (attributes, warm start). ``return_by_s``: as for :func:`decide_lane`.

    ``road`` is the full road with its lanes (``road.lanes``, ``route_lane``), on the knots of the
    MPC's road. ``decision`` is the last :class:`LaneDecision`. ``scene`` is the MPC's scene
    with this full road: the world a drive is judged in, whichever band the MPC keeps to."""

    def __init__(self, mpc, road: Road, config: LaneConfig | None = None, return_by_s: float | None = None):
        if not road.lanes:
            raise ValueError("LaneChoosingMpc needs a road with lanes")
        if getattr(mpc, "road", None) is None:
            raise ValueError("LaneChoosingMpc needs an MPC built with a road (MpcProblem(road=...))")
        self.mpc = mpc
        self.road = road
        own = getattr(mpc, "scene", None)
        #: the world: the MPC's obstacles and body on the full road
        self.scene = (
            Scene(road, tuple(mpc.obstacles), mpc.footprint) if own is None else dataclasses.replace(own, road=road)
        )
        fp = mpc.footprint
        self.config = config or LaneConfig(ego_length_m=fp.length_m, ego_width_m=fp.width_m)
        self.return_by_s = return_by_s
        self.decision: LaneDecision | None = None
        self._band: tuple[int, ...] | None = None
        self._ramp: LateralRamp | None = None
        self._held_gap: float | None = None
        self._cap: float | None = None
        self._table: ObstacleTable | None = None  # the obstacles' compiled description
        #: the path's compiled form (None: a path type without one; the tracks are then numpy)
        self._path_arrays = path_arrays(mpc.path)
        road.bounds(0.0, 0.0, 0.0, fp)  # load the road's kernel now: each band change uses it
        if self._path_arrays is not None:  # and the lane tracks' kernel (on one obstacle at least)
            tab = table_of(list(mpc.obstacles) or [Obstacle(Circle(1.0), (0.0, 0.0, 0.0))], None)
            if tab.all_simple:
                taus = np.arange(0.0, self.config.horizon_s + 1e-9, self.config.dt_s)
                _tracks_compiled(tab, self._path_arrays, 0.0, taus, 0.0, self.config.range_m)
        names = list(mpc.model.input_names)
        #: the controller's full braking [m/s^2] (0: a model without an acceleration input)
        self._decel_mps2 = max(-float(mpc.problem.u_min[names.index("accel")]), 0.0) if "accel" in names else 0.0

    def __getattr__(self, name):  # the MPC's attributes (problem, N, nx, path, obstacles ...)
        if name == "mpc":
            raise AttributeError(name)
        return getattr(self.mpc, name)

    def step(self, x, warm):
        t0 = time.perf_counter()
        mpc = self.mpc
        x = np.asarray(x, float)
        if np.all(np.isfinite(x[:3])):
            s_m, e_y = mpc.path.project(x[:2], warm.s_m, mpc.config.projection_window_m)
            v = float(mpc.model.speed(x))
            compiled = None
            if self._path_arrays is not None:
                self._table = table_of(mpc.obstacles, self._table)
                if self._table.all_simple:
                    compiled = (self._table, self._path_arrays)
            self.decision = decide_lane(
                self.road,
                mpc.path,
                s_m,
                e_y,
                v,
                mpc.obstacles,
                warm.t_s,
                self.decision,
                self.config,
                self._desired_speed(s_m),
                self.return_by_s,
                compiled=compiled,
            )
            band = self.decision.band
            if band != self._band:
                mpc.set_road(self.road.band(band))
                self._band = band
            # the lateral reference: the decision's ramp to its lane's line, or the path itself
            # once the car is home in the route lane
            d = self.decision
            home = d.lane == self.road.route_lane and d.action != "change" and s_m >= d.ramp.s1_m
            ramp = None if home else d.ramp
            av = getattr(mpc, "avoidance", None)
            if av is not None:
                av.stop_gap_m = self._stop_gap(d, v)
            if ramp is not self._ramp:
                mpc.set_lateral_reference(None if ramp is None else ramp.offset)
                self._ramp = ramp
            if d.speed_cap_mps != self._cap:  # a turn-out: slowly past the obstacle, braking hard to it
                mpc.set_speed_cap(d.speed_cap_mps, self._decel_mps2 or None)
                self._cap = d.speed_cap_mps
        # the step's time is the whole step's: the lane decision too
        return dataclasses.replace(mpc.step(x, warm), solve_time_s=time.perf_counter() - t0)

    def _stop_gap(self, d: LaneDecision, v: float) -> float:
        """Extra room [m] the MPC's stop row keeps before the obstacle while the car is held in a
        blocked lane: ``turn_out_m``, so that it can turn out of the lane later, or what braking
        at the controller's full deceleration still leaves (a stop row it cannot keep would
        have the car yaw its front disc back instead). It never grows while the car is held: the
        stop line does not retreat before a car already braking for it."""
        held = d.action == "stop" or (d.action == "keep" and not d.free[d.current])
        if not held or not math.isfinite(d.gap_m):
            self._held_gap = None
            return 0.0
        decel = self._decel_mps2
        braking = v * v / (2.0 * decel) if decel > 0 else 0.0
        room = min(self.config.turn_out_m, max(d.gap_m - braking - _STOP_SLACK_M, 0.0))
        if self._held_gap is not None:
            # a car (nearly) stopped keeps its line: moving it up with the car would let it creep on
            room = self._held_gap if v < self.config.creep_mps else min(room, self._held_gap)
        self._held_gap = room
        return room

    def _desired_speed(self, s_m: float) -> float | None:
        """The MPC's reference speed at ``s_m`` [m] (its speed profile's, else its constant one),
        unless the lane config names a desired speed."""
        if self.config.desired_speed_mps is not None:
            return None
        prof = getattr(self.mpc.config, "speed_profile", None)
        return float(prof.speed(s_m)) if prof is not None else float(self.mpc.v_ref_mps)


def _refresh_cache() -> None:
    """numba keys this module's cache to this file only: the lane tracks link in code from these."""
    from .. import _jitcache
    from ..ocp import avoidance_compiled as _ac
    from ..paths import compiled as _paths_compiled, profile_compiled as _profile_compiled

    files = [m.__file__ for m in (_ac, _paths_compiled, _profile_compiled) if m.__file__ is not None]
    _jitcache.refresh(_tracks_kernel, files)


_refresh_cache()
