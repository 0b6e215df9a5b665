"""Obstacle avoidance terms of the MPC, rebuilt in numbers (never in structure) each step.

Four formulations (the paper's Section V.C and its "safe driving envelope"):

* ``hard`` -- the paper's brute-force keep-out constraint (eq. 54) made convex per predicted
  step: for each footprint disc, a half-plane separating it from the obstacle, linearized at the
  linearization trajectory. Next to an obstacle the half-plane is lateral (pass on the chosen
  side); when no gap in the lane is wide enough it faces the car (stop behind it).
* ``corridor`` -- a convex obstacle-free tube inside the lane: per predicted step, bounds on the
  lateral offset that exclude every obstacle overlapping that stretch of road (plus a "stop
  before it" half-plane when the lane is blocked).
* ``potential`` -- the repulsive field of eq. 55, ``w / (|p - p_o|^2 + eps)``;
* ``gaussian`` -- the Gaussian of eq. 56, ``w exp(-1/2 (p - p_o)' Sigma^-1 (p - p_o))`` (the
  normalizing constant is folded into ``w``).
The two costs are non-convex: each QP uses their second-order model at the linearization point
with the Hessian projected onto the positive semidefinite cone (sequential quadratic
programming; see :mod:`mpcdrive.ocp.avoidance_cost`). The passing side of each obstacle is chosen
once, where the lane has more room, and kept from step to step (no dithering) unless that side
closes. Obstacles are judged on their Frenet boxes along the path (:mod:`mpcdrive.ocp.frenet`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..paths.base import ReferencePath
from ..paths.compiled import PathArrays, path_arrays
from ..scene.footprint import Footprint
from ..scene.geometry import points_polygons
from ..scene.obstacles import Circle, Obstacle, Polygon
from ..scene.road import Road, lin_arc_lengths
from . import avoidance_compiled as _ac
from .avoidance_cost import obstacle_cost, position_cost, sigma_inv
from .frenet import FrenetBox, FrenetBoxes, frenet_box, frenet_boxes
from .relations import checked_relations, step_modes

__all__ = [
    "SIDE_BLOCKED",
    "SIDE_LEFT",
    "SIDE_RIGHT",
    "Avoidance",
    "AvoidanceConfig",
    "AvoidanceMemory",
    "AvoidanceTerms",
    "Formulation",
    "FrenetBox",
    "FrenetBoxes",
    "frenet_box",
    "frenet_boxes",
    "obstacle_cost",
]

Formulation = Literal["hard", "corridor", "potential", "gaussian"]

SIDE_LEFT, SIDE_RIGHT, SIDE_BLOCKED = _ac.SIDE_LEFT, _ac.SIDE_RIGHT, _ac.SIDE_BLOCKED

#: an obstacle coming towards the car along its path, or crossing its road, faster than this
#: [m/s], on the car's road where they meet, is yielded to (a stop row before it), not passed beside
ONCOMING_MPS = 1.0


@dataclass(frozen=True)
class AvoidanceConfig:
    """How obstacles enter the MPC.

    formulation : ``hard`` | ``corridor`` | ``potential`` | ``gaussian``;
    margin_m : clearance kept between footprint and obstacle [m] (hard, corridor, side choice);
    weight : cost weight w (potential, gaussian); epsilon_m2 : eps of eq. 55 [m^2];
    sigma_m : (sx, sy) standard deviations of eq. 56 along / across the path [m];
    influence_m : obstacles farther than this from the vehicle are ignored [m];
    max_obstacles : obstacles considered per step (nearest first) -- fixes the QP size;
    detour : ``none`` or ``trapezoid`` (the paper's detour reference around each obstacle);
    detour_ramp_m : length of the trapezoid's ramps [m];
    follow_gap_s : None (the references run on at the reference speed; the stop constraint alone
        holds the car back) or a time gap [s] (hard, corridor): behind an obstacle that blocks the
        lane ahead, the horizon references approach a stop line that moves with the obstacle's
        prediction, trailing a moving one by this gap at its speed -- car following, without the
        tracking cost pulling the car against the stop constraint (see :func:`~mpcdrive.ocp.follow.follow_references`);
    follow_decel_mps2 : the hardest braking [m/s^2] of those references relative to the line
        (closer than that they fall back at this rate; the stop constraint still holds the car
        off the obstacle).
    """

    formulation: Formulation = "hard"
    margin_m: float = 0.1
    weight: float = 10.0
    epsilon_m2: float = 0.05
    sigma_m: tuple[float, float] = (0.5, 0.5)
    influence_m: float = 5.0
    max_obstacles: int = 3
    detour: Literal["none", "trapezoid"] = "none"
    detour_ramp_m: float = 1.0
    follow_gap_s: float | None = None
    follow_decel_mps2: float = 3.0

    def __post_init__(self):
        if self.formulation not in ("hard", "corridor", "potential", "gaussian"):
            raise ValueError(f"formulation must be hard, corridor, potential or gaussian, got {self.formulation!r}")
        for name in ("margin_m", "weight", "epsilon_m2", "influence_m", "detour_ramp_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")
        if self.epsilon_m2 <= 0 and self.formulation == "potential":
            raise ValueError("epsilon_m2 must be > 0 for the potential field")
        if len(self.sigma_m) != 2 or min(self.sigma_m) <= 0:
            raise ValueError(f"sigma_m must be two positive numbers, got {self.sigma_m}")
        if self.max_obstacles < 1:
            raise ValueError("max_obstacles must be >= 1")
        if self.detour not in ("none", "trapezoid"):
            raise ValueError(f"detour must be 'none' or 'trapezoid', got {self.detour!r}")
        if self.follow_gap_s is not None:
            if not (math.isfinite(self.follow_gap_s) and self.follow_gap_s >= 0):
                raise ValueError(f"follow_gap_s must be None or a finite number >= 0, got {self.follow_gap_s}")
            if not self.uses_rows:
                raise ValueError("follow_gap_s needs a stop constraint: formulation hard or corridor")
        if not (math.isfinite(self.follow_decel_mps2) and self.follow_decel_mps2 > 0):
            raise ValueError(f"follow_decel_mps2 must be a positive finite number, got {self.follow_decel_mps2}")

    @property
    def uses_rows(self) -> bool:
        return self.formulation in ("hard", "corridor")

    @property
    def uses_cost(self) -> bool:
        return self.formulation in ("potential", "gaussian")

    def rows_per_step(self, footprint: Footprint) -> int:
        if self.formulation == "hard":
            return self.max_obstacles * footprint.n_discs
        if self.formulation == "corridor":
            return self.max_obstacles  # stop-before half-planes of blocked obstacles
        return 0


@dataclass
class AvoidanceMemory:
    """Passing-side decisions kept across steps: obstacle index -> SIDE_*."""

    sides: dict[int, int] = field(default_factory=dict)


@dataclass(frozen=True)
class AvoidanceTerms:
    """One step's obstacle terms for the QP.

    rows_a : (N, M, 3), rows_b : (N, M) half-planes on (x_k, y_k, yaw_k) (b = -inf unused);
    lane_lo, lane_hi : (N,) lateral bounds [m] (corridor; None = lane only);
    H : (N, 2, 2), g : (N, 2) position cost model (None without cost);
    e_ref : (N+1,) lateral offset of the detour reference [m] (None without detour);
    sides : passing side per considered obstacle;
    s_max : (N+1,) furthest arc length [m] of the horizon references (the stop line behind the
    obstacles blocking the lane ahead, see ``follow_gap_s``; None when it does not apply)."""

    rows_a: np.ndarray | None
    rows_b: np.ndarray | None
    lane_lo: np.ndarray | None
    lane_hi: np.ndarray | None
    H: np.ndarray | None
    g: np.ndarray | None
    e_ref: np.ndarray | None
    sides: dict
    s_max: np.ndarray | None = None


class Avoidance:
    """Builds the obstacle terms of each step for one controller (sizes fixed at construction)."""

    def __init__(
        self,
        config: AvoidanceConfig,
        obstacles: list[Obstacle],
        path: ReferencePath,
        footprint: Footprint,
        N: int,
        dt_s: float,
        road: Road | None,
    ):
        self.config = config
        self.obstacles = tuple(obstacles)  # a tuple: mpc.obstacles hands on this very object
        self.path = path
        self.footprint = footprint
        self.N, self.dt_s = N, dt_s
        self.road = road
        #: extra distance [m] the stop row of a blocked obstacle keeps before it
        self.stop_gap_m = 0.0
        #: a maneuver planner's relations to the obstacles (:meth:`set_relations`): obstacle index
        #: -> (N,) REL_* codes of steps 1..N; the obstacles it names get their rows from it
        self.relations: dict[int, np.ndarray] = {}
        self.M = config.rows_per_step(footprint)
        self.offsets = footprint.disc_offsets_m
        self._max_offset = float(np.max(self.offsets))
        self.r_disc = footprint.disc_radius_m
        self.half_width = 0.5 * footprint.width_m
        self.half_length = 0.5 * footprint.length_m
        N1 = N + 1
        self._a = np.zeros((N, max(self.M, 1), 3))
        self._b = np.full((N, max(self.M, 1)), -np.inf)
        self._lo = np.zeros(N)
        self._hi = np.zeros(N)
        self._H = np.zeros((N, 2, 2))
        self._g = np.zeros((N, 2))
        self._e_ref = np.zeros(N1)
        self._always = np.ones(N, bool)  # the presence of an obstacle without a lifetime
        #: per considered obstacle, filled each step: not a car following (:meth:`_not_following`),
        #: present at steps 1..N (:meth:`_presence`)
        self._use = np.zeros(config.max_obstacles, np.bool_)
        self._present = np.zeros((config.max_obstacles, N), np.bool_)
        self._no_road = np.zeros(1)  # the road tables passed to the compiled decisions without a road
        #: the compiled decisions' arrays per considered obstacle: moving, previous side, side,
        #: following, stop line possible (updated in place each step)
        m = config.max_obstacles
        self._decisions = (
            np.zeros(m, np.bool_),
            np.zeros(m, np.int64),
            np.zeros(m, np.int64),
            np.zeros(m, np.bool_),
            np.zeros(m, np.bool_),
        )
        #: build with the compiled kernels (``ocp.avoidance_compiled``) where they apply: the
        #: selection when every obstacle is static, at constant velocity or on a recorded
        #: trajectory, the tracks of such obstacles and the hard rows on a path ``path_arrays``
        #: describes; False: the numpy code everywhere (the reference the kernels are tested
        #: against)
        self.compiled = True
        self._table: _ac.ObstacleTable | None = None
        self._cpath: PathArrays | None = None
        self._cpath_of: ReferencePath | None = None
        self._sel = np.empty(config.max_obstacles, np.int64)
        self._present_all = np.ones((config.max_obstacles, N), bool)
        self._warm_up()

    def _warm_up(self) -> None:
        """One discarded :meth:`terms` along the path's start, so that loading (or, on a first
        run, compiling) the kernels it uses happens while building, not in the first control
        step (about 10 ms a kernel)."""
        s_arr = np.linspace(0.0, min(self.N, self.path.length_m), self.N + 1)
        Xlin = np.column_stack([self.path.position(s_arr), np.asarray(self.path.heading(s_arr), float)])
        self.terms(0.0, Xlin[0], Xlin, s_arr, AvoidanceMemory())

    # -- compiled descriptions (rebuilt when the obstacles or the path are replaced) ---------
    def _obstacle_table(self) -> _ac.ObstacleTable:
        self._table = _ac.table_of(self.obstacles, self._table)
        return self._table

    def _compiled_path(self) -> PathArrays | None:
        if not self.compiled:
            return None
        if self._cpath_of is not self.path:
            self._cpath, self._cpath_of = path_arrays(self.path), self.path
        return self._cpath

    # -- helpers ----------------------------------------------------------------------
    def relevant(self, t_s: float, xy: np.ndarray) -> list[int]:
        """Indices of the obstacles a step at time ``t_s`` [s] from position ``xy`` [m] considers:
        those present at some time of the horizon and within the influence distance (centre
        distance minus bounding radius), nearest first, at most max_obstacles."""
        if self.compiled:
            tab = self._obstacle_table()
            if tab.all_simple:
                n = _ac.select(
                    float(t_s),
                    float(xy[0]),
                    float(xy[1]),
                    t_s + self.N * self.dt_s,
                    self.config.influence_m,
                    *tab.motion,
                    tab.bound_r,
                    tab.life,
                    tab.has_life,
                    self.config.max_obstacles,
                    self._sel,
                )
                return self._sel[:n].tolist()
        reach = self.config.influence_m
        t_end = t_s + self.N * self.dt_s
        d = []
        for j, ob in enumerate(self.obstacles):
            if ob.has_lifetime and (ob.t_end_s < t_s or ob.t_start_s > t_end):
                continue
            ox, oy, _ = ob.pose_at(t_s)
            dist = math.hypot(ox - xy[0], oy - xy[1]) - ob.shape.bounding_radius_m
            if dist <= reach:
                d.append((dist, j))
        d.sort()
        return [j for _, j in d[: self.config.max_obstacles]]

    @property
    def passing_room_m(self) -> float:
        """Width [m] of the gap between an obstacle and the lane edge that passing it needs: the
        body's centre line keeps ``half width + the road's margin`` from the road edge and, from the
        obstacle, ``margin`` plus the body's half width (corridor) or the radius of the discs
        that cover the body (hard half-planes act on the disc centres)."""
        obstacle_side = self.r_disc if self.config.formulation == "hard" else self.half_width
        margin = self.road.margin_m if self.road is not None else 0.0
        return self.half_width + margin + self.config.margin_m + obstacle_side

    def set_relations(self, relations: dict[int, np.ndarray] | None) -> None:
        """Take a maneuver planner's relations to the obstacles from the next step on
        (:func:`~.relations.checked_relations`: obstacle index -> (N,) ``REL_*`` codes of steps
        1..N); the rows of a named obstacle keep that relation at each step, the others are
        decided as before. None or an empty dict: no planner."""
        self.relations = checked_relations(relations, self.N)

    def _decide(self, rel: list[int], boxes, packed, x: np.ndarray, s_arr: np.ndarray, memory: AvoidanceMemory):
        """The decisions of one step (compiled: :func:`~mpcdrive.ocp.avoidance_compiled.decide`)
        for the obstacles ``rel`` with Frenet boxes ``boxes`` over the horizon (``packed``: the
        compiled tracks, or None): the passing sides (dict; SIDE_BLOCKED for an obstacle coming
        towards the car or across its road where they meet, which the car yields to), the cars
        following in the lane (a set: kept behind by a longitudinal row only, never swerved or
        braked for), which obstacles a stop line can be put before (dict), and for the compiled
        kernels after it the Frenet boxes as an array (n, 5, N+1) and the sides as an array (n,),
        both in the order of ``rel``."""
        n = len(rel)
        box = packed[5] if packed is not None else self._box_array(rel, boxes)
        moving, prev, side, fol, ahead = (v[:n] for v in self._decisions)
        for i, j in enumerate(rel):
            moving[i] = self.obstacles[j].moving
            prev[i] = memory.sides.get(j, _ac.SIDE_NONE)
        s0 = float(s_arr[0])
        follow = self.config.uses_rows and (self.path.closed or s0 > 0.0)  # no path behind an open start
        e_car = 0.0
        if follow:
            h, p = float(self.path.heading(s0)), self.path.position(s0)
            e_car = -math.sin(h) * (x[0] - p[0]) + math.cos(h) * (x[1] - p[1])
        road = self.road
        if road is None:
            road_s = road_left = road_right = self._no_road
            period = 0.0
        else:
            road_s, road_left, road_right, period = road.s_m, road.left_m, road.right_m, road.period_m
        _ac.decide(
            box,
            moving,
            np.ascontiguousarray(s_arr, dtype=float),
            road is not None,
            road_s,
            road_left,
            road_right,
            period,
            self.passing_room_m,
            self.r_disc + self.config.margin_m + self.half_length,
            float(self.dt_s),
            ONCOMING_MPS,
            follow,
            e_car,
            self.half_width,
            self.half_length,
            self.stop_distance_m,
            prev,
            side,
            fol,
            ahead,
        )
        return (
            dict(zip(rel, side.tolist())),
            {j for j, f in zip(rel, fol.tolist()) if f},
            dict(zip(rel, ahead.tolist())),
            box,
            side,
        )

    def _box_array(self, rel: list[int], boxes) -> np.ndarray:
        """The Frenet boxes of obstacles ``rel`` as an array (n, 5, K), fields in BOX_* order."""
        fields = ("s_ref", "s_lo", "s_hi", "e_lo", "e_hi")
        return np.array([[getattr(boxes[j], f) for f in fields] for j in rel], float).reshape(len(rel), 5, self.N + 1)

    # -- one step ---------------------------------------------------------------------
    def _tracks(self, rel: list[int], t_s: float, s_arr: np.ndarray):
        """Obstacles ``rel`` over the horizon, dicts by index: Frenet boxes (N+1), centres (N+1, 2)
        and, for a polygon, world vertices (N+1, M, 2) (None for a circle); a static obstacle is
        placed and projected once. The shapes of one kind are projected together. Also returns
        the tracks packed for the compiled rows (:meth:`_packed`), or None when built in numpy."""
        cpath = self._compiled_path()
        if cpath is not None:
            tab = self._obstacle_table()
            if tab.all_simple or all(tab.simple[j] for j in rel):
                return self._tracks_compiled(cpath, tab, rel, t_s, s_arr)
        return (*self._tracks_numpy(rel, t_s, s_arr), None)

    def _tracks_compiled(
        self, cpath: PathArrays, tab: _ac.ObstacleTable, rel: list[int], t_s: float, s_arr: np.ndarray
    ):
        """:meth:`_tracks` of static, constant-velocity and recorded obstacles, compiled."""
        n, K = len(rel), self.N + 1
        sel = np.array(rel, np.int64)
        centers_a = np.empty((n, K, 2))
        outlines_a = np.empty((n, K, tab.verts.shape[1], 2))
        box = np.empty((n, 5, K))
        _ac.tracks(
            cpath.kind,
            cpath.geo,
            cpath.tab_s,
            cpath.tab_xy,
            cpath.tab_h,
            cpath.tab_k,
            float(t_s),
            float(self.dt_s),
            s_arr,
            sel,
            *tab.motion,
            tab.moving,
            tab.shape,
            tab.radius,
            tab.verts,
            tab.nverts,
            centers_a,
            outlines_a,
            box,
        )
        boxes = {j: FrenetBoxes(*box[i]) for i, j in enumerate(rel)}
        centers = {j: centers_a[i] for i, j in enumerate(rel)}
        outlines = {
            j: None if tab.shape[j] == _ac.SHAPE_CIRCLE else outlines_a[i, :, : tab.nverts[j]]
            for i, j in enumerate(rel)
        }
        packed = (tab.shape[sel], tab.radius[sel], centers_a, outlines_a, tab.nverts[sel], box)
        return boxes, centers, outlines, packed

    def _packed(self, rel: list[int], boxes, centers, outlines):
        """The tracks of obstacles ``rel`` as the compiled rows take them: shapes, radii (n,),
        centres (n, K, 2), vertices (n, K, V, 2), vertex counts (n,), Frenet boxes (n, 5, K)."""
        n, K = len(rel), self.N + 1
        V = max([3] + [o.shape[1] for o in (outlines[j] for j in rel) if o is not None])
        shape, nverts, radius = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n)
        outlines_a = np.zeros((n, K, V, 2))
        for i, j in enumerate(rel):
            o = outlines[j]
            if o is None:
                radius[i] = _radius(self.obstacles[j])
            else:
                shape[i], nverts[i] = _ac.SHAPE_POLYGON, o.shape[1]
                outlines_a[i, :, : o.shape[1]] = o
        centers_a = np.array([centers[j] for j in rel], float).reshape(n, K, 2)
        return shape, radius, centers_a, outlines_a, nverts, self._box_array(rel, boxes)

    def _tracks_numpy(self, rel: list[int], t_s: float, s_arr: np.ndarray):
        K = self.N + 1
        times = t_s + self.dt_s * np.arange(K)
        centers: dict[int, np.ndarray] = {}
        outlines: dict[int, np.ndarray | None] = {}
        groups: dict[int, list[int]] = {}  # circles (0) and polygons by vertex count
        for j in rel:
            ob = self.obstacles[j]
            tj = times if ob.moving else times[:1]
            centers[j] = ob.poses_at(tj)[:, :2]
            if isinstance(ob.shape, Polygon):
                outlines[j] = ob.outlines_at(tj)
                groups.setdefault(len(ob.shape.points), []).append(j)
            else:
                outlines[j] = None
                groups.setdefault(0, []).append(j)
        boxes: dict[int, FrenetBoxes] = {}
        for kind, js in groups.items():
            counts = [len(centers[j]) for j in js]
            guess = np.concatenate([s_arr[:n] for n in counts])
            if kind == 0:
                radius = np.concatenate([np.full(n, _radius(self.obstacles[j])) for j, n in zip(js, counts)])
                bx = frenet_boxes(self.path, guess, np.concatenate([centers[j] for j in js]), radius)
            else:
                bx = frenet_boxes(
                    self.path, guess, np.zeros((len(guess), 2)), points=np.concatenate([outlines[j] for j in js])
                )
            ends = np.cumsum(counts)
            for j, n, end in zip(js, counts, ends):
                fields = (getattr(bx, f)[end - n : end] for f in ("s_ref", "s_lo", "s_hi", "e_lo", "e_hi"))
                boxes[j] = FrenetBoxes(*(np.repeat(v, K) if n == 1 else v for v in fields))
        for j in rel:
            if not self.obstacles[j].moving:
                centers[j] = np.repeat(centers[j], K, axis=0)
                o = outlines[j]
                outlines[j] = None if o is None else np.repeat(o, K, axis=0)
        return boxes, centers, outlines

    def terms(
        self,
        t_s: float,
        x: np.ndarray,
        Xlin: np.ndarray,
        s_arr: np.ndarray,
        memory: AvoidanceMemory,
        road_lo: np.ndarray | None = None,
        road_hi: np.ndarray | None = None,
    ) -> AvoidanceTerms:
        """Obstacle terms for the horizon starting at time ``t_s`` [s].

        x : (nx,) measured state; Xlin : (N+1, nx) linearization trajectory (row k for x_k);
        s_arr : (N+1,) horizon reference arc lengths [m]; memory : passing sides, updated;
        road_lo, road_hi : (N,) the road's bounds of steps 1..N [m] (``Road.bounds``), which the
        corridor narrows (None: no road)."""
        cfg = self.config
        rel = self.relevant(t_s, x[:2])
        boxes, centers, world, packed = self._tracks(rel, t_s, s_arr)
        sides, following, ahead, box, side = self._decide(rel, boxes, packed, x, s_arr, memory)
        memory.sides.update(sides)
        # horizon steps 1..N at which each obstacle exists (its lifetime)
        times = t_s + self.dt_s * np.arange(1, self.N + 1) if any(self.obstacles[j].has_lifetime for j in rel) else None
        present = {j: self.obstacles[j].present(times) if self.obstacles[j].has_lifetime else self._always for j in rel}
        if following and any(sides[j] == SIDE_BLOCKED and j not in following and ahead[j] for j in rel):
            # braking for an obstacle ahead: keeping clear of a car following is its driver's job
            # (its keep-ahead row would forbid the braking)
            present.update({j: np.zeros(self.N, bool) for j in following})
        rows_a = rows_b = lo = hi = H = g = e_ref = None
        use = self._not_following(rel, following)
        if cfg.detour == "trapezoid":
            e_ref = self._detour(s_arr, box, side, use)
        if cfg.formulation == "hard":
            rows_a, rows_b = self._hard_rows(
                Xlin, s_arr, rel, boxes, centers, world, sides, present, following, packed, ahead
            )
        elif cfg.formulation == "corridor":
            pres = self._presence(rel, present)
            lo, hi, rows_a, rows_b = self._corridor(Xlin, s_arr, rel, box, side, use, pres, ahead, road_lo, road_hi)
        else:
            H, g = position_cost(cfg, self.path, Xlin, rel, boxes, centers, present, self._H, self._g)
        s_max = None if cfg.follow_gap_s is None else self._stop_lines(rel, boxes, sides, ahead, gap_s=cfg.follow_gap_s)
        return AvoidanceTerms(rows_a, rows_b, lo, hi, H, g, e_ref, sides, s_max)

    @property
    def stop_distance_m(self) -> float:
        """Arc length [m] between an obstacle's near end and the reference point of a car held
        back by the stop constraint: the front disc's clearance (hard) or margin plus half the
        body (corridor)."""
        if self.config.formulation == "hard":
            return self.r_disc + self.config.margin_m + self._max_offset
        return self.config.margin_m + self.half_length

    def _stop_lines(self, rel, boxes, sides, ahead, *, gap_s: float) -> np.ndarray | None:
        """(N+1,) furthest reference arc lengths behind the blocking obstacles ahead (or None)."""
        s_max = None
        dt, gap = self.dt_s, gap_s
        for j in rel:
            if sides[j] != SIDE_BLOCKED or not ahead[j]:
                continue
            s_lo = boxes[j].s_lo
            v = np.maximum(np.diff(s_lo) / dt, 0.0)
            v = np.append(v, v[-1]) if len(v) else np.zeros(1)
            line = s_lo - self.stop_distance_m - gap * v
            s_max = line if s_max is None else np.minimum(s_max, line)
        return s_max

    def sigma_inv(self, heading_rad: float) -> np.ndarray:
        """Sigma^-1 of eq. 56 in the world frame, sx along and sy across the path heading."""
        return sigma_inv(self.config.sigma_m, heading_rad)

    def _nearest(self, P: np.ndarray, rel: list[int], centers, outlines) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances (n, R, K) and nearest boundary points (n, R, K, 2) of points P (R, K, 2)
        to the n obstacles ``rel``, point ``P[r, k]`` at horizon time k + 1 (rows 1..N of
        ``centers[j]`` and, for a polygon, of its world vertices ``outlines[j]``)."""
        R, K = P.shape[:2]
        dist = np.empty((len(rel), R, K))
        q = np.empty((len(rel), R, K, 2))
        groups: dict[int, list[int]] = {}  # circles (0) and polygons by vertex count
        for i, j in enumerate(rel):
            o = outlines[j]
            groups.setdefault(0 if o is None else o.shape[1], []).append(i)
        for kind, idx in groups.items():
            js = [rel[i] for i in idx]
            if kind == 0:
                C = np.stack([centers[j][1:] for j in js])[:, None]
                r = np.array([_radius(self.obstacles[j]) for j in js])[:, None, None]
                v = P[None] - C
                n = np.maximum(np.hypot(v[..., 0], v[..., 1]), 1e-12)
                dist[idx] = n - r
                q[idx] = C + r[..., None] * v / n[..., None]
                continue
            polys = np.stack([outlines[j][1:] for j in js])[:, None]  # (g, 1, K, M, 2)
            polys = np.broadcast_to(polys, (len(js), R, K, kind, 2)).reshape(-1, kind, 2)
            pts = np.broadcast_to(P[None], (len(js), R, K, 2)).reshape(-1, 2)
            d, qq = points_polygons(pts, polys)
            dist[idx] = d.reshape(len(js), R, K)
            q[idx] = qq.reshape(len(js), R, K, 2)
        return dist, q

    def _lin_arc_lengths(self, Xlin: np.ndarray, s0: float) -> np.ndarray:
        """(N,) arc lengths [m] of the linearization trajectory's steps 1..N: ``s0`` plus the
        distance travelled along it (the car stays near the path: :func:`~mpcdrive.scene.road.lin_arc_lengths`)."""
        return lin_arc_lengths(Xlin, s0)[1:]

    def _stop_plane(
        self, s_lo: np.ndarray, s_at: np.ndarray, clearance: float, *, ahead: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """The stop constraint ``s(p) <= s_lo - clearance`` linearized at arc length
        ``min(s_at, s_lo - clearance)`` (s_at: where the point is expected): unit tangents t
        (K, 2) and points q (K, 2) with the constraint ``t . p <= t . q - clearance``. Linearizing
        where the car is, not at the obstacle, keeps the half-plane across the car's own road
        where the path bends (a plane through a bend further on would let the car gain ground by
        moving sideways). With ``ahead``, its mirror, the keep-ahead constraint ``s(p) >= s_lo +
        clearance`` (``s_lo`` then the far end of a car behind) linearized at ``max(s_at, s_lo +
        clearance)``: ``t . p >= t . q + clearance``."""
        s_bar = np.maximum(s_at, s_lo + clearance) if ahead else np.minimum(s_at, s_lo - clearance)
        h = np.asarray(self.path.heading(s_bar), float)
        t = np.column_stack([np.cos(h), np.sin(h)])
        return t, self.path.position(s_bar) + t * (s_lo - s_bar)[:, None]

    def _hard_rows(self, Xlin, s_arr, rel, boxes, centers, world, sides, present, following, packed, ahead):
        """The hard rows (N, M, 3), (N, M) of the obstacles ``rel``: compiled on a path
        ``path_arrays`` describes (``packed``: the tracks as :meth:`_packed` gives them, made
        from the others when None), else :meth:`_hard_rows_numpy`."""
        cpath = self._compiled_path()
        if cpath is None:
            return self._hard_rows_numpy(Xlin, s_arr, rel, boxes, centers, world, sides, present, following, ahead)
        a, b = self._a, self._b
        if packed is None:
            packed = self._packed(rel, boxes, centers, world)
        side, mode = step_modes(rel, sides, following, ahead, self.relations, self.N)
        pres = self._presence(rel, present)
        shape, radius, centers_a, outlines_a, nverts, box = packed
        _ac.hard_rows(
            cpath.kind,
            cpath.geo,
            cpath.tab_s,
            cpath.tab_xy,
            cpath.tab_h,
            cpath.tab_k,
            Xlin,
            s_arr,
            np.asarray(self.offsets, float),
            float(self.r_disc),
            float(self.config.margin_m),
            float(self.half_length),
            float(self.config.influence_m),
            shape,
            radius,
            centers_a,
            outlines_a,
            nverts,
            box,
            side,
            mode,
            pres,
            float(self.stop_gap_m),
            a,
            b,
        )
        return a, b

    def _hard_rows_numpy(self, Xlin, s_arr, rel, boxes, centers, world, sides, present, following, ahead):
        a, b = self._a, self._b
        a[:] = 0.0
        b[:] = -np.inf
        if not rel:
            return a, b
        lin = Xlin[1:, :3]
        c, s = np.cos(lin[:, 2]), np.sin(lin[:, 2])
        nd = len(self.offsets)
        off = np.asarray(self.offsets, float)[:, None]  # (nd, 1): every disc at once, (nd, N) arrays
        r_need = self.r_disc + self.config.margin_m
        s_lin = self._lin_arc_lengths(Xlin, s_arr[0])
        P = lin[None, :, :2] + off[..., None] * np.column_stack([c, s])[None]  # disc centres (nd, N, 2)
        s_disc = s_arr[None, 1:] + off
        # every considered obstacle at once: arrays (n_obs, nd, N[, 2]), obstacle i in row slot i
        side_k, mode_k = step_modes(rel, sides, following, ahead, self.relations, self.N)
        side = side_k.astype(float)[:, None, :]
        s_lo, s_hi, s_ref, e_lo, e_hi = (
            np.stack([getattr(boxes[j], f)[1:] for j in rel])[:, None, :]
            for f in ("s_lo", "s_hi", "s_ref", "e_lo", "e_hi")
        )
        e_edge = np.where(side == SIDE_LEFT, e_hi, e_lo)
        # lateral from half a car length before a moving obstacle (a hedge on its prediction);
        # before a standing one from where the disc may reach its side by the next step
        ds = np.diff(np.concatenate([[s_arr[0]], s_lin]))
        moving = np.abs(np.stack([np.diff(boxes[j].s_ref) for j in rel]))[:, None, :] > _ac.STANDING_STEP_M
        reach = r_need + np.where(moving, self.half_length, np.minimum(self.half_length, ds))
        h = np.asarray(self.path.heading(s_ref), float)
        nl = np.stack([-np.sin(h), np.cos(h)], axis=-1)  # path left normal at the obstacle
        q_lat = self.path.position(s_ref) + nl * e_edge[..., None]
        dist, q = self._nearest(P, rel, centers, world)
        v = P[None] - q
        nv = np.maximum(np.hypot(v[..., 0], v[..., 1]), 1e-12)
        n = v / nv[..., None] * np.where(dist >= 0, 1.0, -1.0)[..., None]
        active = dist - self.r_disc <= self.config.influence_m
        # beside the obstacle where the plan has the disc (its reference may run far ahead of a
        # slow car: rows from it had a car creeping out behind a parked one swerve at 45 deg)
        s_near = s_lin[None, :] + off
        lateral = (np.abs(side) == 1) & (s_lo - reach <= s_near) & (s_near <= s_hi + reach)
        n = np.where(lateral[..., None], side[..., None] * nl, n)
        q = np.where(lateral[..., None], q_lat, q)
        active |= lateral
        for i in range(len(rel)):
            for md in (_ac.MODE_STOP, _ac.MODE_AHEAD):
                steps = mode_k[i] == md
                if not steps.any():
                    continue
                if md == _ac.MODE_STOP:  # behind its near end less the clearance
                    tb, qs = self._stop_plane(np.tile(s_lo[i, 0] - self.stop_gap_m, nd), (s_lin + off).ravel(), r_need)
                    nb = -tb.reshape(nd, -1, 2)
                else:  # ahead of its far end plus the clearance, never beyond the disc's reference
                    s_end = np.minimum(np.tile(s_hi[i, 0], nd), (s_disc - r_need).ravel())
                    tb, qs = self._stop_plane(s_end, (s_lin + off).ravel(), r_need, ahead=True)
                    nb = tb.reshape(nd, -1, 2)
                n[i][:, steps] = nb[:, steps]
                q[i][:, steps] = qs.reshape(nd, -1, 2)[:, steps]
                active[i][:, steps] = True
        active &= np.stack([present[j] for j in rel])[:, None, :]  # no row at the steps the obstacle does not exist
        # n . (p + J (x - xbar)) >= n . q + r_need, J = d p / d (x, y, yaw)
        ay = off * (-n[..., 0] * s + n[..., 1] * c)
        rhs = (
            np.einsum("odki,odki->odk", n, q)
            + r_need
            - np.einsum("odki,dki->odk", n, P)
            + n[..., 0] * lin[:, 0]
            + n[..., 1] * lin[:, 1]
            + ay * lin[:, 2]
        )
        m = len(rel) * nd  # row slot * nd + disc, as the obstacles come in rel

        def rows(v, fill):
            return np.where(active, v, fill).reshape(m, -1).T

        a[:, :m, 0] = rows(n[..., 0], 0.0)
        a[:, :m, 1] = rows(n[..., 1], 0.0)
        a[:, :m, 2] = rows(ay, 0.0)
        b[:, :m] = rows(rhs, -np.inf)
        return a, b

    def _not_following(self, rel, following) -> np.ndarray:
        """(n,) bool in the order of ``rel``: the obstacle is not a car following in the lane."""
        use = self._use[: len(rel)]
        for i, j in enumerate(rel):
            use[i] = j not in following
        return use

    def _presence(self, rel, present) -> np.ndarray:
        """(n, N) bool in the order of ``rel``: the obstacle exists at steps 1..N (``present``
        per obstacle; all true without lifetimes, without a copy)."""
        n = len(rel)
        if all(present[j] is self._always for j in rel):
            return self._present_all[:n]
        pres = self._present[:n]
        for i, j in enumerate(rel):
            pres[i] = present[j]
        return pres

    def _corridor(self, Xlin, s_arr, rel, box, side, use, pres, ahead, road_lo, road_hi):
        """The corridor formulation of one step for the obstacles ``rel`` (Frenet boxes ``box``,
        passing sides ``side``, ``use``: not a car following, ``pres``: presence, as
        :meth:`_decide`, :meth:`_not_following` and :meth:`_presence` give them): the lateral
        bounds (compiled: :func:`~mpcdrive.ocp.avoidance_compiled.corridor_bounds`) and the
        stop-before half-planes of the blocked obstacles ahead, one slot per obstacle used."""
        lo, hi = self._lo, self._hi
        if road_lo is None or road_hi is None:
            lo[:], hi[:] = -1e3, 1e3
        else:
            lo[:], hi[:] = road_lo, road_hi
        a, b = self._a, self._b
        a[:] = 0.0
        b[:] = -np.inf
        m = self.config.margin_m
        s_c = np.ascontiguousarray(s_arr, dtype=float)
        _ac.corridor_bounds(box, use, side, pres, s_c, m, self.half_length, self.half_width, lo, hi)
        s_lin = None
        slot = 0
        for i, j in enumerate(rel):
            if not use[i]:
                continue
            if side[i] == SIDE_BLOCKED and ahead[j]:
                # stop before it: s(p) <= s_lo - margin - half length, i.e. t . p <= t . q - that
                if s_lin is None:
                    s_lin = self._lin_arc_lengths(Xlin, s_arr[0])
                s_lo = box[i, _ac.BOX_S_LO]
                for k in range(1, self.N + 1):
                    if not pres[i, k - 1]:
                        continue
                    t, q = self._stop_plane(s_lo[k : k + 1], s_lin[k - 1 : k], m + self.half_length)
                    a[k - 1, slot, :2] = -t[0]
                    b[k - 1, slot] = -(t[0] @ q[0]) + m + self.half_length
            slot += 1
        return lo, hi, a, b

    def _detour(self, s_arr, box, side, use):
        """The paper's trapezoidal detour (compiled: :func:`~mpcdrive.ocp.avoidance_compiled.detour_offsets`)
        around the obstacles with Frenet boxes ``box`` passed on ``side`` where ``use`` (not a car
        following): the reference shifts sideways by the room each one needs, ramping over
        ``detour_ramp_m`` before and after it."""
        _ac.detour_offsets(
            box,
            use,
            side,
            np.ascontiguousarray(s_arr, dtype=float),
            self.half_width,
            self.half_length,
            self.config.margin_m,
            self.config.detour_ramp_m,
            self._e_ref,
        )
        return self._e_ref


def _radius(ob: Obstacle) -> float:
    """The radius [m] of a circle obstacle."""
    assert isinstance(ob.shape, Circle)
    return ob.shape.radius_m
