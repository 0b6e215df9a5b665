"""The planner's contact test: a disc of the car's body against an obstacle's predicted box, in
the path's Frenet frame, compiled (numba subroutines that :mod:`.checks` links in).

An obstacle's sample is its centre's arc length and offset, its Frenet box (half extents along
and across the path at its yaw to the path's heading: ``ob_hl``, ``ob_hw``) and its oriented box
(that yaw, and its own half length and width: ``ob_or``). A disc moving over a step is tested
against the Frenet box first (cheap, and it contains the oriented box), then against the oriented
box, the disc's way taken in the obstacle's frame: a car yawed to the path (turning across it, or
driving straight where the path bends) covers much less than its Frenet box (at 45 degrees, a
4.5 m by 1.8 m car's box is 4.5 m by 4.5 m).
"""

from __future__ import annotations

import math

from .._subroutine import subroutine


@subroutine
def _slab(t0, t1, p0, dp, b):
    """The part of the parameter interval [t0, t1] where ``|p0 + t dp| < b`` (empty: t0 > t1)."""
    if abs(dp) < 1e-12:
        return (t0, t1) if abs(p0) < b else (1.0, 0.0)
    ta, tb = (-b - p0) / dp, (b - p0) / dp
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@subroutine
def _segment_hits_box(x0, y0, x1, y1, bx, by):
    """Whether the segment (x0, y0)-(x1, y1) meets the box |x| < bx, |y| < by (slabs)."""
    t0, t1 = _slab(0.0, 1.0, x0, x1 - x0, bx)
    if t0 > t1:
        return False
    t0, t1 = _slab(t0, t1, y0, y1 - y0, by)
    return not t0 > t1


@subroutine
def _box_distance(x, y, bx, by):
    """Distance from the point (x, y) to the box |x| <= bx, |y| <= by (0 inside)."""
    dx = max(abs(x) - bx, 0.0)
    dy = max(abs(y) - by, 0.0)
    return math.sqrt(dx * dx + dy * dy)


@subroutine
def _swept_hit(x0, y0, x1, y1, bx, by, rn):
    """Whether a disc of radius ``rn`` moving from (x0, y0) to (x1, y1) comes within its radius of
    the box |x| <= bx, |y| <= by: the segment meets the box grown by the radius, and the disc's
    nearest approach (a segment no longer than the radius: its ends and middle) is within it."""
    if not _segment_hits_box(x0, y0, x1, y1, bx + rn, by + rn):
        return False
    if math.hypot(x1 - x0, y1 - y0) > rn:
        return True
    return (
        min(
            _box_distance(x0, y0, bx, by),
            _box_distance(0.5 * (x0 + x1), 0.5 * (y0 + y1), bx, by),
            _box_distance(x1, y1, bx, by),
        )
        < rn
    )


@subroutine
def _disc_meets(q0s, q0d, qs, qd, bl, bw, ob_or, o, k0, k1, rn):
    """Whether a disc of radius ``rn`` moving from (q0s, q0d) to (qs, qd) (along and across the
    path, relative to an obstacle's centre at the step before and at the step) comes within its
    radius of the obstacle: of its Frenet box of half extents ``bl``, ``bw`` over the step, and of
    its own box, turned by its yaw to the path (``ob_or[o, k0]`` and ``ob_or[o, k1]``: cos, sin,
    half length, half width at the two steps; the disc's way taken in the obstacle's frame)."""
    if not _swept_hit(q0s, q0d, qs, qd, bl, bw, rn):
        return False
    c0, s0, c1, s1 = ob_or[o, k0, 0], ob_or[o, k0, 1], ob_or[o, k1, 0], ob_or[o, k1, 1]
    u0, w0 = c0 * q0s + s0 * q0d, c0 * q0d - s0 * q0s
    u1, w1 = c1 * qs + s1 * qd, c1 * qd - s1 * qs
    return _swept_hit(u0, w0, u1, w1, ob_or[o, k1, 2], ob_or[o, k1, 3], rn)


@subroutine
def _beyond_box(s0, d0, s1, d1, reach, bl, bw):
    """Whether every point within ``reach`` of the segment (s0, d0)-(s1, d1) lies outside the box
    |s| < bl, |d| < bw, both ends being beyond the same one of its sides (each disc of the body
    lies within ``reach`` of its reference point: when this holds, no disc's swept segment meets
    the box)."""
    bl += reach + 1e-9
    bw += reach + 1e-9
    return (s0 > bl and s1 > bl) or (s0 < -bl and s1 < -bl) or (d0 > bw and d1 > bw) or (d0 < -bw and d1 < -bw)
