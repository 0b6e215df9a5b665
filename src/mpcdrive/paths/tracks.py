"""Tracks from CSV waypoint files: a centre line and the road widths on either side.

The format is the one F1TENTH race-track files use: a header naming the columns (optionally
behind ``#``), then one waypoint a line::

    # x_m, y_m, w_tr_right_m, w_tr_left_m
    0.0, 0.0, 0.8, 0.8
    ...

``x_m``, ``y_m`` [m] are required; ``w_tr_right_m``, ``w_tr_left_m`` [m] (road width to the
right / left of the centre line) are optional but come together; other columns are ignored.
The delimiter is ``,`` or ``;``. A loop whose last point lies near its first is closed unless
told otherwise. Bad files raise ``ValueError`` naming the file, line and column.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path as FsPath

import numpy as np

from .waypoints import WaypointPath

REQUIRED = ("x_m", "y_m")
WIDTHS = ("w_tr_right_m", "w_tr_left_m")


@dataclass(frozen=True, eq=False)
class Track:
    """A road: centre line ``path`` and widths to its right / left at the waypoints.

    points : (M, 2) waypoints [m]; s_points_m : (M,) their arc lengths on the path [m];
    width_right_m, width_left_m : (M,) [m] or None when the file has no widths.
    """

    name: str
    path: WaypointPath
    points: np.ndarray
    s_points_m: np.ndarray
    width_right_m: np.ndarray | None
    width_left_m: np.ndarray | None

    @property
    def closed(self) -> bool:
        return self.path.closed

    @property
    def has_widths(self) -> bool:
        return self.width_right_m is not None

    def _widths(self) -> tuple[np.ndarray, np.ndarray]:
        """(right, left) widths at the waypoints; a ValueError for a track without widths."""
        if self.width_right_m is None or self.width_left_m is None:
            raise ValueError(f"track {self.name!r} has no road widths")
        return self.width_right_m, self.width_left_m

    def widths_at(self, s_m) -> tuple[np.ndarray, np.ndarray]:
        """(right, left) road widths [m] at arc length(s) s_m [m], linearly interpolated."""
        wr, wl = self._widths()
        s = np.asarray(s_m, float)
        sp = self.s_points_m
        if self.closed:
            L = self.path.length_m
            s = np.mod(s, L)
            sp = np.r_[sp, L]
            wr = np.r_[wr, wr[0]]
            wl = np.r_[wl, wl[0]]
        return np.interp(s, sp, wr), np.interp(s, sp, wl)

    @property
    def min_half_width_m(self) -> float | None:
        """Narrowest distance from the centre line to a road edge [m] (None without widths)."""
        if not self.has_widths:
            return None
        wr, wl = self._widths()
        return float(min(wr.min(), wl.min()))

    def boundaries(self, ds_m: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(left, right) road edges (K, 2) [m] along one traversal, for plots."""
        n = max(2, int(math.ceil(self.path.length_m / (ds_m or self.path.length_m / 600))) + 1)
        s = np.linspace(0.0, self.path.length_m, n)
        p = self.path.position(s)
        h = self.path.heading(s)
        nrm = np.stack([-np.sin(h), np.cos(h)], axis=-1)
        wr, wl = self.widths_at(s)
        return p + wl[:, None] * nrm, p - wr[:, None] * nrm


def _fail(file: str, line: int | None, column: str | None, problem: str):
    where = file
    if line is not None:
        where += f": line {line}"
    if column is not None:
        where += f": column {column}"
    raise ValueError(f"{where}: {problem}")


def _parse(text: str, file: str) -> tuple[np.ndarray, np.ndarray | None, list[int]]:
    lines = [(i + 1, ln.strip()) for i, ln in enumerate(text.splitlines())]
    lines = [(i, ln) for i, ln in lines if ln]
    if not lines:
        _fail(file, None, None, "empty file (expected a header naming x_m, y_m and one waypoint a line)")
    # leading comment lines; the header is the first line naming x_m (or the first non-comment line)
    h = 0
    while h < len(lines) - 1 and lines[h][1].startswith("#") and "x_m" not in lines[h][1]:
        h += 1
    hline, header = lines[h]
    lines = lines[h:]
    header = header.lstrip("#").strip()
    delim = ";" if ";" in header else ","
    cols = [c.strip() for c in header.split(delim)]
    missing = [c for c in REQUIRED if c not in cols]
    if missing:
        _fail(
            file,
            hline,
            None,
            f"header must name the columns {', '.join(REQUIRED)} (found: {', '.join(cols)}); "
            f"missing {', '.join(missing)}",
        )
    dup = sorted({c for c in cols if cols.count(c) > 1 and c})
    if dup:
        _fail(file, hline, None, f"duplicate column(s) {', '.join(dup)}")
    has_w = [c in cols for c in WIDTHS]
    if any(has_w) and not all(has_w):
        _fail(file, hline, None, f"give both {WIDTHS[0]} and {WIDTHS[1]} or neither")
    wanted = list(REQUIRED) + (list(WIDTHS) if all(has_w) else [])
    idx = [cols.index(c) for c in wanted]
    rows, row_lines = [], []
    for ln_no, ln in lines[1:]:
        if ln.startswith("#"):
            continue
        parts = [p.strip() for p in ln.split(delim)]
        if len(parts) != len(cols):
            _fail(file, ln_no, None, f"expected {len(cols)} values ({', '.join(cols)}), got {len(parts)}")
        row = []
        for c, j in zip(wanted, idx):
            try:
                val = float(parts[j])
            except ValueError:
                _fail(file, ln_no, c, f"not a number: {parts[j]!r}")
            if not math.isfinite(val):
                _fail(file, ln_no, c, f"not finite: {parts[j]!r}")
            if c in WIDTHS and val <= 0:
                _fail(file, ln_no, c, f"road width must be positive, got {val}")
            row.append(val)
        rows.append(row)
        row_lines.append(ln_no)
    if len(rows) < 3:
        _fail(file, None, None, f"need at least 3 waypoints, got {len(rows)}")
    data = np.array(rows)
    return data[:, :2], (data[:, 2:4] if data.shape[1] == 4 else None), row_lines


