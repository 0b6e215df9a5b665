"""Figures of laps on tracks: trajectory coloured by speed, lateral acceleration, tracking error
of several controllers along the track (read results, never solve).

Like :mod:`mpcdrive.plots.figures`: each ``plot_*`` writes a PNG atomically and returns its path;
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
from mpcdrive.plots.figures import _lane_boundaries, _new_figure, _save, _title
from mpcdrive.sim.analysis import lateral_acceleration_mps2
from mpcdrive.types import SimResult

__all__ = ["plot_lateral_acceleration", "plot_speed_map", "plot_tracking_comparison"]


def _draw_road(ax, result: SimResult, track: Track | None) -> None:
    path = np.asarray(result.path_xy, float)
    ax.plot(path[:, 0], path[:, 1], color="0.6", lw=0.8, ls=":", label="centre line")
    if track is not None and track.has_widths:
        left, right = track.boundaries()
    elif result.lane_half_width_m is not None and path.shape[0] >= 2:
        left, right = _lane_boundaries(path, float(result.lane_half_width_m))
    else:
        return
    ax.plot(left[:, 0], left[:, 1], color="k", lw=1.0, label="road edge")
    ax.plot(right[:, 0], right[:, 1], color="k", lw=1.0)


def _make_speed_map(result: SimResult, track: Track | None = None, title: str | None = None) -> Figure:
    fig, axes = _new_figure(size=(8.0, 6.5))
    ax = axes[0, 0]
    _draw_road(ax, result, track)
    xy = np.asarray(result.xy, float)
    v = np.asarray(result.v_mps, float)
    if xy.shape[0] >= 2:
        seg = np.stack([xy[:-1], xy[1:]], axis=1)
        lc = LineCollection(seg, cmap="viridis", linewidths=2.5)
        lc.set_array(0.5 * (v[:-1] + v[1:]))
        ax.add_collection(lc)
        cb = fig.colorbar(lc, ax=ax)
        cb.set_label("speed v [m/s]")
        ax.plot(xy[0, 0], xy[0, 1], "o", color="tab:green", ms=7, label="start")
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title if title is not None else _title("Trajectory coloured by speed", result))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


def _make_lateral_acceleration(result: SimResult, limit_mps2: float | None = None) -> Figure:
    fig, axes = _new_figure()
    ax = axes[0, 0]
    ay = lateral_acceleration_mps2(result)
    ax.plot(result.s_m - result.s_m[0], ay, color="tab:red", lw=1.2, label="lateral acceleration")
    if limit_mps2 is not None:
        ax.axhline(limit_mps2, color="k", ls="--", lw=1.0, label=f"limit ±{limit_mps2:.3g} m/s^2")
        ax.axhline(-limit_mps2, color="k", ls="--", lw=1.0)
    ax.set_xlabel("distance along the path s [m]")
    ax.set_ylabel("lateral acceleration a_y [m/s^2]")
    ax.set_title(_title("Lateral acceleration", result))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


def _make_tracking_comparison(results: Mapping[str, SimResult], title: str | None = None) -> Figure:
    if not results:
        raise ValueError("plot_tracking_comparison needs at least one result")
    fig, axes = _new_figure(2, 1, size=(9.0, 7.0), sharex=True)
    ax, ax_v = axes[0, 0], axes[1, 0]
    for label, res in results.items():
        s = res.s_m - res.s_m[0]
        ax.plot(s, np.abs(res.e_y_m), lw=1.1, label=str(label))
        ax_v.plot(s, res.v_mps, lw=1.1, label=str(label))
    ax.set_ylabel("|e_y| [m]")
    ax.set_title(title or "Tracking error along the track")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    ax_v.set_xlabel("distance along the path s [m]")
    ax_v.set_ylabel("speed v [m/s]")
    ax_v.grid(True, alpha=0.3)
    return fig


def plot_speed_map(result: SimResult, path: str | os.PathLike, track: Track | None = None,
                   title: str | None = None) -> Path:
    """Driven trajectory coloured by speed [m/s] (colour bar), with the road edges of ``track`` (or
    the lane of the result) and the centre line. Writes a PNG; returns ``path``."""
    return _save(_make_speed_map(result, track, title), path)


def plot_lateral_acceleration(result: SimResult, path: str | os.PathLike, limit_mps2: float | None = None) -> Path:
    """Lateral acceleration [m/s^2] along the path (from the logged positions), with +-``limit_mps2``
    dashed when given (e.g. mu g). Writes a PNG; returns ``path``."""
    return _save(_make_lateral_acceleration(result, limit_mps2), path)


def plot_tracking_comparison(results: Mapping[str, SimResult], path: str | os.PathLike,
                             title: str | None = None) -> Path:
    """|e_y| [m] and speed [m/s] along the path of several runs keyed by label (e.g. controllers on
    the same track). Writes a PNG; returns ``path``."""
    return _save(_make_tracking_comparison(results, title), path)
