"""What the figure modules share: figures on the Agg canvas, atomic PNG writing, titles that
fit, colours, lane boundaries, obstacles drawn at their closest approach, and path coordinates
(s, e_y) for long roads. Read results, never solve.
"""

from __future__ import annotations

import io
import os
import textwrap
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mpcdrive.io.atomic import atomic_write_bytes
from mpcdrive.scene.geometry import road_edges
from mpcdrive.types import SimResult

DPI = 120
ITER_LABEL = "iteration k [-]"
REF_COLOR = "tab:blue"
DRIVEN_COLOR = "tab:red"
#: colours of several runs in one axes: never the reference path's blue
RUN_COLORS = (
    "tab:red",
    "tab:orange",
    "tab:green",
    "tab:purple",
    "tab:brown",
    "tab:pink",
    "tab:olive",
    "tab:cyan",
    "0.25",
)
OBSTACLE_COLOR = "0.35"
#: a map whose bounding box is longer than this many times its width gets a path-coordinate panel
LONG_ROAD_RATIO = 6.0


# --------------------------------------------------------------------------- figures and text
def new_figure(nrows: int = 1, ncols: int = 1, size=(7.0, 4.5), **kw) -> tuple[Figure, np.ndarray]:
    """A figure on its own Agg canvas (constrained layout) and its axes grid (always 2-D)."""
    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False, **kw)
    return fig, axes


def save(fig: Figure, path: str | os.PathLike) -> Path:
    """Render ``fig`` to PNG and write it atomically; return the path."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    fig.clear()  # drop artists now rather than at garbage collection
    return atomic_write_bytes(path, buf.getvalue())


def run_label(result: SimResult) -> str:
    """Short run name for titles from ``result.meta`` ('' when none is recorded)."""
    for key in ("id", "scenario_id", "scenario", "name"):
        value = result.meta.get(key)
        if isinstance(value, str) and value:
            return value
    return ""


def title_for(base: str, result: SimResult) -> str:
    name = run_label(result)
    return f"{base} — {name}" if name else base


def _wrap(text: str, width_in: float, fontsize_pt: float) -> str:
    # an average glyph is about 0.6 em wide; wrap at spaces (and after the dash of a run name)
    chars = max(12, int(width_in * 72.0 / (0.6 * fontsize_pt)))
    lines = []
    for para in str(text).split("\n"):
        lines.extend(textwrap.wrap(para, chars, break_long_words=True, break_on_hyphens=False) or [""])
    return "\n".join(lines)


def set_title(ax, text: str) -> None:
    """Axes title wrapped to the axes' width, so that a long run name is never cut off."""
    fig = ax.get_figure()
    ax.set_title(text)
    width_in = ax.get_position().width * fig.get_figwidth()
    ax.set_title(_wrap(text, width_in, ax.title.get_fontsize()))


def set_suptitle(fig: Figure, text: str) -> None:
    """Figure title wrapped to the figure's width."""
    t = fig.suptitle(text)
    t.set_text(_wrap(text, 0.95 * fig.get_figwidth(), t.get_fontsize()))