def load_track_csv(
    file: str | os.PathLike, *, closed: bool | None = None, smoothing: float = 0.0, name: str | None = None
) -> Track:
    """Read a CSV waypoint file into a :class:`Track`.

    closed : True / False, or None to decide from the data (closed when the last point lies within
    three median waypoint spacings of the first); smoothing : spline smoothing factor (see
    :class:`~mpcdrive.paths.WaypointPath`). Raises ValueError naming file, line and column.
    """
    fname = os.fspath(file)
    try:
        text = FsPath(fname).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValueError(f"{fname}: track file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{fname}: cannot read track file ({e})") from None
    return track_from_text(text, fname, closed=closed, smoothing=smoothing, name=name or FsPath(fname).stem)


def track_from_text(
    text: str, source: str, *, closed: bool | None = None, smoothing: float = 0.0, name: str = "track"
) -> Track:
    """Parse CSV ``text`` (``source`` names it in errors) into a :class:`Track`."""
    pts, widths, row_lines = _parse(text, source)
    step = np.hypot(*np.diff(pts, axis=0).T)
    if np.any(step < 1e-9):
        i = int(np.argmax(step < 1e-9))
        _fail(source, row_lines[i + 1], None, f"waypoint repeats the previous one (line {row_lines[i]})")
    gap = float(np.hypot(*(pts[-1] - pts[0])))
    if closed is None:
        closed = gap < 3.0 * float(np.median(step))
    if closed and gap < 1e-9:  # a repeated first point closes the loop explicitly
        pts = pts[:-1]
        widths = None if widths is None else widths[:-1]
    try:
        path = WaypointPath(pts, closed=bool(closed), smoothing=smoothing)
    except ValueError as e:
        raise ValueError(f"{source}: {e}") from None
    # arc length of each waypoint (the spline passes through them, starting at the first):
    # sequential projection near the previous one
    s_pts = np.zeros(len(pts))
    window = max(1.0, 3.0 * float(step.max()))
    for i in range(1, len(pts)):
        s_pts[i], _ = path.project(pts[i], s_pts[i - 1], window_m=window)
        if s_pts[i] <= s_pts[i - 1]:
            _fail(
                source,
                row_lines[i],
                None,
                "waypoint does not advance along the track (reversing or self-overlapping waypoints)",
            )
    return Track(
        name=name,
        path=path,
        points=pts,
        s_points_m=s_pts,
        width_right_m=None if widths is None else widths[:, 0].copy(),
        width_left_m=None if widths is None else widths[:, 1].copy(),
    )


def write_track_csv(
    file: str | os.PathLike, points, width_right_m=None, width_left_m=None, comment: str | None = None
) -> None:
    """Write waypoints (M, 2) [m] and optional widths (M,) [m] in the format :func:`load_track_csv` reads."""
    pts = np.asarray(points, float)
    lines = []
    if comment:
        lines += [f"# {c}" for c in comment.splitlines()]
    if width_right_m is None:
        lines.append("# x_m, y_m")
        lines += [f"{x:.5f}, {y:.5f}" for x, y in pts]
    else:
        wr = np.broadcast_to(np.asarray(width_right_m, float), (len(pts),))
        wl = np.broadcast_to(np.asarray(width_left_m, float), (len(pts),))
        lines.append("# x_m, y_m, w_tr_right_m, w_tr_left_m")
        lines += [f"{x:.5f}, {y:.5f}, {a:.5f}, {b:.5f}" for (x, y), a, b in zip(pts, wr, wl)]
    FsPath(file).write_text("\n".join(lines) + "\n", encoding="utf-8")
