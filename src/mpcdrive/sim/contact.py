"""Contacts of the body with the obstacles over a logged drive: the signed distance at each
logged state and, between two logged states, on the swept motion.

Between two logged states the body's pose is interpolated linearly (position and yaw) and the
obstacles are where their motions put them. The signed distance between two convex bodies
changes no faster than the fastest relative motion of their points, so over an interval in
which the points move at most ``M`` [m] relative to each other, distances ``d_a`` and ``d_b`` at
its ends bound every distance inside from below by ``(d_a + d_b - M) / 2``: an interval with
``d_a + d_b >= M`` cannot hold a contact. Only the others are split in two (conservative
advancement), until either that holds or the relative motion over a piece is at most
``2 * SWEEP_DEPTH_M``: a contact between the logged states deeper than :data:`SWEEP_DEPTH_M`
is never missed, and its depth is found to within it. A normal run, whose states are logged
more often than its bodies move near one another, pays nothing; an obstacle at 300 m/s that
crosses the car between two states of a 0.01 s log is caught.
"""

from __future__ import annotations

import math

import numpy as np

from ..scene.footprint import Footprint
from ..scene.geometry import shape_distance
from ..scene.obstacles import Circle, Obstacle, TrajectoryMotion

#: contacts between two logged states shallower than this [m] may go unseen; deeper ones are
#: found, their depth to within this
SWEEP_DEPTH_M = 1e-3
#: the most distance evaluations one interval between logged states may take
_MAX_EVALS = 20000


def contact_count(clearance_m: np.ndarray) -> int:
    """How many contacts a run had: stretches of steps with the smallest footprint-to-obstacle
    distance ``clearance_m`` (K,) [m] below 0 (one contact lasting many steps counts once)."""
    hit = np.asarray(clearance_m) < 0.0
    return int(np.count_nonzero(hit[1:] & ~hit[:-1]) + (1 if hit.size and hit[0] else 0))


def collision_events(clearance_m: np.ndarray, t_s: np.ndarray, obstacles, contact_t_s=None) -> list[dict]:
    """One event per contact of the footprint with an obstacle, in time order: ``obstacle``
    (index in the scenario's list), ``name``, ``step`` (the first logged step of the contact, or
    the one just before it when it began between two steps), ``t_s`` [s] (when it began: that
    step's time, or the time between the steps), ``steps`` in contact and ``depth_m`` (deepest
    penetration [m], > 0).

    ``clearance_m`` : (n_obstacles, K) signed distances [m] per step (negative = overlap, at the
    step or between it and the next, :func:`clearances`); ``contact_t_s`` : (n_obstacles, K) the
    time a contact began at or after each step (NaN: none; None: at the steps' times). A contact
    starts at a step with overlap after one without (or at step 0)."""
    events = []
    for i, d in enumerate(clearance_m):
        hit = d < 0.0
        starts = np.flatnonzero(hit & ~np.r_[False, hit[:-1]])
        ends = np.flatnonzero(hit & ~np.r_[hit[1:], False]) + 1
        for a, b in zip(starts, ends):
            t = t_s[a] if contact_t_s is None or not math.isfinite(contact_t_s[i, a]) else contact_t_s[i, a]
            events.append(
                {
                    "obstacle": i,
                    "name": obstacles[i].name,
                    "step": int(a),
                    "t_s": float(t),
                    "steps": int(b - a),
                    "depth_m": float(-d[a:b].min()),
                }
            )
    return sorted(events, key=lambda e: (e["step"], e["t_s"], e["obstacle"]))


def recorded_traffic(log: list, T: np.ndarray) -> tuple[Obstacle, ...]:
    """The traffic as it moved: per obstacle its shape through the poses the plant reported at
    each logged step (``T`` (K,) [s]; interpolated between), with its lifetime."""
    if not log or not log[0]:
        return ()
    out = []
    for i, last in enumerate(log[-1]):
        P = np.array([seen[i].pose_at(t) for seen, t in zip(log, T)], float)
        P[:, 2] = np.unwrap(P[:, 2])
        d = P - P[0]
        motion = TrajectoryMotion(T, d[:, 0], d[:, 1], d[:, 2])
        out.append(Obstacle(last.shape, tuple(P[0]), motion, last.name, last.t_start_s, last.t_end_s))
    return tuple(out)


