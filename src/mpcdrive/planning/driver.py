"""The controller drives the planner's maneuver.

:class:`PlannedMpc` wraps an MPC built with a road (:class:`~mpcdrive.control.mpc.LtvMpc`,
either backend). Every replanning (every control step by default, at most ``replan_s`` apart)
:class:`~.planner.ManeuverPlanner` chooses a maneuver; the MPC then gets

* its **references**: the maneuver's arc lengths and speeds at the horizon's steps
  (``set_longitudinal_plan``) and its lateral move as the lateral reference
  (``set_lateral_reference``);
* its **road**: the lanes the maneuver's body uses over the MPC's horizon and those the body
  overlaps now (``set_road`` with :meth:`~mpcdrive.scene.road.Road.band`); the body-in-road rows
  keep the car inside them;
* its **obstacle rows**, the safety net, built by the MPC as before: the hard half-planes keep
  the footprint clear of every obstacle whatever the references say.

Between replannings the maneuver is followed from where the car is on it. The goal, once
reached, is dropped: the car drives on along its lane.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
import math
import time

import numpy as np
from numba import njit

from ..control.base import projection_guess
from ..ocp.avoidance_compiled import ObstacleTable, table_of
from ..scene.road import Road
from ..scene.world import Scene
from ..units import wrap_angle
from .config import PlannerConfig, VehicleLimits
from .planner import Maneuver, ManeuverPlanner, PlanningGoal

__all__ = ["PlannedMpc", "vehicle_limits"]

#: a car within this distance [m] of the line its maneuver keeps to tracks the line itself (the
#: controller corrects a tracking error that size; a maneuver from where the car is would carry it)
KEEP_LINE_M = 0.5


def vehicle_limits(mpc) -> VehicleLimits:
    """The :class:`VehicleLimits` of an MPC: its footprint, its model's wheelbase (and where its
    rear axle is behind the centre of gravity), its input, rate and speed bounds, its friction
    circle and the margin its obstacle rows keep."""
    pb = mpc.problem
    fp = mpc.footprint
    names = list(mpc.model.input_names)
    params = getattr(mpc.model, "params", None)
    wheelbase = float(getattr(params, "wheelbase_m", 0.0) or 0.0)
    if wheelbase <= 0.0:
        raise ValueError("the maneuver planner needs a model with a wheelbase (kinematic or dynamic bicycle)")
    if "accel" not in names:
        raise ValueError("the maneuver planner needs a model with an acceleration input (kinematic4, dynamic)")
    ia = names.index("accel")
    speed_index = list(mpc.model.state_names).index("v") if "v" in mpc.model.state_names else 3
    v_max = float(pb.x_max[speed_index]) if pb.x_max is not None else math.inf
    if not math.isfinite(v_max):
        v_max = 70.0  # no bound: the planner samples up to 250 km/h
    rate = float(pb.du_max_per_s[0])
    av = getattr(mpc, "avoidance", None)  # its obstacle rows, and the margin they keep
    return VehicleLimits(
        length_m=fp.length_m,
        width_m=fp.width_m,
        wheelbase_m=wheelbase,
        max_steer_rad=float(pb.u_max[0]),
        max_steer_rate_rad_s=rate if math.isfinite(rate) else 10.0,
        max_accel_mps2=float(pb.u_max[ia]) if math.isfinite(pb.u_max[ia]) else 10.0,
        max_decel_mps2=-float(pb.u_min[ia]) if math.isfinite(pb.u_min[ia]) else 10.0,
        max_speed_mps=v_max,
        friction_mps2=float(pb.friction_accel_mps2) if pb.friction_accel_mps2 else math.inf,
        center_offset_m=fp.center_offset_m,
        disc_offsets_m=tuple(float(o) for o in fp.disc_offsets_m),
        disc_radius_m=fp.disc_radius_m,
        disc_margin_m=float(av.config.margin_m) if av is not None else 0.0,
        rear_axle_m=float(getattr(params, "lr_m", 0.0) or 0.0),
    )


@njit(cache=True)
def lanes_overlapped(knots, left, right, corners, s_m, e_y_m, e_psi_rad, hit):
    """Write into ``hit`` (L,) whether the body overlaps each lane: its ``corners`` (n, 2) [m,
    body frame] at arc length ``s_m``, offset ``e_y_m`` [m] and heading ``e_psi_rad`` to the path
    (a body turned across the path reaches further to its sides than its half width), against
    the lanes' edges ``left`` / ``right`` (L, K) [m] on the road's ``knots`` (K,) [m], read at
    the corners' arc lengths (constant beyond the ends): the body's offsets span into the lane's
    (its left edge the largest, its right edge the smallest at those arc lengths)."""
    c, sn = math.cos(e_psi_rad), math.sin(e_psi_rad)
    K = knots.shape[0]
    d_lo, d_hi = math.inf, -math.inf
    for q in range(corners.shape[0]):
        d = e_y_m + sn * corners[q, 0] + c * corners[q, 1]
        d_lo, d_hi = min(d_lo, d), max(d_hi, d)
    for j in range(left.shape[0]):
        lft, rgt = -math.inf, math.inf
        for q in range(corners.shape[0]):
            s = min(max(s_m + c * corners[q, 0] - sn * corners[q, 1], knots[0]), knots[K - 1])
            i = min(max(np.searchsorted(knots, s, side="right") - 1, 0), max(K - 2, 0))
            k = min(i + 1, K - 1)
            w = (s - knots[i]) / (knots[k] - knots[i]) if k > i else 0.0
            lft = max(lft, left[j, i] * (1.0 - w) + left[j, k] * w)
            rgt = min(rgt, right[j, i] * (1.0 - w) + right[j, k] * w)
        hit[j] = d_lo < lft and d_hi > rgt


class PlannedMpc:
    """An MPC driving the maneuvers of a :class:`ManeuverPlanner` on ``road`` (its lanes, on the
    knots of the MPC's road). ``config``: the planner's settings; ``goal``: a
    :class:`PlanningGoal`; ``replan_s``: the longest time [s] between two replannings (0: every
    step). ``maneuver`` is the last maneuver, ``scene`` the MPC's scene with the full road (the
    world a drive is judged in, whichever lanes the MPC keeps to); ``plans`` counts replannings
    and ``plan_time_s`` sums their wall time."""

    def __init__(
        self,
        mpc,
        road: Road,
        config: PlannerConfig | None = None,
        goal: PlanningGoal | None = None,
        replan_s: float = 0.0,
    ):
        if getattr(mpc, "road", None) is None:
            raise ValueError("PlannedMpc needs an MPC built with a road (MpcProblem(road=...))")
        if not (math.isfinite(replan_s) and 0.0 <= replan_s <= 0.5):
            raise ValueError(f"replan_s must be between 0 and 0.5 s, got {replan_s!r}")
        self.mpc = mpc
        self.road = road
        own = getattr(mpc, "scene", None)
        #: the world: the MPC's obstacles and body on the full road
        self.scene = (
            Scene(road, tuple(mpc.obstacles), mpc.footprint) if own is None else dataclasses.replace(own, road=road)
        )
        cfg = config or PlannerConfig()
        prof = getattr(mpc.config, "speed_profile", None)
        wanted = prof.speed if prof is not None else float(mpc.v_ref_mps)
        self.planner = ManeuverPlanner(
            mpc.path,
            road,
            vehicle_limits(mpc),
            cfg,
            wanted_speed=wanted,
            goal=goal,
            band_steps=int(math.ceil(mpc.N * mpc.dt_s / cfg.dt_s)),
            cache_step_s=float(mpc.dt_s),
            bend=getattr(prof, "bend", None),
        )
        self.config = cfg
        self.goal = goal
        self.goal_reached_s: float | None = None
        self.replan_s = float(replan_s)
        self.maneuver: Maneuver | None = None
        self._planned_at = -math.inf
        self._band: tuple[int, ...] | None = None
        # the obstacles' table now, not in the first control step (a step rebuilds it only when
        # the MPC is handed other obstacles)
        self._table: ObstacleTable | None = table_of(mpc.obstacles, None)
        self._lateral = None
        self._line_key: tuple | None = None
        self._leaves_of: Maneuver | None = None  # the maneuver _leaves was found for
        self._leaves = False
        self._line_ref: Callable[[np.ndarray], np.ndarray] | None = None
        names = list(mpc.model.input_names)
        self._accel = names.index("accel")
        self._wheelbase = self.planner.limits.wheelbase_m
        self.plans = 0
        self.plan_time_s = 0.0
        #: one row per replanning: (t [s], kind, target, lane, offset [m], safe, ttc [s], pairs
        #: checked, pairs sampled, wall time [s])
        self.log: list[tuple] = []
        self._t_mpc = mpc.dt_s * np.arange(mpc.N + 1)
        # the body's corners and every lane's edges on the road's knots (rows), for _lanes_now
        self._corners = mpc.footprint.corners()
        edges = np.zeros((2, len(road.lanes), len(road.s_m)))
        for i, ln in enumerate(road.lanes):
            edges[0, i], edges[1, i] = ln.left_m, ln.right_m
        self._lane_left, self._lane_right = edges[0], edges[1]
        self._overlaps = np.zeros(len(road.lanes), np.bool_)  # lanes_overlapped's output, in place
        road.bounds(0.0, 0.0, 0.0, mpc.footprint)  # load the road's kernel now: each band change uses it

    def planner_stats(self) -> dict:
        """The replannings of the run so far (``metrics.json["planner"]``): their number, how
        many had no safe maneuver, the pairs each sampled and checked (median, largest) and its
        wall time [us] (median, p99, largest)."""
        if not self.log:
            return {"replannings": 0, "unsafe": 0, "sampled": None, "checked": None, "plan_time_us": None}
        sampled = np.array([r[8] for r in self.log], float)
        checked = np.array([r[7] for r in self.log], float)
        us = 1e6 * np.array([r[9] for r in self.log], float)
        return {
            "replannings": len(self.log),
            "unsafe": sum(1 for r in self.log if not r[5]),
            "sampled": {"p50": float(np.median(sampled)), "max": int(sampled.max())},
            "checked": {"p50": float(np.median(checked)), "max": int(checked.max())},
            "plan_time_us": {
                "p50": float(np.percentile(us, 50)),
                "p99": float(np.percentile(us, 99)),
                "max": float(us.max()),
            },
        }

    def __getattr__(self, name):  # the MPC's attributes (problem, N, nx, path, obstacles ...)
        if name == "mpc":
            raise AttributeError(name)
        return getattr(self.mpc, name)

    def _lane_line(self, m: Maneuver, s_m: float, e_y_m: float):
        """The lateral reference of maneuver ``m`` for the car at (``s_m``, ``e_y_m``) [m]: None
        (the path) when it keeps to the route lane's line, the line plus offset of its lane when
        it keeps to that one (the car within ``KEEP_LINE_M`` of it just ahead, and the move never
        farther from the line than the body is wide up to the maneuver's end), else its lateral
        move. (A pass leaves the line it ends on by a lane: judged only just ahead, where its
        move has barely begun, the pass was handed to the controller as the route's line and the
        car stayed in its lane. Smaller moves, as between the lines of lanelets side by side in a
        junction, stay the line's: the controller corrects them itself.)"""
        lat = m.lateral
        target = float(lat(s_m + 1.0))  # just ahead: a move under way is not yet on its line
        on_line = abs(float(np.interp(s_m, lat.knots_m, lat.line_m)) + lat.offset_m - e_y_m) <= KEEP_LINE_M
        if (
            not on_line
            or abs(target - (float(np.interp(s_m + 1.0, lat.knots_m, lat.line_m)) + lat.offset_m)) > KEEP_LINE_M
        ):
            return lat
        if self._leaves_of is not m:  # the maneuver's own samples, once per replanning
            dev = m.d_m - (np.interp(m.s_m, lat.knots_m, lat.line_m) + lat.offset_m)
            self._leaves = float(np.max(np.abs(dev))) > self.mpc.footprint.width_m
            self._leaves_of = m
        if self._leaves:
            return lat
        if m.lane == self.road.route_lane and lat.offset_m == 0.0 and self.road.lanes:
            return None
        key = (m.lane, lat.offset_m)
        if self._line_key != key:
            knots, line, off = lat.knots_m, lat.line_m, lat.offset_m
            self._line_ref = lambda s: np.interp(s, knots, line) + off
            self._line_key = key
        return self._line_ref

    def _lanes_now(self, s_m: float, e_y_m: float, e_psi_rad: float) -> set[int]:
        """The lanes the body overlaps at (s, e_y) [m] and heading ``e_psi_rad`` to the path
        (:func:`lanes_overlapped`)."""
        hit = self._overlaps
        lanes_overlapped(self.road.s_m, self._lane_left, self._lane_right, self._corners, s_m, e_y_m, e_psi_rad, hit)
        return set(np.flatnonzero(hit).tolist())

    def step(self, x, warm):
        t0 = time.perf_counter()
        mpc = self.mpc
        x = np.asarray(x, float)
        if np.all(np.isfinite(x[:4])):
            t_s = float(warm.t_s)
            s_m, e_y = mpc.path.project(x[:2], projection_guess(warm), mpc.config.projection_window_m)
            s_m, e_y = float(s_m), float(e_y)
            v = float(mpc.model.speed(x))
            e_psi = wrap_angle(float(x[2]) - float(mpc.path.heading(s_m)))
            if self.goal is not None and self.goal_reached_s is None:
                if self.goal.reached(t_s, s_m, e_y, v, float(x[2])):
                    self.goal_reached_s = t_s
                    self.planner.set_goal(None)  # reached: drive on along the lane
            due = self.maneuver is None or t_s - self._planned_at >= self.replan_s - 1e-9
            if due:
                self._table = table_of(mpc.obstacles, self._table)
                u = warm.u_prev
                a0 = float(u[self._accel]) if u is not None else 0.0
                kappa = math.tan(float(u[0])) / self._wheelbase if u is not None else 0.0
                self.maneuver = self.planner.plan(t_s, s_m, e_y, v, math.tan(e_psi), a0, self._table, kappa)
                self._planned_at = t_s
                self.plans += 1
                m = self.maneuver
                self.plan_time_s += m.plan_time_s
                self.log.append(
                    (t_s, m.kind, m.target, m.lane, m.offset_m, m.safe, m.ttc_s, m.checked, m.candidates, m.plan_time_s)
                )
            m = self.maneuver
            assert m is not None
            # the maneuver from where the car is on it (between replannings, later on it)
            tau = t_s - self._planned_at + self._t_mpc
            s_ref = np.interp(tau, m.t_s, m.s_m)
            v_ref = np.interp(tau, m.t_s, m.v_mps)
            past = tau > m.t_s[-1]  # beyond the maneuver: on at its last speed
            if np.any(past):
                s_ref[past] = m.s_m[-1] + m.v_mps[-1] * (tau[past] - m.t_s[-1])
            s_ref = np.maximum.accumulate(s_ref - s_ref[0] + s_m)
            mpc.set_longitudinal_plan(s_ref, np.maximum(v_ref, 0.0))
            # the lateral reference: a maneuver that keeps the car on its lane's line (plus its
            # offset) gives the controller that line, so that it corrects the car's tracking error
            # itself; a move to another line gives the move
            line = self._lane_line(m, s_m, e_y)
            if line is not self._lateral:
                mpc.set_lateral_reference(line)
                self._lateral = line
            if getattr(mpc, "avoidance", None) is not None:
                # the obstacle rows keep the maneuver's side of each obstacle it checked
                idx = np.clip(np.rint(tau[1:] / self.config.dt_s).astype(np.int64), 0, len(m.t_s) - 1)
                mpc.set_obstacle_relations(dict(zip(m.obstacle_index.tolist(), m.relations[:, idx])))
            band = tuple(sorted(set(m.lanes) | self._lanes_now(s_m, e_y, e_psi))) if self.road.lanes else ()
            if band and band != self._band:
                mpc.set_road(self.road.band(band))
                self._band = band
        out = mpc.step(x, warm)
        # the step's time is the whole step's: the planning too
        return dataclasses.replace(out, solve_time_s=time.perf_counter() - t0)
