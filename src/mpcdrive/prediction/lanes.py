"""Lanes for prediction: centre lines with their successors, a car matched to the lane it drives
in and followed along it.

A :class:`LaneMap` holds lanes as centre polylines ``(M, 2)`` [m] in driving direction, each with
the ids of the lanes it continues into. :meth:`LaneMap.match` finds the lane a car at ``(x, y)``
heading ``yaw`` drives in (its centre line within reach, its direction within
``max_heading_rad``); :meth:`LaneMap.follow` walks from there along the lane and its successors
(at a fork the straightest one, the lane going on with its road: the car's turn is not
observable) and gives positions and headings at the requested distances. numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: the matching grid's cell [m], and how far beyond a cell its segments reach [m] (more than
#: any half width plus reach a match accepts: a wider lane is matched against every segment)
CELL_M = 25.0
GRID_PAD_M = 6.0


@dataclass(frozen=True, eq=False)
class Lane:
    """A lane: ``centre`` (M, 2) [m] in driving direction (M >= 2, consecutive points distinct),
    ``successors`` the ids of the lanes it continues into, ``half_width_m`` [m]."""

    id: int
    centre: np.ndarray
    successors: tuple[int, ...] = ()
    half_width_m: float = 1.75

    def __post_init__(self):
        c = np.asarray(self.centre, float)
        if c.ndim != 2 or c.shape[1] != 2 or len(c) < 2 or not np.all(np.isfinite(c)):
            raise ValueError(f"lane {self.id}: centre must be at least 2 finite points (M, 2), got shape {c.shape}")
        keep = np.r_[True, np.hypot(*np.diff(c, axis=0).T) > 1e-9]
        c = c[keep]
        if len(c) < 2:
            raise ValueError(f"lane {self.id}: centre has zero length")
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "successors", tuple(int(s) for s in self.successors))
        if not (math.isfinite(self.half_width_m) and self.half_width_m > 0):
            raise ValueError(f"lane {self.id}: half_width_m must be positive, got {self.half_width_m}")

    @property
    def s_m(self) -> np.ndarray:
        """(M,) arc length at each centre point [m]."""
        return np.r_[0.0, np.cumsum(np.hypot(*np.diff(self.centre, axis=0).T))]

    @property
    def length_m(self) -> float:
        return float(self.s_m[-1])

    @property
    def turn_rad(self) -> float:
        """Absolute heading change from the lane's start to its end [rad] (0: straight)."""
        d = np.diff(self.centre, axis=0)
        h0, h1 = math.atan2(d[0, 1], d[0, 0]), math.atan2(d[-1, 1], d[-1, 0])
        return abs((h1 - h0 + math.pi) % (2.0 * math.pi) - math.pi)


@dataclass(frozen=True)
class LaneMatch:
    """Where a car is: ``lane`` id, arc length ``s_m`` along it [m], lateral offset ``e_y_m``
    (left positive) [m] and heading offset ``e_psi_rad`` from the lane's direction [rad]."""

    lane: int
    s_m: float
    e_y_m: float
    e_psi_rad: float


