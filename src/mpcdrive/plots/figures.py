"""Figures of a closed-loop run (the paper's Figs. 3-12); read results, never solve.

Each ``plot_*`` function takes a :class:`~mpcdrive.types.SimResult` and an output path, writes a
PNG atomically and returns the path.  The figure itself is built by a matching ``_make_*``
function returning a :class:`matplotlib.figure.Figure`, so tests can check structure (labels
with units, data present) without reading pixels.

Figures are made with the object-oriented API (``Figure`` rendered by the Agg canvas) and never
through ``pyplot``: no window ever opens, the global backend of a host program (a notebook, a
GUI) is left alone, and no figure is registered in pyplot's global manager, so nothing needs
closing and thousands of runs do not grow memory.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from mpcdrive.plots.common import (
    DRIVEN_COLOR,
    ITER_LABEL,
    LONG_ROAD_RATIO,
    REF_COLOR,
    RUN_COLORS,
    aspect_ratio,
    draw_obstacles,
    result_road_edges,
    new_figure,
    run_label,
    save,
    set_suptitle,
    set_title,
    title_for,
)
from mpcdrive.plots.laps import plot_lateral_acceleration, plot_speed_map
from mpcdrive.types import SimResult
from mpcdrive.units import rad2deg

__all__ = [
    "plot_heading_deviation",
    "plot_lateral_deviation",
    "plot_overview",
    "plot_speed",
    "plot_steering",
    "plot_steering_comparison",
    "plot_trajectory",
    "plot_clearance",
    "plot_trajectory_overlay",
    "plot_cost_map",
    "speed_varies",
    "write_run_figures",
]


# --------------------------------------------------------------------------- helpers
def _iterations(result: SimResult) -> np.ndarray:
    return np.arange(result.steps)


def _finite_max(values: np.ndarray) -> float | None:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.max()) if v.size else None


def _symmetric_ylim(ax, values: np.ndarray, floor: float) -> None:
    m = _finite_max(np.abs(values))
    top = max(1.1 * m, floor) if m is not None else floor
    ax.set_ylim(-top, top)


def _max_steer_rad(result: SimResult) -> float | None:
    value = result.meta.get("max_steer_rad")
    if value is None:
        return None
    value = float(value)
    return value if np.isfinite(value) and value > 0 else None


# --------------------------------------------------------------------------- drawing on axes
def _map_extent(result: SimResult) -> tuple[float, bool]:
    """(aspect ratio, wide) of the map: reference path, lane and driven trajectory."""
    path = np.asarray(result.path_xy, dtype=float)
    sets = [path, np.asarray(result.xy, dtype=float)]
    edges = result_road_edges(result)
    if edges is not None:
        sets.extend(edges)
    return aspect_ratio(*sets)


def is_long_road(result: SimResult) -> bool:
    """True when the map of the run is more than ``LONG_ROAD_RATIO`` times longer than wide (a
    road of 230 m x 4 m): its figures add a panel in path coordinates (s, e_y)."""
    ratio, _ = _map_extent(result)
    return ratio > LONG_ROAD_RATIO


def _draw_trajectory(
    ax,
    result: SimResult,
    title: str | None = None,
    horizons: bool = True,
    legend: bool = True,
    time_labels: bool = True,
) -> None:
    path = np.asarray(result.path_xy, dtype=float)
    xy = np.asarray(result.xy, dtype=float)
    if horizons and result.X_pred is not None and np.ndim(result.X_pred) == 3:
        X = np.asarray(result.X_pred, dtype=float)
        if X.shape[0] and X.shape[1] and X.shape[2] >= 2:
            stride = max(1, X.shape[0] // 10)
            for i, k in enumerate(range(0, X.shape[0], stride)):
                ax.plot(
                    X[k, :, 0],
                    X[k, :, 1],
                    color="0.55",
                    lw=0.8,
                    zorder=1,
                    label="predicted horizon" if i == 0 else None,
                )
    if path.ndim == 2 and path.shape[0] >= 1:
        ax.plot(path[:, 0], path[:, 1], color=REF_COLOR, lw=1.5, label="reference path", zorder=2)
        edges = result_road_edges(result)
        if edges is not None:
            left, right = edges
            ax.plot(left[:, 0], left[:, 1], color="k", lw=1.0, ls="--", label="lane boundary")
            ax.plot(right[:, 0], right[:, 1], color="k", lw=1.0, ls="--")
    draw_obstacles(ax, result, time_labels=time_labels)
    ax.plot(xy[:, 0], xy[:, 1], color=DRIVEN_COLOR, lw=1.5, label="driven trajectory", zorder=3)
    if xy.shape[0]:
        ax.plot(xy[0, 0], xy[0, 1], "o", color="tab:green", ms=7, label="start", zorder=4)
        ax.plot(xy[-1, 0], xy[-1, 1], "s", color=DRIVEN_COLOR, ms=5, label="end", zorder=4)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    set_title(ax, title if title is not None else title_for("Trajectory", result))
    ax.grid(True, alpha=0.3)
    if legend:
        ax.legend(loc="best", fontsize="small")


def _draw_path_coordinates(ax, result: SimResult, title: str | None = None) -> None:
    """The run in path coordinates: lateral offset e_y [m] over the distance along the path s [m]
    (the lateral axis exaggerated), lane, obstacles (moving ones at their closest approach)."""
    path = np.asarray(result.path_xy, dtype=float)
    s_path = np.r_[0.0, np.cumsum(np.hypot(*np.diff(path, axis=0).T))] if len(path) >= 2 else np.zeros(len(path))
    s = np.asarray(result.s_m, dtype=float)
    e_y = np.asarray(result.e_y_m, dtype=float)
    lo = min(0.0, float(np.nanmin(s))) if s.size else 0.0
    hi = max(float(s_path[-1]) if s_path.size else 0.0, float(np.nanmax(s)) if s.size else 0.0)
    ax.plot([lo, hi], [0.0, 0.0], color=REF_COLOR, lw=1.5, label="reference path (e_y = 0)", zorder=2)
    prof = result.road_profile
    if prof is not None:
        prof = np.asarray(prof, dtype=float)
        ax.plot(prof[:, 0], prof[:, 1], color="k", lw=1.0, ls="--", label="lane boundary")
        ax.plot(prof[:, 0], prof[:, 2], color="k", lw=1.0, ls="--")
    if len(path) >= 2:
        draw_obstacles(ax, result, frenet_path_xy=path)
    ax.plot(s, e_y, color=DRIVEN_COLOR, lw=1.5, label="driven trajectory", zorder=3)
    if s.size:
        ax.plot(s[0], e_y[0], "o", color="tab:green", ms=7, label="start", zorder=4)
        ax.plot(s[-1], e_y[-1], "s", color=DRIVEN_COLOR, ms=5, label="end", zorder=4)
    edge = float(np.max(np.abs(prof[:, 1:]))) if prof is not None else 0.0
    top = max(edge, float(np.nanmax(np.abs(e_y))) if e_y.size else 0.0, 0.5)
    # obstacles that reach within two lane half-widths of the path are shown whole
    near = [np.abs(p.get_xy()[:, 1]) for p in ax.patches if hasattr(p, "get_xy")]
    reach = max([float(a.max()) for a in near if a.size and a.min() < 2.0 * top], default=0.0)
    top = max(2.0 * top, 1.05 * reach)
    ax.set_ylim(-top, top)
    ax.set_xlim(lo, hi)
    ax.set_xlabel("distance along the path s [m]")
    ax.set_ylabel("lateral offset e_y [m]")
    set_title(ax, title if title is not None else title_for("In path coordinates (lateral axis stretched)", result))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", borderaxespad=0.0)


def _draw_lateral(ax, result: SimResult, log_y: bool = False) -> None:
    abs_ey = np.abs(np.asarray(result.e_y_m, dtype=float))
    k = _iterations(result)
    ax.set_xlabel(ITER_LABEL)
    ax.set_ylabel("|e_y| [m]")
    set_title(ax, title_for("Lateral (distance) deviation", result))
    ax.grid(True, alpha=0.3)
    top = _finite_max(abs_ey)
    if log_y:
        pos = abs_ey[np.isfinite(abs_ey) & (abs_ey > 0)]
        floor = max(float(pos.min()) * 0.5, 1e-9) if pos.size else 1e-9
        ax.semilogy(k, np.maximum(abs_ey, floor), color=DRIVEN_COLOR, lw=1.2)
        ax.set_ylim(floor, max(2.0 * (top or floor), 10 * floor))
    else:
        ax.plot(k, abs_ey, color=DRIVEN_COLOR, lw=1.2)
        ax.set_ylim(0.0, max(1.1 * top, 1e-3) if top is not None else 1e-3)
    if k.size:
        ax.set_xlim(0, max(int(k[-1]), 1))


def _draw_heading(ax, result: SimResult) -> None:
    e_psi_deg = rad2deg(np.asarray(result.e_psi_rad, dtype=float))
    k = _iterations(result)
    ax.plot(k, e_psi_deg, color=DRIVEN_COLOR, lw=1.2)
    ax.axhline(0.0, color="k", lw=0.6)
    _symmetric_ylim(ax, e_psi_deg, floor=0.1)
    ax.set_xlabel(ITER_LABEL)
    ax.set_ylabel("e_psi [deg]")
    set_title(ax, title_for("Heading deviation", result))
    ax.grid(True, alpha=0.3)
    if k.size:
        ax.set_xlim(0, max(int(k[-1]), 1))


def _draw_steering(ax, result: SimResult) -> None:
    steer_deg = rad2deg(np.asarray(result.steer_rad, dtype=float))
    k = _iterations(result)
    ax.plot(k, steer_deg, color=DRIVEN_COLOR, lw=1.2, label="steering angle")
    bound = _max_steer_rad(result)
    floor = 0.5
    if bound is not None:
        b = rad2deg(bound)
        ax.axhline(b, color="k", ls="--", lw=1.0, label=f"bound ±{b:.3g} deg")
        ax.axhline(-b, color="k", ls="--", lw=1.0)
        floor = b * 1.1
        ax.legend(loc="best", fontsize="small")
    _symmetric_ylim(ax, steer_deg, floor=floor)
    ax.set_xlabel(ITER_LABEL)
    ax.set_ylabel("steering angle delta [deg]")
    set_title(ax, title_for("Steering angle", result))
    ax.grid(True, alpha=0.3)
    if k.size:
        ax.set_xlim(0, max(int(k[-1]), 1))


# --------------------------------------------------------------------------- figure builders
def _make_trajectory(result: SimResult, title: str | None = None) -> Figure:
    ratio, wide = _map_extent(result)
    if ratio <= LONG_ROAD_RATIO:
        fig, axes = new_figure(size=(7.0, 6.0))
        _draw_trajectory(axes[0, 0], result, title)
        return fig
    # a long road: the true-scale map as a strip, the run in path coordinates beside it
    if wide:
        map_h = float(np.clip(9.0 / ratio, 0.6, 2.5))
        fig, axes = new_figure(2, 1, size=(11.0, map_h + 4.6), height_ratios=[map_h + 0.7, 3.6])
        ax_map, ax_s = axes[0, 0], axes[1, 0]
    else:
        map_w = float(np.clip(5.5 / ratio, 0.6, 2.5))
        fig, axes = new_figure(1, 2, size=(map_w + 9.5, 5.5), width_ratios=[map_w + 0.9, 8.6])
        ax_map, ax_s = axes[0, 0], axes[0, 1]
    _draw_trajectory(
        ax_map,
        result,
        title if title is not None else title_for("Trajectory (true scale)", result),
        legend=False,
        time_labels=False,
    )
    _draw_path_coordinates(ax_s, result)
    return fig


def _make_lateral_deviation(result: SimResult, log_y: bool = False) -> Figure:
    fig, axes = new_figure()
    _draw_lateral(axes[0, 0], result, log_y=log_y)
    return fig


def _make_heading_deviation(result: SimResult) -> Figure:
    fig, axes = new_figure()
    _draw_heading(axes[0, 0], result)
    return fig


def _make_steering(result: SimResult) -> Figure:
    fig, axes = new_figure()
    _draw_steering(axes[0, 0], result)
    return fig


def _has_accel_input(result: SimResult) -> bool:
    return "accel" in tuple(result.input_names)


def _make_speed(result: SimResult) -> Figure:
    with_accel = _has_accel_input(result)
    fig, axes = new_figure(2 if with_accel else 1, 1, size=(7.0, 6.0 if with_accel else 4.5))
    k = _iterations(result)
    ax = axes[0, 0]
    ax.plot(k, np.asarray(result.v_mps, dtype=float), color=DRIVEN_COLOR, lw=1.2, label="speed")
    # reference speed from the horizon references, when the model has a speed state
    names = tuple(result.state_names)
    refs = result.refs
    if (
        "v" in names
        and refs is not None
        and np.ndim(refs) == 3
        and refs.shape[0] == result.steps
        and refs.shape[1] > 0
        and refs.shape[2] > names.index("v")
    ):
        ax.plot(k, refs[:, 0, names.index("v")], color=REF_COLOR, ls="--", lw=1.0, label="reference speed")
    elif (
        {"vx", "vy"} <= set(names)
        and refs is not None
        and np.ndim(refs) == 3
        and refs.shape[0] == result.steps
        and refs.shape[1] > 0
        and refs.shape[2] == len(names)
    ):
        ref_v = np.hypot(refs[:, 0, names.index("vx")], refs[:, 0, names.index("vy")])
        ax.plot(k, ref_v, color=REF_COLOR, ls="--", lw=1.0, label="reference speed")
    ax.set_ylabel("speed v [m/s]")
    set_title(ax, title_for("Speed", result))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    ax.set_xlabel(ITER_LABEL)
    if with_accel:
        ax2 = axes[1, 0]
        ax2.plot(k, np.asarray(result.accel_mps2, dtype=float), color="tab:purple", lw=1.2)
        ax2.axhline(0.0, color="k", lw=0.6)
        ax2.set_ylabel("acceleration a [m/s^2]")
        ax2.set_xlabel(ITER_LABEL)
        set_title(ax2, "Acceleration input")
        ax2.grid(True, alpha=0.3)
    return fig


def _make_overview(result: SimResult) -> Figure:
    fig, axes = new_figure(2, 2, size=(12.0, 9.0))
    if is_long_road(result):  # a strip on this scale: the run in path coordinates instead
        _draw_path_coordinates(axes[0, 0], result)
        axes[0, 0].legend(loc="lower right", fontsize="x-small", ncols=2)
    else:
        _draw_trajectory(axes[0, 0], result)
    _draw_lateral(axes[0, 1], result)
    _draw_heading(axes[1, 0], result)
    _draw_steering(axes[1, 1], result)
    name = run_label(result)
    set_suptitle(fig, f"Run overview — {name}" if name else "Run overview")
    return fig


def _make_steering_comparison(results: Mapping[str, SimResult], title: str | None = None) -> Figure:
    if not results:
        raise ValueError("plot_steering_comparison needs at least one result")
    fig, axes = new_figure(2, 1, size=(8.0, 6.5))
    ax, ax_rate = axes[0, 0], axes[1, 0]
    bound = None
    peak_rate = 0.0
    for i, (label, res) in enumerate(results.items()):
        k = _iterations(res)
        steer_deg = rad2deg(np.asarray(res.steer_rad, dtype=float))
        (line,) = ax.plot(k, steer_deg, lw=1.2, color=RUN_COLORS[i % len(RUN_COLORS)], label=str(label))
        if steer_deg.size >= 2 and res.dt_s > 0:
            rate = np.diff(steer_deg) / float(res.dt_s)
            ax_rate.plot(k[1:], rate, lw=1.0, color=line.get_color(), label=str(label))
            peak_rate = max(peak_rate, _finite_max(np.abs(rate)) or 0.0)
        if bound is None:
            bound = _max_steer_rad(res)
    if bound is not None:
        b = rad2deg(bound)
        ax.axhline(b, color="k", ls="--", lw=1.0, label=f"bound ±{b:.3g} deg")
        ax.axhline(-b, color="k", ls="--", lw=1.0)
    ax.set_ylabel("steering angle delta [deg]")
    set_title(ax, title or "Steering angle comparison")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    ax.set_xlabel(ITER_LABEL)
    ax_rate.axhline(0.0, color="k", lw=0.6)
    top = max(1.1 * peak_rate, 0.1)
    ax_rate.set_ylim(-top, top)
    ax_rate.set_ylabel("steering rate [deg/s]")
    ax_rate.set_xlabel(ITER_LABEL)
    set_title(ax_rate, "Steering rate (finite difference)")
    ax_rate.grid(True, alpha=0.3)
    return fig


# --------------------------------------------------------------------------- public API
def plot_trajectory(result: SimResult, path: str | os.PathLike, title: str | None = None) -> Path:
    """Reference path (blue) vs driven trajectory (red) in x/y [m], equal aspect, start marker,
    road edges (``result.road_profile``) when set, a few predicted horizons (thin
    grey, about every 10 % of the run), obstacles (moving ones where they were at their closest
    approach, with the time). A map more than ``LONG_ROAD_RATIO`` times longer than wide gets
    a second panel in path coordinates (s, e_y) [m].  Writes a PNG; returns ``path``."""
    return save(_make_trajectory(result, title), path)


def plot_lateral_deviation(result: SimResult, path: str | os.PathLike, log_y: bool = False) -> Path:
    """|e_y| [m] over iterations (the paper's "distance deviation"); linear y from 0 unless
    ``log_y``.  Writes a PNG; returns ``path``."""
    return save(_make_lateral_deviation(result, log_y=log_y), path)


def plot_heading_deviation(result: SimResult, path: str | os.PathLike) -> Path:
    """Heading error e_psi [deg] over iterations.  Writes a PNG; returns ``path``."""
    return save(_make_heading_deviation(result), path)


def plot_steering(result: SimResult, path: str | os.PathLike) -> Path:
    """Applied steering angle [deg] over iterations, with +-``meta["max_steer_rad"]`` dashed when
    recorded.  Writes a PNG; returns ``path``."""
    return save(_make_steering(result), path)


def plot_speed(result: SimResult, path: str | os.PathLike) -> Path:
    """Speed [m/s] over iterations (reference speed dashed when the model has a ``v`` state),
    plus the acceleration input [m/s^2] when the model has one.  Writes a PNG; returns ``path``."""
    return save(_make_speed(result), path)


def plot_overview(result: SimResult, path: str | os.PathLike) -> Path:
    """2x2 grid: trajectory, lateral deviation, heading deviation, steering (the paper's four
    figures per experiment).  Writes a PNG; returns ``path``."""
    return save(_make_overview(result), path)


def plot_steering_comparison(
    results: Mapping[str, SimResult], path: str | os.PathLike, title: str | None = None
) -> Path:
    """Overlaid steering angles [deg] and steering rates [deg/s] of several runs, keyed by legend
    label (the input-smoothing experiment, the paper's Fig. 12).  Writes a PNG; returns ``path``."""
    return save(_make_steering_comparison(results, title), path)


def speed_varies(result: SimResult, tol_mps: float = 1e-6) -> bool:
    """True when the logged speed changes by more than ``tol_mps`` [m/s] over the run."""
    v = np.asarray(result.v_mps, dtype=float)
    v = v[np.isfinite(v)]
    return bool(v.size and np.ptp(v) > tol_mps)


def write_run_figures(result: SimResult, out_dir: str | os.PathLike) -> list[Path]:
    """Write every figure of one run into ``out_dir`` (created if needed); return their paths.

    Files: ``trajectory.png``, ``lateral_deviation.png``, ``heading_deviation.png``,
    ``steering.png``, ``speed.png``, ``speed_map.png`` (trajectory coloured by speed) and
    ``lateral_acceleration.png`` (the last three only when the model has an ``accel`` input or the
    speed varies) and ``overview.png``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [
        plot_trajectory(result, out / "trajectory.png"),
        plot_lateral_deviation(result, out / "lateral_deviation.png"),
        plot_heading_deviation(result, out / "heading_deviation.png"),
        plot_steering(result, out / "steering.png"),
    ]
    if _has_accel_input(result) or speed_varies(result):
        paths.append(plot_speed(result, out / "speed.png"))
        paths.append(plot_speed_map(result, out / "speed_map.png"))
        paths.append(plot_lateral_acceleration(result, out / "lateral_acceleration.png"))
    if result.clearance_m is not None:
        paths.append(plot_clearance(result, out / "clearance.png"))
    paths.append(plot_overview(result, out / "overview.png"))
    return paths


def _make_clearance(result: SimResult) -> Figure:
    fig, axes = new_figure()
    ax = axes[0, 0]
    c = np.asarray(result.clearance_m, dtype=float)
    ax.plot(_iterations(result), c, color=DRIVEN_COLOR, lw=1.2, label="footprint-to-obstacle clearance")
    ax.axhline(0.0, color="k", lw=1.0, ls="--", label="contact")
    ax.set_xlabel(ITER_LABEL)
    ax.set_ylabel("clearance [m]")
    set_title(ax, title_for("Obstacle clearance", result))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_clearance(result: SimResult, path: str | os.PathLike) -> Path:
    """Smallest footprint-to-obstacle distance [m] over iterations (negative = overlap)."""
    return save(_make_clearance(result), path)


def _make_trajectory_overlay(results: Mapping[str, SimResult], title: str | None = None) -> Figure:
    fig, axes = new_figure(size=(8.0, 4.5))
    ax = axes[0, 0]
    first = next(iter(results.values()))
    path = np.asarray(first.path_xy, dtype=float)
    ax.plot(path[:, 0], path[:, 1], color=REF_COLOR, lw=1.2, ls="-.", label="reference path")
    edges = result_road_edges(first)
    if edges is not None:
        left, right = edges
        ax.plot(left[:, 0], left[:, 1], color="k", lw=1.0, ls="--", label="lane boundary")
        ax.plot(right[:, 0], right[:, 1], color="k", lw=1.0, ls="--")
    draw_obstacles(ax, first)  # moving ones at their closest approach to the first run
    for i, (name, r) in enumerate(results.items()):
        ax.plot(r.xy[:, 0], r.xy[:, 1], lw=1.4, color=RUN_COLORS[i % len(RUN_COLORS)], label=name)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    set_title(ax, title or "Trajectories")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", borderaxespad=0.0)
    return fig


def plot_trajectory_overlay(
    results: Mapping[str, SimResult], path: str | os.PathLike, title: str | None = None
) -> Path:
    """Several runs on the same road overlaid (obstacles and lane from the first)."""
    return save(_make_trajectory_overlay(results, title), path)


def _make_cost_map(X: np.ndarray, Y: np.ndarray, C: np.ndarray, title: str) -> Figure:
    fig, axes = new_figure(size=(7.0, 4.5))
    ax = axes[0, 0]
    cs = ax.contourf(X, Y, C, levels=30, cmap="viridis")
    fig.colorbar(cs, ax=ax, label="obstacle cost [-]")
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    set_title(ax, title)
    return fig


def plot_cost_map(
    X: np.ndarray, Y: np.ndarray, C: np.ndarray, path: str | os.PathLike, title: str = "Obstacle cost map"
) -> Path:
    """Filled contours of an obstacle cost evaluated on a grid (the paper's Fig. 14)."""
    return save(_make_cost_map(X, Y, C, title), path)
