"""The road around a reference path: the one owner of the rule "the body stays ``margin_m``
inside the road".

A :class:`Road` gives, as functions of the path's arc length ``s`` [m], the lateral offsets of
its left and right edges from the path (``e_y`` [m], positive to the left of the direction of
travel, so ``left_m > right_m``), linear between knots and constant beyond the ends, and the
lanes inside it (:class:`Lane`: the route lane, its same-direction neighbours, lanes a scenario
allows). A constant lane centred on the path, per-side widths, widths per point (a track's CSV,
a CommonRoad route's lanelets) are all the same object.

The rule (:func:`centre_bounds`): every point of the vehicle's body -- its rectangle at the
predicted yaw relative to the path, sampled along both long sides -- stays ``margin_m`` inside
the edges *at the arc length where that point is*, with the path's curvature taken into account
(a straight body on a curved road: the outer edge comes ``kappa d^2 / 2`` closer at distance
``d`` ahead or behind). It is turned into bounds ``lo_k <= e_y,k <= hi_k`` on the reference
point's lateral offset, per horizon step, evaluated at the linearization trajectory (the yaw is
held at its linearization value, as the obstacle rows are linearized). Where the road is
narrower than the body needs, both bounds are the middle of what there is: the rows are soft
(``MpcProblem.lane_slack_weight``), so the car is pulled to the middle and the excess is paid
for, never an infeasible QP. A drive is judged by the same rule without its linearization
(:meth:`Road.measure_excess_m`): every point of the body's outline, in the world frame, against
the edges at its own arc length, exact to a tenth of a millimetre; :meth:`Road.body_excess_m`
is the rows' form of it (the controller's quick checks). A road may end (``start_m`` / ``end_m``:
where the mapped road begins / ends along the path, e.g. a lane with no successor): a point
behind the start or past the end is outside by how far it is beyond it (with its distance beyond
a side edge, the straight-line distance to the road's corner). The controller's rows do not see
the ends: a reference that stops the body inside the road keeps it there.

The functions are numba-compiled and called both from numpy code (the OSQP controller) and from
the compiled control step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numba import njit

from .._subroutine import subroutine
from .footprint import Footprint

#: points sampled along each long side of the body (rear corner, ..., front corner)
BODY_SAMPLES = 5
#: the largest sampling error [m] of :meth:`Road.measure_excess_m` (between the outline points)
EXCESS_SAMPLING_TOL_M = 1e-4
#: the most points per side of the body outline :meth:`Road.measure_excess_m` takes (2^j + 1)
EXCESS_MAX_POINTS = 513


class ProjectingPath(Protocol):
    """What :meth:`Road.measure_excess_m` needs of a reference path (``mpcdrive.paths``)."""

    def project_many(self, xy, s_guess, window_m) -> tuple[np.ndarray, np.ndarray]: ...

    def curvature(self, s) -> np.ndarray: ...


def _placed(points: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(K, M, 2) world positions [m] of body-frame points ``points`` (M, 2) at poses (K, >= 3)."""
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    px, py = points[None, :, 0], points[None, :, 1]
    return np.stack([poses[:, :1] + c * px - s * py, poses[:, 1:2] + s * px + c * py], axis=-1)


@subroutine
def _value_slope(tab_s, tab_v, s, period):
    """(value, d/ds) of the piecewise-linear table (tab_s increasing) at s: constant beyond the
    ends (slope 0), or periodic with ``period`` [m] when it is > 0 (a closed path; the table
    spans one period, the last knot joined to the first of the next lap)."""
    n = tab_s.shape[0]
    if period > 0.0:
        s = tab_s[0] + (s - tab_s[0]) % period
        if s > tab_s[n - 1]:  # between the last knot and the first one of the next lap
            slope = (tab_v[0] - tab_v[n - 1]) / (tab_s[0] + period - tab_s[n - 1])
            return tab_v[n - 1] + slope * (s - tab_s[n - 1]), slope
    if n == 1 or s <= tab_s[0]:
        return tab_v[0], 0.0
    if s >= tab_s[n - 1]:
        return tab_v[n - 1], 0.0
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if tab_s[mid] <= s:
            lo = mid
        else:
            hi = mid
    slope = (tab_v[hi] - tab_v[lo]) / (tab_s[hi] - tab_s[lo])
    return tab_v[lo] + slope * (s - tab_s[lo]), slope


