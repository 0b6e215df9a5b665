"""Generator of the packaged tracks (1:10 scale, for the F1TENTH-class car).

A track is a sequence of straights and corners; each corner is a clothoid (curvature rising
linearly from 0), a circular arc of the corner's radius and a clothoid back to 0, so the curvature
is continuous as on real roads (a spline through the waypoints then reproduces it without ringing).
The curvature profile is integrated with a fine step and sampled every ``DS_M`` metres; the CSV
holds ``x_m, y_m, w_tr_right_m, w_tr_left_m``. Run ``python -m mpcdrive.scenarios.tracks.generate
[DIR]`` to rewrite the files (default: next to this module); a test checks the shipped files equal
this output.

* ``raceway``: closed race-track-like loop (about 54 m, corners of radius 1.6 m to 3 m including a
  left-right chicane, 1.6 m wide). It follows a polygon whose corners are rounded, so it closes
  by construction.
* ``hairpins``: open mountain road (about 60 m): an S-bend, then three 180-degree hairpins of radius
  2.25 m -- about three times the F1TENTH car's minimum turning radius of 0.74 m -- 1.4 m wide.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from ...paths.tracks import write_track_csv

DS_M = 0.1  # waypoint spacing [m]
_FINE_M = 0.001  # integration step [m]

#: closed polygon of the raceway [m] and the corner radius at each vertex [m]
RACEWAY_VERTICES = [
    (0.0, 0.0),
    (14.0, 0.0),
    (17.0, 6.0),
    (12.0, 8.5),
    (8.0, 6.0),
    (4.0, 10.0),
    (-4.0, 9.0),
    (-4.0, 2.0),
]
RACEWAY_RADII = [2.0, 3.0, 2.0, 1.6, 2.5, 2.0, 2.5, 1.6]

#: the hairpin road: ("S", length m) straights and ("C", radius m, turn deg) corners
HAIRPIN_SEGMENTS = [
    ("S", 6.0),
    ("C", 4.0, 30.0),
    ("C", 4.0, -30.0),
    ("S", 3.0),
    ("C", 2.25, 180.0),
    ("S", 8.0),
    ("C", 2.25, -180.0),
    ("S", 8.0),
    ("C", 2.25, 180.0),
    ("S", 6.0),
]

WIDTHS_M = {"raceway": 1.6, "hairpins": 1.4}
DESCRIPTIONS = {
    "raceway": "closed race-track-like loop, corner radii 1.6-3.0 m with clothoid transitions, chicane, 1.6 m wide",
    "hairpins": "open road: an S-bend, then three 180-degree hairpins of radius 2.25 m, 1.4 m wide",
}


def clothoid_length(radius_m: float, turn_rad: float) -> float:
    """Length [m] of each transition clothoid of a corner: 35 % of the corner's arc length, at most 1.5 m."""
    return min(0.35 * radius_m * abs(turn_rad), 1.5)


def corner_pieces(radius_m: float, turn_rad: float) -> list[tuple[float, float, float]]:
    """Curvature pieces (length m, kappa at start, kappa at end) of a clothoid-arc-clothoid corner."""
    k = math.copysign(1.0 / radius_m, turn_rad)
    lc = clothoid_length(radius_m, turn_rad)
    arc = radius_m * abs(turn_rad) - lc  # the two clothoids turn lc / r together
    return [(lc, 0.0, k), (arc, k, k), (lc, k, 0.0)]