class LaneMap:
    """Lanes by id, with every centre segment stacked for matching a car against all at once."""

    def __init__(self, lanes) -> None:
        self.lanes: dict[int, Lane] = {}
        for lane in lanes:
            if lane.id in self.lanes:
                raise ValueError(f"lane id {lane.id} appears twice")
            self.lanes[lane.id] = lane
        if not self.lanes:
            raise ValueError("a lane map needs at least one lane")
        a, b, owner, s0, hw = [], [], [], [], []
        for lane in self.lanes.values():
            c, s = lane.centre, lane.s_m
            a.append(c[:-1])
            b.append(c[1:])
            owner.append(np.full(len(c) - 1, lane.id))
            s0.append(s[:-1])
            hw.append(np.full(len(c) - 1, lane.half_width_m))
        self._a, self._b = np.vstack(a), np.vstack(b)
        self._owner, self._s0, self._hw = np.concatenate(owner), np.concatenate(s0), np.concatenate(hw)
        d = self._b - self._a
        self._len = np.hypot(d[:, 0], d[:, 1])
        self._dir = d / self._len[:, None]
        self._heading = np.arctan2(d[:, 1], d[:, 0])
        self._lines: dict[tuple[int, float], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
        # a grid of CELL_M cells, each with the segments passing within GRID_PAD_M of it
        lo = np.minimum(self._a, self._b) - GRID_PAD_M
        hi = np.maximum(self._a, self._b) + GRID_PAD_M
        i0, i1 = np.floor(lo / CELL_M).astype(int), np.floor(hi / CELL_M).astype(int)
        cells: dict[tuple[int, int], list[int]] = {}
        for k in range(len(self._a)):
            for cx in range(i0[k, 0], i1[k, 0] + 1):
                for cy in range(i0[k, 1], i1[k, 1] + 1):
                    cells.setdefault((cx, cy), []).append(k)
        self._cells = {c: np.array(v, np.int64) for c, v in cells.items()}
        self._hw_max = float(self._hw.max())

    def match(
        self,
        x_m: float,
        y_m: float,
        yaw_rad: float,
        *,
        max_heading_rad: float = math.radians(45.0),
        reach_m: float = 1.0,
    ) -> LaneMatch | None:
        """The lane a car at ``(x_m, y_m)`` heading ``yaw_rad`` drives in: among the centre
        segments at most the lane's half width plus ``reach_m`` away whose direction is within
        ``max_heading_rad`` of the car's, the nearest (distance plus 2 m per radian of heading
        offset); None when no lane qualifies."""
        p = np.array([x_m, y_m], float)
        if self._hw_max + reach_m <= GRID_PAD_M:
            ix = self._cells.get((int(math.floor(x_m / CELL_M)), int(math.floor(y_m / CELL_M))))
            if ix is None:
                return None
        else:  # lanes wider than the grid's padding: every segment
            ix = np.arange(len(self._a))
        a, d, seg_len = self._a[ix], self._dir[ix], self._len[ix]
        rel = p - a
        t = np.clip(np.einsum("ij,ij->i", rel, d), 0.0, seg_len)
        foot = a + t[:, None] * d
        dist = np.hypot(*(p - foot).T)
        dpsi = (yaw_rad - self._heading[ix] + math.pi) % (2.0 * math.pi) - math.pi
        ok = (dist <= self._hw[ix] + reach_m) & (np.abs(dpsi) <= max_heading_rad)
        if not ok.any():
            return None
        score = np.where(ok, dist + 2.0 * np.abs(dpsi), np.inf)
        i = int(np.argmin(score))
        cross = d[i, 0] * rel[i, 1] - d[i, 1] * rel[i, 0]
        k = int(ix[i])
        return LaneMatch(int(self._owner[k]), float(self._s0[k] + t[i]), float(cross), float(dpsi[i]))

    def chain(self, lane_id: int, length_m: float) -> list[int]:
        """Lane ids from ``lane_id`` on, over successors (the one turning least at a fork; ids
        break ties), until they reach ``length_m`` [m] or a lane without a successor in the map;
        never a lane twice."""
        out = [lane_id]
        total = self.lanes[lane_id].length_m
        while total < length_m:
            nxt = [s for s in self.lanes[out[-1]].successors if s in self.lanes and s not in out]
            if not nxt:
                break
            best = min(nxt, key=lambda j: (self.lanes[j].turn_rad, j))
            out.append(best)
            total += self.lanes[best].length_m
        return out

    def follow(self, lane_id: int, s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (K, 2) [m] and headings (K,) [rad, continuous] at the arc lengths ``s_m`` (K,) [m] from
        the start of lane ``lane_id``, along it and its successors (:meth:`chain`); past the last
        lane the line goes on straight along its last direction."""
        s_m = np.asarray(s_m, float)
        P, cum, u, heading = self._line(lane_id, float(s_m.max(initial=0.0)))
        i = np.clip(np.searchsorted(cum, s_m, side="right") - 1, 0, len(u) - 1)
        xy = P[i] + (s_m - cum[i])[:, None] * u[i]
        return xy, heading[i]

    def _line(self, lane_id: int, length_m: float):
        """The joined centre line from lane ``lane_id`` over at least ``length_m`` [m] (kept per
        lane and 100 m of length): points, their arc lengths, unit segment directions, segment
        headings [rad] (unwrapped: continuous along the line)."""
        key = (lane_id, 100.0 * math.ceil(max(length_m, 1.0) / 100.0))
        hit = self._lines.get(key)
        if hit is None:
            ids = self.chain(lane_id, key[1])
            pts = [self.lanes[ids[0]].centre]
            for j in ids[1:]:
                c = self.lanes[j].centre
                # successors start where their predecessor ends: drop the shared point
                pts.append(c[1:] if np.hypot(*(c[0] - pts[-1][-1])) < 0.5 else c)
            P = np.vstack(pts)
            P = P[np.r_[True, np.hypot(*np.diff(P, axis=0).T) > 1e-9]]
            seg = np.diff(P, axis=0)
            seg_len = np.hypot(seg[:, 0], seg[:, 1])
            u = seg / seg_len[:, None]
            line = (P, np.r_[0.0, np.cumsum(seg_len)], u, np.unwrap(np.arctan2(u[:, 1], u[:, 0])))
            self._lines[key] = line
            return line
        return hit