def clearances(X: np.ndarray, T: np.ndarray, obstacles, footprint: Footprint):
    """The footprint-to-obstacle signed distances of a drive: ``(at_steps, swept, contact_t,
    logs)``, for the body's poses ``X`` (K, >= 3) at the logged times ``T`` (K,) [s].

    at_steps : (n_obstacles, K) [m] the distance at each logged step per obstacle. Exact where
    it can matter (the step's nearest obstacle, every contact); for the others a lower bound
    (centre distance less both bounding radii), >= 0 and >= the step's smallest distance; inf
    outside an obstacle's lifetime.
    swept : (n_obstacles, K) [m] the same, except where the body touched the obstacle between
    the step and the next: there the deepest overlap found in between (negative).
    contact_t : (n_obstacles, K) [s] when a contact began at the step or after it, before the
    next (NaN: none).
    logs : the obstacles' logged shapes and poses (for reports)."""
    at_steps = _sampled(X, T, obstacles, footprint)
    swept = at_steps.copy()
    contact_t = np.where(at_steps < 0.0, np.broadcast_to(T, at_steps.shape), np.nan)
    if len(T) >= 2:
        _sweep(X, T, obstacles, footprint, swept, contact_t)
    return at_steps, swept, contact_t, _logs(T, obstacles)


def _body_reach_m(footprint: Footprint) -> float:
    """The farthest a body point is from the reference point [m]."""
    return math.hypot(abs(footprint.center_offset_m) + 0.5 * footprint.length_m, 0.5 * footprint.width_m)


def _sampled(X: np.ndarray, T: np.ndarray, obstacles, footprint: Footprint) -> np.ndarray:
    """(n_obstacles, K) signed distances at the logged steps (exact where they can matter, else
    lower bounds, as :func:`clearances` says)."""
    K = len(T)
    body_r = _body_reach_m(footprint)
    clear = np.full((len(obstacles), K), np.inf)
    for i, ob in enumerate(obstacles):
        P = ob.poses_at(T)
        bound = np.hypot(P[:, 0] - X[:, 0], P[:, 1] - X[:, 1]) - body_r - ob.shape.bounding_radius_m
        # an obstacle outside its lifetime is not there to hit
        clear[i] = np.where(np.broadcast_to(ob.present(T), (K,)), bound, np.inf)
    for k in range(K):
        body = None
        best = math.inf
        for i in np.argsort(clear[:, k], kind="stable"):
            b = clear[i, k]
            if b == math.inf or (b > best + 1e-9 and b > 1e-9):
                break  # this one and the rest are farther and not in contact (1 nm of rounding)
            if body is None:
                body = footprint.polygon(*X[k, :3])
            clear[i, k] = shape_distance(body, obstacles[i].at(T[k]))
            best = min(best, clear[i, k])
    return clear