@subroutine
def _interp(tab_s, tab_v, s, period):
    """The value of :func:`_value_slope`."""
    return _value_slope(tab_s, tab_v, s, period)[0]


@subroutine
def body_bounds(
    tab_s, tab_left, tab_right, period, s, kappa, yaw_rel, half_length_m, half_width_m, center_offset_m, margin_m
):
    """(lo, hi, dlo, dhi): the bounds [m] of the reference point's lateral offset that keep every
    sampled point of the body ``margin_m`` inside the road edges, for the reference point at arc
    length ``s`` [m] where the path's curvature is ``kappa`` [1/m], the body yawed ``yaw_rel``
    [rad] from the path heading, and their slopes d/d(yaw) [m/rad] there (of the sample point
    that binds), with which the rows are linearized in the yaw. lo > hi (road too narrow) gives
    the middle of the two for both, with zero slopes."""
    cs, sn = math.cos(yaw_rel), math.sin(yaw_rel)
    hi = math.inf
    lo = -math.inf
    dhi = 0.0
    dlo = 0.0
    for i in range(BODY_SAMPLES):
        dx = center_offset_m - half_length_m + 2.0 * half_length_m * i / (BODY_SAMPLES - 1)
        for side in range(2):
            dy = half_width_m if side == 0 else -half_width_m
            d = dx * cs - dy * sn  # the point's distance along the path
            y = dx * sn + dy * cs  # its lateral offset from the reference point
            bend = 0.5 * kappa * d * d  # where the curved path is at d, seen from s
            left, left_slope = _value_slope(tab_s, tab_left, s + d, period)
            right, right_slope = _value_slope(tab_s, tab_right, s + d, period)
            left += bend
            right += bend
            h = left - margin_m - y
            l_ = right + margin_m - y
            # d/dyaw: dd = -y, dy = d
            if h < hi:
                hi = h
                dhi = -(left_slope + kappa * d) * y - d
            if l_ > lo:
                lo = l_
                dlo = -(right_slope + kappa * d) * y - d
    if lo > hi:
        mid = 0.5 * (lo + hi)
        return mid, mid, 0.0, 0.0
    return lo, hi, dlo, dhi


@njit(cache=True)
def centre_bounds(
    tab_s,
    tab_left,
    tab_right,
    period,
    s_arr,
    kappa_arr,
    yaw_rel_arr,
    half_length_m,
    half_width_m,
    center_offset_m,
    margin_m,
    lo_out,
    hi_out,
):
    """:func:`body_bounds` for each entry of the (n,) arrays, written to ``lo_out`` / ``hi_out``."""
    for k in range(s_arr.shape[0]):
        lo_out[k], hi_out[k], _, _ = body_bounds(
            tab_s,
            tab_left,
            tab_right,
            period,
            s_arr[k],
            kappa_arr[k],
            yaw_rel_arr[k],
            half_length_m,
            half_width_m,
            center_offset_m,
            margin_m,
        )


def lin_arc_lengths(Xlin, s0_m: float) -> np.ndarray:
    """(N+1,) arc lengths [m] of a linearization trajectory ``Xlin`` (N+1, >= 2) on the path:
    ``s0_m`` (the measured state's) plus the distance travelled along it (the car stays near the
    path); where the road rows and the obstacle rows are linearized."""
    return s0_m + np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(Xlin[:, :2], axis=0).T))])