def integrate(pieces, ds_m: float = DS_M, closed: bool = False) -> np.ndarray:
    """Points (M, 2) [m] every ~``ds_m`` along piecewise-linear curvature ``pieces`` starting at the
    origin heading east (the last point is dropped on a closed track)."""
    s_parts, k_parts = [np.zeros(1)], [np.zeros(1)]
    s0 = 0.0
    for length, k0, k1 in pieces:
        if length <= 0:
            continue
        n = max(1, int(math.ceil(length / _FINE_M)))
        t = np.arange(1, n + 1) / n
        s_parts.append(s0 + length * t)
        k_parts.append(k0 + (k1 - k0) * t)
        s0 += length
    s = np.concatenate(s_parts)
    k = np.concatenate(k_parts)
    k[0] = pieces[0][1]
    ds = np.diff(s)
    h = np.r_[0.0, np.cumsum(0.5 * (k[1:] + k[:-1]) * ds)]
    # positions: trapezoid on cos/sin of the heading (error ~ ds^2 kappa^2 / 12 per metre)
    x = np.r_[0.0, np.cumsum(0.5 * (np.cos(h[1:]) + np.cos(h[:-1])) * ds)]
    y = np.r_[0.0, np.cumsum(0.5 * (np.sin(h[1:]) + np.sin(h[:-1])) * ds)]
    n_out = max(2, int(round(s[-1] / ds_m)))
    s_out = np.linspace(0.0, s[-1], n_out + 1)
    pts = np.column_stack([np.interp(s_out, s, x), np.interp(s_out, s, y)])
    return pts[:-1] if closed else pts


def _corner_setback(radius_m: float, turn_rad: float) -> float:
    """Distance [m] from a polygon vertex back to where its symmetric corner starts."""
    pts = integrate(corner_pieces(radius_m, turn_rad), ds_m=_FINE_M * 10)
    xe, ye = pts[-1]
    return float(xe - ye / math.tan(turn_rad))


def polygon_pieces(vertices, radii) -> list[tuple[float, float, float]]:
    """Curvature pieces of the closed polygon ``vertices`` with rounded corners, starting in the
    middle of the edge from vertex 0 to vertex 1."""
    P = np.asarray(vertices, float)
    n = len(P)
    heading = [math.atan2(*(P[(i + 1) % n] - P[i])[::-1]) for i in range(n)]
    turn = [math.remainder(heading[i] - heading[i - 1], 2 * math.pi) for i in range(n)]
    back = [_corner_setback(radii[i], turn[i]) for i in range(n)]
    edge = [float(np.hypot(*(P[(i + 1) % n] - P[i]))) for i in range(n)]
    straight = [edge[i] - back[i] - back[(i + 1) % n] for i in range(n)]
    bad = [i for i in range(n) if straight[i] < 0]
    if bad:
        raise ValueError(f"polygon edge(s) {bad} too short for their corners")
    pieces = [(0.5 * edge[0] - back[1], 0.0, 0.0)]
    for i in range(1, n + 1):
        pieces += corner_pieces(radii[i % n], turn[i % n])
        if i < n:
            pieces.append((straight[i], 0.0, 0.0))
    pieces.append((0.5 * edge[0] - back[0], 0.0, 0.0))
    return pieces


def segment_pieces(segments) -> list[tuple[float, float, float]]:
    """Curvature pieces of ("S", length) / ("C", radius, turn_deg) segments."""
    pieces = []
    for seg in segments:
        if seg[0] == "S":
            pieces.append((float(seg[1]), 0.0, 0.0))
        else:
            pieces += corner_pieces(float(seg[1]), math.radians(seg[2]))
    return pieces


def track_points(name: str) -> np.ndarray:
    """Waypoints (M, 2) [m] of the packaged track ``name``, starting at (0, 0) heading east."""
    if name == "raceway":
        pts = integrate(polygon_pieces(RACEWAY_VERTICES, RACEWAY_RADII), closed=True)
    elif name == "hairpins":
        pts = integrate(segment_pieces(HAIRPIN_SEGMENTS))
    else:
        raise ValueError(f"unknown track {name!r}")
    return np.round(pts, 5) + 0.0


def write_tracks(out_dir: Path) -> list[Path]:
    """Write every packaged track as ``out_dir/<name>.csv``; return the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, width in WIDTHS_M.items():
        f = out_dir / f"{name}.csv"
        write_track_csv(
            f,
            track_points(name),
            0.5 * width,
            0.5 * width,
            comment=f"mpcdrive packaged track {name!r}: {DESCRIPTIONS[name]}\n"
            "generated by python -m mpcdrive.scenarios.tracks.generate",
        )
        written.append(f)
    return written


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    out = Path(args[0]) if args else Path(__file__).parent
    for f in write_tracks(out):
        print(f"wrote {f}")


if __name__ == "__main__":
    main()
