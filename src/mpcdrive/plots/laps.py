"""Figures of laps on tracks: trajectory coloured by speed, lateral acceleration, tracking error
of several controllers along the track (read results, never solve).

Like :mod:`mpcdrive.plots.figures` (whose helpers both take from :mod:`mpcdrive.plots.common`): each ``plot_*`` writes a PNG atomically and returns its path;
the matching ``_make_*`` builds the :class:`~matplotlib.figure.Figure` (Agg canvas, no pyplot).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from mpcdrive.paths.tracks import Track
from mpcdrive.plots.common import (
    DRIVEN_COLOR,
    LONG_ROAD_RATIO,
    RUN_COLORS,
    aspect_ratio,
    result_road_edges,
    new_figure,
    save,
    set_title,
    title_for,
)
from mpcdrive.sim.analysis import lateral_acceleration_mps2
from mpcdrive.types import SimResult

__all__ = ["plot_lateral_acceleration", "plot_speed_map", "plot_tracking_comparison"]


def _draw_road(ax, result: SimResult, track: Track | None) -> None:
    path = np.asarray(result.path_xy, float)
    ax.plot(path[:, 0], path[:, 1], color="0.6", lw=0.8, ls=":", label="centre line")
    if track is not None and track.has_widths:
        left, right = track.boundaries()
    else:
        edges = result_road_edges(result)
        if edges is None:
            return
        left, right = edges
    ax.plot(left[:, 0], left[:, 1], color="k", lw=1.0, label="road edge")
    ax.plot(right[:, 0], right[:, 1], color="k", lw=1.0)


def _make_speed_map(result: SimResult, track: Track | None = None, title: str | None = None) -> Figure:
    xy = np.asarray(result.xy, float)
    v = np.asarray(result.v_mps, float)
    ratio, wide = aspect_ratio(np.asarray(result.path_xy, float), xy)
    long_road = ratio > LONG_ROAD_RATIO
    if long_road:  # a strip at true scale, and the speed along the path below it
        map_h = float(np.clip(9.0 / ratio, 0.6, 2.5)) if wide else 4.0
        fig, axes = new_figure(2, 1, size=(11.0, map_h + 4.0), height_ratios=[map_h + 0.8, 3.0])
    else:
        fig, axes = new_figure(size=(8.0, 6.5))
    ax = axes[0, 0]
    _draw_road(ax, result, track)
    if xy.shape[0] >= 2:
        seg = np.stack([xy[:-1], xy[1:]], axis=1)
        lc = LineCollection(seg, cmap="viridis", linewidths=2.5)
        lc.set_array(0.5 * (v[:-1] + v[1:]))
        finite = v[np.isfinite(v)]
        if finite.size and np.ptp(finite) <= 1e-6 * max(1.0, float(np.max(np.abs(finite)))):
            lc.set_clim(float(finite[0]) - 0.5, float(finite[0]) + 0.5)  # constant speed: no offset noise
        ax.add_collection(lc)
        cb = fig.colorbar(lc, ax=ax, location="right" if not long_road else "top", shrink=1.0 if not long_road else 0.5)
        cb.formatter.set_useOffset(False)
        cb.update_ticks()
        cb.set_label("speed v [m/s]")
        ax.plot(xy[0, 0], xy[0, 1], "o", color="tab:green", ms=7, label="start")
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    set_title(ax, title if title is not None else title_for("Trajectory coloured by speed", result))
    ax.grid(True, alpha=0.3)
    if long_road:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", borderaxespad=0.0)
        ax_v = axes[1, 0]
        ax_v.plot(result.s_m, v, color=DRIVEN_COLOR, lw=1.4, label="speed")
        ax_v.ticklabel_format(axis="y", useOffset=False)
        finite = v[np.isfinite(v)]
        if finite.size and np.ptp(finite) < 0.1:
            ax_v.set_ylim(float(np.mean(finite)) - 0.5, float(np.mean(finite)) + 0.5)
        ax_v.set_xlabel("distance along the path s [m]")
        ax_v.set_ylabel("speed v [m/s]")
        set_title(ax_v, "Speed along the path")
        ax_v.grid(True, alpha=0.3)
    else:
        ax.legend(loc="best", fontsize="small")
    return fig


def _make_lateral_acceleration(result: SimResult, limit_mps2: float | None = None) -> Figure:
    fig, axes = new_figure()
    ax = axes[0, 0]
    ay = lateral_acceleration_mps2(result)
    ax.plot(result.s_m - result.s_m[0], ay, color=DRIVEN_COLOR, lw=1.2, label="lateral acceleration")
    if limit_mps2 is not None:
        ax.axhline(limit_mps2, color="k", ls="--", lw=1.0, label=f"limit ±{limit_mps2:.3g} m/s^2")
        ax.axhline(-limit_mps2, color="k", ls="--", lw=1.0)
    ax.set_xlabel("distance along the path s [m]")
    ax.set_ylabel("lateral acceleration a_y [m/s^2]")
    set_title(ax, title_for("Lateral acceleration", result))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


def _make_tracking_comparison(results: Mapping[str, SimResult], title: str | None = None) -> Figure:
    if not results:
        raise ValueError("plot_tracking_comparison needs at least one result")
    fig, axes = new_figure(2, 1, size=(9.0, 7.0), sharex=True)
    ax, ax_v = axes[0, 0], axes[1, 0]
    for i, (label, res) in enumerate(results.items()):
        s = res.s_m - res.s_m[0]
        color = RUN_COLORS[i % len(RUN_COLORS)]
        ax.plot(s, np.abs(res.e_y_m), lw=1.1, color=color, label=str(label))
        ax_v.plot(s, res.v_mps, lw=1.1, color=color, label=str(label))
    ax.set_ylabel("|e_y| [m]")
    set_title(ax, title or "Tracking error along the track")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    ax_v.set_xlabel("distance along the path s [m]")
    ax_v.set_ylabel("speed v [m/s]")
    ax_v.grid(True, alpha=0.3)
    return fig


def plot_speed_map(
    result: SimResult, path: str | os.PathLike, track: Track | None = None, title: str | None = None
) -> Path:
    """Driven trajectory coloured by speed [m/s] (colour bar), with the road edges of ``track`` (or
    the lane of the result) and the centre line. Writes a PNG; returns ``path``."""
    return save(_make_speed_map(result, track, title), path)


def plot_lateral_acceleration(result: SimResult, path: str | os.PathLike, limit_mps2: float | None = None) -> Path:
    """Lateral acceleration [m/s^2] along the path (from the logged positions), with +-``limit_mps2``
    dashed when given (e.g. mu g). Writes a PNG; returns ``path``."""
    return save(_make_lateral_acceleration(result, limit_mps2), path)


def plot_tracking_comparison(
    results: Mapping[str, SimResult], path: str | os.PathLike, title: str | None = None
) -> Path:
    """|e_y| [m] and speed [m/s] along the path of several runs keyed by label (e.g. controllers on
    the same track). Writes a PNG; returns ``path``."""
    return save(_make_tracking_comparison(results, title), path)