def _sweep(X, T, obstacles, footprint: Footprint, clear: np.ndarray, contact_t: np.ndarray) -> None:
    """Contacts between the logged steps (the module's method), written into ``clear`` (the
    deepest overlap of the interval after a step, where below the step's own distance) and
    ``contact_t`` (when the first began, where the step itself had none)."""
    dt = np.diff(T)
    turn = np.abs((np.diff(X[:, 2]) + math.pi) % (2.0 * math.pi) - math.pi) * _body_reach_m(footprint)
    ego_move = np.hypot(np.diff(X[:, 0]), np.diff(X[:, 1])) + turn
    for i, ob in enumerate(obstacles):
        # the points' relative motion over each interval [m]: where the obstacle moves linearly
        # in time, as the body does, their relative translation is linear too (cars side by side
        # at one speed hardly move relative to each other); else both motions added up
        P = ob.poses_at(T)
        relative = np.hypot(np.diff(X[:, 0]) - np.diff(P[:, 0]), np.diff(X[:, 1]) - np.diff(P[:, 1]))
        relative += turn + np.abs(np.diff(P[:, 2])) * ob.shape.bounding_radius_m
        move = np.where(ob.moves_linearly(T), relative, ego_move + ob.point_speeds_mps(T) * dt)
        present = np.broadcast_to(ob.present(T), T.shape)
        near = present[:-1] & present[1:] & (clear[i, :-1] + clear[i, 1:] < move)
        if ob.has_lifetime:  # it appears or vanishes between two steps
            inside = ((ob.t_start_s > T[:-1]) & (ob.t_start_s < T[1:])) | ((ob.t_end_s > T[:-1]) & (ob.t_end_s < T[1:]))
            near |= inside | (present[:-1] != present[1:])
        for k in np.flatnonzero(near):
            ta, tb = max(T[k], ob.t_start_s), min(T[k + 1], ob.t_end_s)
            if not tb > ta:
                continue
            interval = _Interval(X[k], X[k + 1], T[k], T[k + 1], ob, footprint)
            depth, first = interval.deepest(ta, tb, move[k] / dt[k])
            if depth < 0.0 and depth < clear[i, k]:
                clear[i, k] = depth
            if depth < 0.0 and not math.isfinite(contact_t[i, k]):
                contact_t[i, k] = first


class _Interval:
    """The body between two logged poses ``x0`` (at ``t0``) and ``x1`` (at ``t1``), interpolated
    linearly, against one obstacle where its motion puts it."""

    def __init__(self, x0, x1, t0: float, t1: float, ob: Obstacle, footprint: Footprint):
        self.x0, self.t0, self.span = np.asarray(x0[:3], float), float(t0), float(t1 - t0)
        d = np.asarray(x1[:3], float) - self.x0
        d[2] = (d[2] + math.pi) % (2.0 * math.pi) - math.pi
        self.d, self.ob, self.footprint = d, ob, footprint

    def distance(self, t: float) -> float:
        """Signed distance [m] between the body and the obstacle at time ``t`` [s]."""
        x = self.x0 + ((t - self.t0) / self.span) * self.d
        return shape_distance(self.footprint.polygon(*x), self.ob.at(t))

    def deepest(self, ta: float, tb: float, rate_mps: float) -> tuple[float, float]:
        """(the smallest signed distance found in [ta, tb] [m], the first time it was negative
        [s] or NaN) at points of relative speed at most ``rate_mps`` [m/s]."""
        da, db = self.distance(ta), self.distance(tb)
        low = min(da, db)
        first = ta if da < 0.0 else (tb if db < 0.0 else math.nan)
        stack = [(ta, tb, da, db)]
        evals = 2
        while stack and evals < _MAX_EVALS:
            a, b, d_a, d_b = stack.pop()
            reach = rate_mps * (b - a)
            if d_a + d_b >= reach or reach <= 2.0 * SWEEP_DEPTH_M:
                continue  # no contact inside, or one no deeper than SWEEP_DEPTH_M beyond the ends
            m = 0.5 * (a + b)
            d_m = self.distance(m)
            evals += 1
            if d_m < low:
                low = d_m
            if d_m < 0.0 and not m > first:
                first = m
            stack.append((m, b, d_m, d_b))
            stack.append((a, m, d_a, d_m))
        return low, first


def _logs(T: np.ndarray, obstacles) -> list[dict]:
    """The obstacles' shapes and poses at the logged steps (``meta["obstacles"]``)."""
    logs = []
    for ob in obstacles:
        poses = np.array([ob.pose_at(t) for t in T])
        entry = {"name": ob.name, "moving": ob.moving}
        if isinstance(ob.shape, Circle):
            centers = poses[:, :2].round(4)
            entry.update(
                type="circle", radius_m=ob.shape.radius_m, center=centers.tolist() if ob.moving else centers[0].tolist()
            )
        else:
            world = np.array([ob.at(t).points for t in (T if ob.moving else T[:1])]).round(4)
            entry.update(type="polygon", points=world.tolist() if ob.moving else world[0].tolist())
        logs.append(entry)
    return logs