@subroutine
def horizon_bounds(
    tab_s,
    tab_left,
    tab_right,
    period,
    s_arr,
    heading,
    kappa,
    yaw,
    half_length_m,
    half_width_m,
    center_offset_m,
    margin_m,
    lo_out,
    hi_out,
    dlo_out,
    dhi_out,
):
    """:func:`body_bounds` per horizon step x_1 .. x_n of an MPC: the path's heading [rad] and
    curvature [1/m] at arc lengths ``s_arr`` [m], the linearization trajectory's yaw ``yaw`` [rad]
    (all (n,)); the relative yaw is wrapped to [-pi, pi). Writes the bounds and their yaw slopes
    (the first step's are then widened to what it can reach: :func:`reach_first_step`)."""
    for k in range(s_arr.shape[0]):
        rel = (yaw[k] - heading[k] + math.pi) % (2.0 * math.pi) - math.pi
        lo_out[k], hi_out[k], dlo_out[k], dhi_out[k] = body_bounds(
            tab_s,
            tab_left,
            tab_right,
            period,
            s_arr[k],
            kappa[k],
            rel,
            half_length_m,
            half_width_m,
            center_offset_m,
            margin_m,
        )


@subroutine
def reach_first_step(lo, hi, dlo, dhi, e1_m, dyaw1_rad):
    """Widen the road bounds of an MPC horizon's first step x_1 (``lo[0]``, ``hi[0]`` [m], yaw
    slopes ``dlo[0]``, ``dhi[0]``, of :func:`horizon_bounds`) to hold the body where the model puts
    it one step ahead with the linearization's first input: its reference point's lateral offset
    ``e1_m`` [m] (as the rows measure it) and yaw ``dyaw1_rad`` [rad] off the linearization yaw.
    That x_1 is reachable (the first input of the shifted plan keeps the rate limits), so the row
    never asks for what no input gives. Without this, a car that the plant's lag (tyre slip, a
    steering servo) carried past a bound bought the slack back with the steering at its rate
    limit: a limit cycle on CommonRoad's ST model. Where x_1 is inside, nothing changes."""
    need_lo = e1_m - dlo[0] * dyaw1_rad
    need_hi = e1_m - dhi[0] * dyaw1_rad
    if need_lo < lo[0]:
        lo[0] = need_lo
    if need_hi > hi[0]:
        hi[0] = need_hi


@dataclass(frozen=True, eq=False)
class Lane:
    """One lane of a :class:`Road`, on the road's knots: its centre and edges as lateral offsets
    [m] from the reference path (positive left). ``name`` identifies it (a lanelet id, "left");
    ``oncoming``: it goes the other way (a car uses it only to pass)."""

    name: str
    center_m: np.ndarray
    left_m: np.ndarray
    right_m: np.ndarray
    oncoming: bool = False