# --------------------------------------------------------------------------- geometry
def polyline_coordinates(path_xy: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(P, 2) path coordinates (s, e_y) [m] of ``points`` (P, 2) on the polyline ``path_xy``: the
    arc length of the nearest point and the signed distance to it (left positive)."""
    p = np.asarray(path_xy, float)
    q = np.atleast_2d(np.asarray(points, float))
    if len(p) < 2:
        return np.column_stack([np.zeros(len(q)), np.zeros(len(q))])
    d = np.diff(p, axis=0)
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    s0 = np.r_[0.0, np.cumsum(np.sqrt(dd))][:-1]
    out = np.empty((len(q), 2))
    for j, x in enumerate(q):
        r = x - p[:-1]
        t = np.clip(np.einsum("ij,ij->i", r, d) / dd, 0.0, 1.0)
        off = r - t[:, None] * d
        i = int(np.argmin(np.einsum("ij,ij->i", off, off)))
        seg = d[i] / np.sqrt(dd[i])
        out[j] = s0[i] + t[i] * np.sqrt(dd[i]), seg[0] * off[i, 1] - seg[1] * off[i, 0]
    return out


def aspect_ratio(*point_sets: np.ndarray) -> tuple[float, bool]:
    """(long side / short side, True when wider than tall) of the bounding box of the points."""
    pts = [np.asarray(p, float).reshape(-1, 2) for p in point_sets if np.size(p)]
    if not pts:
        return 1.0, True
    allp = np.vstack(pts)
    allp = allp[np.all(np.isfinite(allp), axis=1)]
    if not len(allp):
        return 1.0, True
    w, h = np.ptp(allp[:, 0]), np.ptp(allp[:, 1])
    long_side, short_side = max(w, h), min(w, h)
    return (float(long_side / short_side) if short_side > 1e-12 else np.inf), bool(w >= h)


# --------------------------------------------------------------------------- obstacles
def obstacle_outlines(entry: Mapping) -> list[np.ndarray]:
    """Closed outlines (M, 2) of a logged obstacle, one per logged time (one if static):
    ``{"type": "circle", "center": [x, y] | (T, 2), "radius_m": r}`` or
    ``{"type": "polygon", "points": (P, 2) | (T, P, 2)}``."""
    if entry.get("type") == "circle":
        c = np.atleast_2d(np.asarray(entry["center"], dtype=float))
        th = np.linspace(0.0, 2.0 * np.pi, 48)
        r = float(entry["radius_m"])
        return [np.column_stack([x + r * np.cos(th), y + r * np.sin(th)]) for x, y in c]
    p = np.asarray(entry.get("points", []), dtype=float)
    if p.ndim == 2:
        p = p[None]
    return [np.vstack([q, q[:1]]) for q in p]


def _point_outline_distance(x: np.ndarray, outline: np.ndarray) -> float:
    a, b = outline[:-1], outline[1:]
    d = b - a
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    t = np.clip(np.einsum("ij,ij->i", x - a, d) / dd, 0.0, 1.0)
    return float(np.min(np.hypot(*(x - a - t[:, None] * d).T)))


def closest_approach(outlines: list[np.ndarray], xy: np.ndarray) -> int:
    """Step k at which the logged vehicle position ``xy[k]`` is nearest to the obstacle outline
    of the same step (the moment a figure of a moving obstacle should show)."""
    n = min(len(outlines), len(xy))
    if n == 0:
        return 0
    dist = [_point_outline_distance(np.asarray(xy[k], float), outlines[k]) for k in range(n)]
    return int(np.argmin(dist))


def draw_obstacles(ax, result: SimResult, frenet_path_xy: np.ndarray | None = None, time_labels: bool = True) -> None:
    """Obstacles logged in ``result.meta["obstacles"]``: static ones filled; a moving one filled
    where it was at its closest approach to the vehicle, labelled with that time, the vehicle's
    position at that time marked, and the path of its centre dotted with an arrow (direction of
    motion). With ``frenet_path_xy`` everything is drawn in path coordinates (s, e_y) of that
    polyline instead of x, y; ``time_labels=False`` leaves the times out (a map strip whose
    path-coordinate panel shows them)."""
    xy = np.asarray(result.xy, float)
    t = np.asarray(result.t_s, float)
    to_plot = (
        (lambda pts: polyline_coordinates(frenet_path_xy, pts))
        if frenet_path_xy is not None
        else (lambda pts: np.asarray(pts, float))
    )
    first_static = first_moving = True
    for entry in result.meta.get("obstacles") or []:
        outlines = obstacle_outlines(entry)
        if not outlines:
            continue
        if len(outlines) == 1:
            o = to_plot(outlines[0])
            ax.fill(
                o[:, 0],
                o[:, 1],
                color=OBSTACLE_COLOR,
                alpha=0.8,
                zorder=2.5,
                label="obstacle" if first_static else None,
            )
            first_static = False
            continue
        k = closest_approach(outlines, xy)
        centres = to_plot(np.array([o[:-1].mean(axis=0) for o in outlines]))
        ax.plot(
            centres[:, 0],
            centres[:, 1],
            color="0.4",
            lw=0.8,
            ls=":",
            zorder=2.4,
            label="moving obstacle's track" if first_moving else None,
        )
        if len(centres) >= 2 and np.hypot(*(centres[-1] - centres[-2])) > 0:
            ax.annotate(
                "",
                xy=centres[-1],
                xytext=centres[-2],
                zorder=2.4,
                arrowprops={"arrowstyle": "-|>", "color": "0.4", "lw": 0.8},
            )
        o = to_plot(outlines[k])
        ax.fill(
            o[:, 0],
            o[:, 1],
            facecolor="0.75",
            edgecolor="0.15",
            lw=1.0,
            alpha=0.9,
            zorder=2.5,
            label="moving obstacle at closest approach" if first_moving else None,
        )
        if k < len(xy) and time_labels:
            ego = to_plot(xy[k : k + 1])[0]
            ax.plot(
                ego[0],
                ego[1],
                "o",
                mfc="white",
                mec="k",
                ms=5,
                zorder=4.5,
                label="vehicle at that time" if first_moving else None,
            )
            # the time label on the obstacle's side away from the vehicle
            centre = o[:-1].mean(axis=0)
            away = centre - ego
            away = away / np.hypot(*away) if np.hypot(*away) > 1e-12 else np.array([0.0, 1.0])
            label_at = o[int(np.argmax((o - centre) @ away))]
            ax.annotate(
                f"t = {t[min(k, len(t) - 1)]:.1f} s",
                xy=label_at,
                xytext=tuple(5.0 * away),
                textcoords="offset points",
                fontsize="small",
                zorder=5,
                ha="left" if away[0] > 0.3 else "right" if away[0] < -0.3 else "center",
                va="bottom" if away[1] > 0.3 else "top" if away[1] < -0.3 else "center",
            )
        first_moving = False


def result_road_edges(result) -> tuple[np.ndarray, np.ndarray] | None:
    """(left, right) road edge polylines (M, 2) [m] of a run (its ``road_profile`` along its
    ``path_xy``), or None without a road."""
    path = np.asarray(result.path_xy, dtype=float)
    if result.road_profile is None or path.ndim != 2 or path.shape[0] < 2:
        return None
    return road_edges(path, result.road_profile)