@dataclass(frozen=True, eq=False, init=False)
class Road:
    """Left / right road edges ``left_m`` / ``right_m`` [m] (lateral offsets from the reference
    path, positive left) at arc lengths ``s_m`` [m]; the body stays ``margin_m`` inside them.
    ``lanes`` (optional) are the lanes between the edges, ``route_lane`` the index of the one the
    route follows; ``period_m`` > 0 makes the tables periodic (a closed path of that length, the
    knots spanning one lap). ``start_m`` / ``end_m`` [m] (optional; None: the road goes on, as it
    always does on a closed path): the arc lengths along the path where the mapped road begins /
    ends, beyond which the body is outside it (:meth:`measure_excess_m`); the edges' tables are
    held constant up to them. Build with :meth:`constant`, :meth:`per_side` or :meth:`from_widths`."""

    s_m: np.ndarray
    left_m: np.ndarray
    right_m: np.ndarray
    margin_m: float
    lanes: tuple[Lane, ...]
    route_lane: int
    period_m: float
    start_m: float | None
    end_m: float | None

    def __init__(
        self,
        s_m,
        left_m,
        right_m,
        margin_m: float = 0.05,
        lanes: tuple[Lane, ...] = (),
        route_lane: int = 0,
        period_m: float = 0.0,
        start_m: float | None = None,
        end_m: float | None = None,
    ):
        s = np.atleast_1d(np.asarray(s_m, float)).copy()
        left = np.broadcast_to(np.asarray(left_m, float), s.shape).copy()
        right = np.broadcast_to(np.asarray(right_m, float), s.shape).copy()
        if s.ndim != 1 or s.size < 1:
            raise ValueError("road knots s_m must be a non-empty 1-D array")
        for name, a in (("s_m", s), ("left_m", left), ("right_m", right)):
            if not np.all(np.isfinite(a)):
                raise ValueError(f"road {name} contains non-finite values")
        if np.any(np.diff(s) <= 0):
            raise ValueError("road knots s_m must be strictly increasing")
        if np.any(left <= right):
            k = int(np.argmax(left <= right))
            raise ValueError(
                f"road left edge {left[k]:g} m is not left of its right edge {right[k]:g} m at s = {s[k]:g} m"
            )
        if not (math.isfinite(margin_m) and margin_m >= 0):
            raise ValueError(f"road margin_m must be >= 0, got {margin_m!r}")
        if not (math.isfinite(period_m) and period_m >= 0):
            raise ValueError(f"road period_m must be >= 0, got {period_m!r}")
        if period_m > 0 and s[-1] - s[0] >= period_m:
            raise ValueError("a periodic road's knots must span less than one period")
        if lanes and not 0 <= route_lane < len(lanes):
            raise ValueError(f"route_lane {route_lane} is not one of the {len(lanes)} lanes")
        for ln in lanes:
            for name in ("center_m", "left_m", "right_m"):
                if np.shape(getattr(ln, name)) != s.shape:
                    raise ValueError(f"lane {ln.name}: {name} must have one value per road knot ({s.size})")
        for name, end in (("start_m", start_m), ("end_m", end_m)):
            if end is not None and (isinstance(end, bool) or not math.isfinite(end)):
                raise ValueError(f"road {name} must be a finite arc length [m] or None, got {end!r}")
            if end is not None and period_m > 0:
                raise ValueError(f"a periodic road (a closed path) has no {name}: it goes on lap after lap")
        if start_m is not None and end_m is not None and not start_m < end_m:
            raise ValueError(f"road start_m {start_m:g} m must be before its end_m {end_m:g} m")
        for name, value in (
            ("s_m", s),
            ("left_m", left),
            ("right_m", right),
            ("margin_m", float(margin_m)),
            ("lanes", tuple(lanes)),
            ("route_lane", int(route_lane)),
            ("period_m", float(period_m)),
            ("start_m", None if start_m is None else float(start_m)),
            ("end_m", None if end_m is None else float(end_m)),
        ):
            object.__setattr__(self, name, value)

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def constant(cls, width_m: float, margin_m: float = 0.05) -> Road:
        """A lane ``width_m`` [m] wide centred on the path."""
        return cls.per_side(0.5 * width_m, 0.5 * width_m, margin_m)

    @classmethod
    def per_side(cls, left_width_m: float, right_width_m: float, margin_m: float = 0.05) -> Road:
        """Edges ``left_width_m`` [m] to the left and ``right_width_m`` [m] to the right of the path."""
        return cls.from_widths([0.0], [left_width_m], [right_width_m], margin_m)

    @classmethod
    def from_widths(
        cls,
        s_m,
        left_width_m,
        right_width_m,
        margin_m: float = 0.05,
        period_m: float = 0.0,
        start_m: float | None = None,
        end_m: float | None = None,
    ) -> Road:
        """Edges at distances ``left_width_m`` / ``right_width_m`` [m] (>= 0, per knot) to either
        side of the path at arc lengths ``s_m`` [m]; one lane between them; ``start_m`` /
        ``end_m`` [m]: where the road begins / ends along the path (None: it goes on)."""
        s = np.atleast_1d(np.asarray(s_m, float))
        wl = np.broadcast_to(np.asarray(left_width_m, float), s.shape)
        wr = np.broadcast_to(np.asarray(right_width_m, float), s.shape)
        if np.any(wl < 0) or np.any(wr < 0):
            raise ValueError("road widths must be >= 0")
        return cls(s, wl, -wr, margin_m, period_m=period_m, start_m=start_m, end_m=end_m)

    def with_ends(self, start_m: float | None, end_m: float | None) -> Road:
        """This road beginning at ``start_m`` and ending at ``end_m`` [m] along the path (None: it
        goes on there), everything else kept."""
        return Road(
            self.s_m,
            self.left_m,
            self.right_m,
            self.margin_m,
            self.lanes,
            self.route_lane,
            self.period_m,
            start_m,
            end_m,
        )

    @property
    def has_ends(self) -> bool:
        """Whether the road begins or ends somewhere along the path (``start_m`` / ``end_m``)."""
        return self.start_m is not None or self.end_m is not None

    # -- the rule -------------------------------------------------------------------------------
    def edges(self, s_m) -> tuple[np.ndarray, np.ndarray]:
        """(left, right) edge offsets [m] at arc length(s) ``s_m``."""
        s = np.asarray(s_m, float)
        if self.period_m > 0:
            p = self.period_m
            return (np.interp(s, self.s_m, self.left_m, period=p), np.interp(s, self.s_m, self.right_m, period=p))
        return np.interp(s, self.s_m, self.left_m), np.interp(s, self.s_m, self.right_m)

    @property
    def min_width_m(self) -> float:
        """The narrowest width of the road [m]."""
        return float(np.min(self.left_m - self.right_m))

    @property
    def max_offset_m(self) -> float:
        """The farthest an edge gets from the path [m]."""
        return float(max(np.max(self.left_m), -np.min(self.right_m)))

    def bounds(self, s_m, kappa, yaw_rel_rad, footprint: Footprint) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) [m]: the bounds of the reference point's lateral offset that keep ``footprint``
        ``margin_m`` inside the road (:func:`body_bounds`), for arrays of arc lengths [m],
        curvatures [1/m] and yaws relative to the path [rad] (broadcast together)."""
        return self._bounds(s_m, kappa, yaw_rel_rad, footprint, self.margin_m)

    def body_excess_m(self, s_m, e_y_m, kappa, yaw_rel_rad, footprint: Footprint) -> np.ndarray:
        """How far [m] the body is outside the road (0 inside) by the rule of :meth:`bounds` with
        no margin, for the reference point at lateral offset(s) ``e_y_m``: the controller rows'
        form (sampled points, the curvature's ``kappa d^2 / 2``), which over-reports on tight
        curves by millimetres; a body reaching past the road's start or end (its corners' distance
        along the path, ``d`` of :func:`body_bounds`) is outside by that much as well. A drive is
        judged by :meth:`measure_excess_m`, exact."""
        lo, hi = self._bounds(s_m, kappa, yaw_rel_rad, footprint, 0.0)
        e = np.asarray(e_y_m, float)
        side = np.maximum(np.maximum(e - hi, lo - e), 0.0)
        if not self.has_ends:
            return side
        c = footprint.corners()  # (4, 2) body frame
        yaw = np.asarray(yaw_rel_rad, float)[..., None]
        d = c[:, 0] * np.cos(yaw) - c[:, 1] * np.sin(yaw)  # each corner's distance along the path
        along = np.asarray(s_m, float)[..., None] + d
        return np.maximum(side, self._past_ends_m(along).max(axis=-1))

    def measure_excess_m(self, path: ProjectingPath, poses, s_m, footprint: Footprint) -> np.ndarray:
        """(K,) how far [m] the body was outside the road at each of the poses ``poses`` (K, >= 3)
        ``[x m, y m, yaw rad, ...]`` of its reference point, whose arc lengths on ``path`` are
        ``s_m`` (K,) [m] (0 inside; no margin): the measure a drive is judged by. A point behind
        ``start_m`` or past ``end_m`` is outside by how far (:meth:`_points_excess`).

        Exact in the world frame, unlike :meth:`body_excess_m` (the controller rows' linearized
        rule): points along the body's outline are each projected onto ``path`` (its
        ``project_many``, searched near ``s_m``) and compared with the edges at their own arc
        length. Between two outline points the excess is a smooth function whose curvature is
        bounded by the path's local curvature ``kappa`` (|d2e/dtau2| <= kappa / (1 - kappa e)
        along a straight side, the edges' slope adding its share), so the points are spaced for
        a sampling error of at most :data:`EXCESS_SAMPLING_TOL_M`; where a side crosses a knot at
        which an edge bends, the point on the knot is measured too. So the measure is exact to
        that tolerance on the path as it is represented (a waypoint path's own table)."""
        return self._measure(path, poses, s_m, footprint, sides=True)

    def _measure(self, path: ProjectingPath, poses, s_m, footprint: Footprint, sides: bool) -> np.ndarray:
        """:meth:`measure_excess_m` (``sides``) or only its ends' share (:meth:`measure_end_excess_m`)."""
        X = np.asarray(poses, float)
        S = np.asarray(s_m, float).reshape(-1)
        K = len(S)
        if X.ndim != 2 or X.shape[0] != K or X.shape[1] < 3:
            raise ValueError(f"poses must be (K, 3) with one row per arc length ({K}), got shape {X.shape}")
        out = np.zeros(K)
        if K == 0 or not (sides or self.has_ends):
            return out
        corners = footprint.corners()  # (4, 2) counter-clockwise, body frame
        reach = float(np.max(np.hypot(corners[:, 0], corners[:, 1])))  # of a body point from (x, y)
        counts = self._outline_counts(path, S, reach, footprint)
        window = np.full(1, 2.0 * reach + 1.0)
        knots = self._bend_knots(S, reach)
        for n in np.unique(counts):
            ks = np.flatnonzero(counts == n)
            # n points along each side, corner to corner: (4 sides, n) in the body frame
            tau = np.linspace(0.0, 1.0, int(n))
            a, b = corners, np.roll(corners, -1, axis=0)
            body = a[:, None, :] + tau[None, :, None] * (b - a)[:, None, :]  # (4, n, 2)
            P = _placed(body.reshape(-1, 2), X[ks])  # (k, 4n, 2)
            s_pts, e_pts = path.project_many(
                P.reshape(-1, 2), np.repeat(S[ks], P.shape[1]), np.broadcast_to(window, (P.shape[0] * P.shape[1],))
            )
            s_pts, e_pts = s_pts.reshape(len(ks), 4, int(n)), e_pts.reshape(len(ks), 4, int(n))
            out[ks] = self._points_excess(s_pts, e_pts, sides).reshape(len(ks), -1).max(axis=1)
            if sides and knots.size:  # the points of the sides on the knots where an edge bends
                out[ks] = np.maximum(out[ks], self._knot_excess(path, knots, s_pts, body, X[ks], S[ks], window))
        return out

    def measure_end_excess_m(self, path: ProjectingPath, poses, s_m, footprint: Footprint) -> np.ndarray:
        """(K,) how far [m] the body reached behind the road's start or past its end at each pose
        (the arc length of its outline's points against ``start_m`` / ``end_m``; 0 for a road
        without ends): the part of :meth:`measure_excess_m` the road's ends account for."""
        return self._measure(path, poses, s_m, footprint, sides=False)

    def _points_excess(self, s_pts: np.ndarray, e_pts: np.ndarray, sides: bool = True) -> np.ndarray:
        """Excess [m] of points at arc lengths ``s_pts`` and lateral offsets ``e_pts`` (0 inside):
        beyond a side edge, behind the start or past the end (both: the distance to the road's
        corner); only the ends' share without ``sides``."""
        if sides:
            left, right = self.edges(s_pts)
            side = np.maximum(np.maximum(e_pts - left, right - e_pts), 0.0)
        else:
            side = np.zeros(np.shape(s_pts))
        if not self.has_ends:
            return side
        return np.hypot(side, self._past_ends_m(s_pts))

    def _past_ends_m(self, s_pts) -> np.ndarray:
        """How far [m] arc lengths ``s_pts`` lie behind ``start_m`` or past ``end_m`` (0 between)."""
        s = np.asarray(s_pts, float)
        past = np.zeros(s.shape)
        if self.start_m is not None:
            past = np.maximum(past, self.start_m - s)
        if self.end_m is not None:
            past = np.maximum(past, s - self.end_m)
        return past

    def _outline_counts(self, path: ProjectingPath, S: np.ndarray, reach: float, footprint: Footprint) -> np.ndarray:
        """(K,) points per side of the body outline at each step: the fewest (2^j + 1, 5 to
        :data:`EXCESS_MAX_POINTS`) for which the curvature bound M of the excess along a side
        (the path's largest |kappa| within ``reach`` [m] of the step's arc length) keeps the
        sampling error M h^2 / 8 within :data:`EXCESS_SAMPLING_TOL_M`, h the spacing."""
        offsets = np.linspace(-reach, reach, max(9, int(math.ceil(2.0 * reach / 0.02)) + 1))
        kappa = np.abs(np.asarray(path.curvature(S[:, None] + offsets[None, :]), float)).max(axis=1)
        lateral = reach + float(self.max_offset_m)  # how far from the path a body point can count
        stretch = np.maximum(1.0 - kappa * lateral, 0.1)  # 1 - kappa e, kept away from the centre
        slopes = np.abs(np.diff(np.r_[self.left_m, self.right_m].reshape(2, -1), axis=1))
        ds = np.diff(self.s_m)
        slope = float(np.max(slopes / ds)) if ds.size else 0.0
        M = kappa / stretch * (1.0 + slope / stretch)
        side = max(footprint.length_m, footprint.width_m)
        h = np.sqrt(8.0 * EXCESS_SAMPLING_TOL_M / np.maximum(M, 1e-12))
        need = np.ceil(side / h) + 1.0
        j = np.ceil(np.log2(np.maximum(need - 1.0, 4.0)))
        return np.minimum(2.0**j + 1.0, EXCESS_MAX_POINTS).astype(int)

    def _bend_knots(self, S: np.ndarray, reach: float) -> np.ndarray:
        """Arc lengths [m] of the knots at which an edge bends (its slope changes), within
        ``reach`` (plus a metre) of the arc lengths ``S``, laps repeated on a periodic road."""
        s, left, right = self.s_m, self.left_m, self.right_m
        if s.size < 2 and self.period_m <= 0:
            return np.zeros(0)
        if self.period_m > 0:  # one lap of knots, the joint to the next lap included
            p = self.period_m
            s_ext = np.r_[s[-1] - p, s, s[0] + p]
            l_ext, r_ext = np.r_[left[-1], left, left[0]], np.r_[right[-1], right, right[0]]
        else:
            s_ext, l_ext, r_ext = s, left, right
        sl_l, sl_r = np.diff(l_ext) / np.diff(s_ext), np.diff(r_ext) / np.diff(s_ext)
        if self.period_m > 0:
            bend = (np.abs(np.diff(sl_l)) > 0) | (np.abs(np.diff(sl_r)) > 0)
            lap = s_ext[1:-1][bend]
        else:  # beyond the ends the edges are held: the end knots bend unless the slope is 0
            sl_l, sl_r = np.r_[0.0, sl_l, 0.0], np.r_[0.0, sl_r, 0.0]
            bend = (np.abs(np.diff(sl_l)) > 0) | (np.abs(np.diff(sl_r)) > 0)
            lap = s[bend]
        if lap.size == 0:
            return lap
        lo, hi = float(S.min()) - reach - 1.0, float(S.max()) + reach + 1.0
        if self.period_m > 0:
            m = np.arange(math.floor((lo - lap.max()) / self.period_m), math.ceil((hi - lap.min()) / self.period_m) + 1)
            lap = (lap[None, :] + self.period_m * m[:, None]).ravel()
        lap = np.sort(lap)
        return lap[(lap >= lo) & (lap <= hi)]

    def _knot_excess(self, path, knots, s_pts, body, X, S, window) -> np.ndarray:
        """(k,) the largest excess [m] at the points of the body's sides that lie on a bend knot:
        between two outline points (arc lengths ``s_pts`` (k, 4, n), body-frame points ``body``
        (4, n, 2)) that a knot lies between, the point at the knot's arc length (interpolated in
        arc length along the side), projected and measured like the others."""
        s0, s1 = s_pts[..., :-1], s_pts[..., 1:]
        lo, hi = np.minimum(s0, s1), np.maximum(s0, s1)
        first = np.searchsorted(knots, lo, side="right")
        count = np.searchsorted(knots, hi, side="left") - first  # knots strictly between
        out = np.zeros(len(X))
        if not np.any(count > 0):
            return out
        step, side, q = np.nonzero(count > 0)
        c = count[step, side, q]
        step, side, q = np.repeat(step, c), np.repeat(side, c), np.repeat(q, c)
        start = np.repeat(first[count > 0], c)
        kth = np.arange(len(step)) - np.repeat(np.cumsum(c) - c, c)
        sk = knots[start + kth]
        a, b = s0[step, side, q], s1[step, side, q]
        w = (sk - a) / (b - a)
        pts = body[side, q] + w[:, None] * (body[side, q + 1] - body[side, q])  # (m, 2) body frame
        xs = X[step]
        cos, sin = np.cos(xs[:, 2]), np.sin(xs[:, 2])
        world = np.column_stack(
            [xs[:, 0] + cos * pts[:, 0] - sin * pts[:, 1], xs[:, 1] + sin * pts[:, 0] + cos * pts[:, 1]]
        )
        s_k, e_k = path.project_many(world, S[step], np.broadcast_to(window, (len(step),)))
        np.maximum.at(out, step, self._points_excess(s_k, e_k))
        return out

    def _bounds(self, s_m, kappa, yaw_rel_rad, footprint: Footprint, margin_m: float):
        b = np.broadcast_arrays(np.asarray(s_m, float), np.asarray(kappa, float), np.asarray(yaw_rel_rad, float))
        shape = b[0].shape
        s, k, y = (np.ascontiguousarray(a, dtype=float).ravel() for a in b)
        lo, hi = np.empty(s.size), np.empty(s.size)
        centre_bounds(
            self.s_m,
            self.left_m,
            self.right_m,
            self.period_m,
            s,
            k,
            y,
            0.5 * footprint.length_m,
            0.5 * footprint.width_m,
            footprint.center_offset_m,
            margin_m,
            lo,
            hi,
        )
        return lo.reshape(shape), hi.reshape(shape)

    def narrowest_fit_m(self, footprint: Footprint) -> float:
        """Room [m] left beside the body, aligned with a straight path, where the road is
        narrowest: negative when the car (plus both margins) does not fit somewhere."""
        return self.min_width_m - footprint.width_m - 2.0 * self.margin_m

    def band(self, lanes) -> Road:
        """The road made of the lanes with indices ``lanes`` (neighbours: their outer edges), its
        lanes and margin kept: what a decision layer lets the body use now."""
        idx = sorted(set(int(i) for i in lanes))
        if not idx or not all(0 <= i < len(self.lanes) for i in idx):
            raise ValueError(f"lane indices {lanes} are not among the road's {len(self.lanes)} lanes")
        left = np.max([self.lanes[i].left_m for i in idx], axis=0)
        right = np.min([self.lanes[i].right_m for i in idx], axis=0)
        return Road(
            self.s_m,
            left,
            np.minimum(right, left - 1e-6),
            self.margin_m,
            self.lanes,
            self.route_lane,
            self.period_m,
            self.start_m,
            self.end_m,
        )

    def whole(self) -> Road:
        """The whole road: its edges widened to the outer edges of every lane (the road itself
        without lanes), its lanes and margin kept. Where the body counts as inside when a drive
        is judged, whichever lanes a decision layer lets the controller use at the time."""
        if not self.lanes:
            return self
        left = np.maximum(self.left_m, np.max([ln.left_m for ln in self.lanes], axis=0))
        right = np.minimum(self.right_m, np.min([ln.right_m for ln in self.lanes], axis=0))
        return Road(
            self.s_m, left, right, self.margin_m, self.lanes, self.route_lane, self.period_m, self.start_m, self.end_m
        )

    def profile(self, length_m: float, ds_m: float = 0.5) -> np.ndarray:
        """(M, 3) rows ``[s_m, left_m, right_m]`` over arc lengths 0..``length_m`` [m] (every
        ``ds_m`` and at the knots): the edges along the path, for figures and result files."""
        n = max(2, int(math.ceil(length_m / ds_m)) + 1)
        s = np.unique(np.concatenate([np.linspace(0.0, length_m, n), self.s_m[(self.s_m > 0) & (self.s_m < length_m)]]))
        left, right = self.edges(s)
        return np.column_stack([s, left, right])
