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

import io
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mpcdrive.io.atomic import atomic_write_bytes
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

_DPI = 120
_ITER_LABEL = "iteration k [-]"
_REF_COLOR = "tab:blue"
_DRIVEN_COLOR = "tab:red"


# --------------------------------------------------------------------------- helpers
def _new_figure(nrows: int = 1, ncols: int = 1, size=(7.0, 4.5), **kw) -> tuple[Figure, np.ndarray]:
    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False, **kw)
    return fig, axes


def _save(fig: Figure, path: str | os.PathLike) -> Path:
    """Render ``fig`` to PNG and write it atomically; return the path."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI)
    fig.clear()  # drop artists now rather than at garbage collection
    return atomic_write_bytes(path, buf.getvalue())


def _label(result: SimResult) -> str:
    """Short run name for titles from ``result.meta`` ('' when none is recorded)."""
    for key in ("id", "scenario_id", "scenario", "name"):
        value = result.meta.get(key)
        if isinstance(value, str) and value:
            return value
    return ""


def _title(base: str, result: SimResult) -> str:
    name = _label(result)
    return f"{base} — {name}" if name else base


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


def _lane_boundaries(path_xy: np.ndarray, half_width_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Left and right lane boundaries (M, 2) [m]: the polyline offset by +-half width along its
    unit normals (central-difference tangents; repeated points keep the previous normal)."""
    p = np.asarray(path_xy, dtype=float)
    tangent = np.gradient(p, axis=0)
    norm = np.hypot(tangent[:, 0], tangent[:, 1])
    good = norm > 1e-12
    if not good.any():
        raise ValueError("reference path has no extent; cannot draw lane boundaries")
    # carry the last valid tangent over degenerate (repeated) points
    idx = np.where(good, np.arange(len(p)), 0)
    idx = np.maximum.accumulate(idx)
    first_good = int(np.argmax(good))
    idx[: first_good + 1] = first_good
    unit = tangent[idx] / norm[idx, None]
    normal = np.column_stack([-unit[:, 1], unit[:, 0]])  # left of the direction of travel
    return p + half_width_m * normal, p - half_width_m * normal


# --------------------------------------------------------------------------- drawing on axes
def _draw_trajectory(ax, result: SimResult, title: str | None = None, horizons: bool = True) -> None:
    path = np.asarray(result.path_xy, dtype=float)
    xy = np.asarray(result.xy, dtype=float)
    if horizons and result.X_pred is not None and np.ndim(result.X_pred) == 3:
        X = np.asarray(result.X_pred, dtype=float)
        if X.shape[0] and X.shape[1] and X.shape[2] >= 2:
            stride = max(1, X.shape[0] // 10)
            for i, k in enumerate(range(0, X.shape[0], stride)):
                ax.plot(X[k, :, 0], X[k, :, 1], color="0.55", lw=0.8, zorder=1,
                        label="predicted horizon" if i == 0 else None)
    if path.ndim == 2 and path.shape[0] >= 1:
        ax.plot(path[:, 0], path[:, 1], color=_REF_COLOR, lw=1.5, label="reference path", zorder=2)
        if result.lane_half_width_m is not None and path.shape[0] >= 2:
            left, right = _lane_boundaries(path, float(result.lane_half_width_m))
            ax.plot(left[:, 0], left[:, 1], color="k", lw=1.0, ls="--", label="lane boundary")
            ax.plot(right[:, 0], right[:, 1], color="k", lw=1.0, ls="--")
    _draw_obstacles(ax, result)
    ax.plot(xy[:, 0], xy[:, 1], color=_DRIVEN_COLOR, lw=1.5, label="driven trajectory", zorder=3)
    if xy.shape[0]:
        ax.plot(xy[0, 0], xy[0, 1], "o", color="tab:green", ms=7, label="start", zorder=4)
        ax.plot(xy[-1, 0], xy[-1, 1], "s", color=_DRIVEN_COLOR, ms=5, label="end", zorder=4)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title if title is not None else _title("Trajectory", result))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


def _obstacle_outlines(entry: Mapping) -> list[np.ndarray]:
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


def _draw_obstacles(ax, result: SimResult) -> None:
    """Obstacles logged in ``result.meta["obstacles"]``: static ones filled, moving ones as
    outlines at a few times (darker = later) with the path of their centre."""
    for i, entry in enumerate(result.meta.get("obstacles") or []):
        outlines = _obstacle_outlines(entry)
        if not outlines:
            continue
        label = "obstacle" if i == 0 else None
        if len(outlines) == 1:
            o = outlines[0]
            ax.fill(o[:, 0], o[:, 1], color="0.35", alpha=0.8, zorder=2.5, label=label)
            continue
        ks = np.unique(np.linspace(0, len(outlines) - 1, 6).astype(int))
        for j, k in enumerate(ks):
            o = outlines[k]
            ax.plot(o[:, 0], o[:, 1], color="0.2", alpha=0.25 + 0.75 * j / max(len(ks) - 1, 1), lw=1.0,
                    zorder=2.5, label=label if j == len(ks) - 1 else None)
        centres = np.array([o[:-1].mean(axis=0) for o in outlines])
        ax.plot(centres[:, 0], centres[:, 1], color="0.4", lw=0.8, ls=":", zorder=2.4)


def _draw_lateral(ax, result: SimResult, log_y: bool = False) -> None:
    abs_ey = np.abs(np.asarray(result.e_y_m, dtype=float))
    k = _iterations(result)
    ax.set_xlabel(_ITER_LABEL)
    ax.set_ylabel("|e_y| [m]")
    ax.set_title(_title("Lateral (distance) deviation", result))
    ax.grid(True, alpha=0.3)
    top = _finite_max(abs_ey)
    if log_y:
        pos = abs_ey[np.isfinite(abs_ey) & (abs_ey > 0)]
        floor = max(float(pos.min()) * 0.5, 1e-9) if pos.size else 1e-9
        ax.semilogy(k, np.maximum(abs_ey, floor), color=_DRIVEN_COLOR, lw=1.2)
        ax.set_ylim(floor, max(2.0 * (top or floor), 10 * floor))
    else:
        ax.plot(k, abs_ey, color=_DRIVEN_COLOR, lw=1.2)
        ax.set_ylim(0.0, max(1.1 * top, 1e-3) if top is not None else 1e-3)
    if k.size:
        ax.set_xlim(0, max(int(k[-1]), 1))


def _draw_heading(ax, result: SimResult) -> None:
    e_psi_deg = rad2deg(np.asarray(result.e_psi_rad, dtype=float))
    k = _iterations(result)
    ax.plot(k, e_psi_deg, color=_DRIVEN_COLOR, lw=1.2)
    ax.axhline(0.0, color="k", lw=0.6)
    _symmetric_ylim(ax, e_psi_deg, floor=0.1)
    ax.set_xlabel(_ITER_LABEL)
    ax.set_ylabel("e_psi [deg]")
    ax.set_title(_title("Heading deviation", result))
    ax.grid(True, alpha=0.3)
    if k.size:
        ax.set_xlim(0, max(int(k[-1]), 1))


def _draw_steering(ax, result: SimResult) -> None:
    steer_deg = rad2deg(np.asarray(result.steer_rad, dtype=float))
    k = _iterations(result)
    ax.plot(k, steer_deg, color=_DRIVEN_COLOR, lw=1.2, label="steering angle")
    bound = _max_steer_rad(result)
    floor = 0.5
    if bound is not None:
        b = rad2deg(bound)
        ax.axhline(b, color="k", ls="--", lw=1.0, label=f"bound ±{b:.3g} deg")
        ax.axhline(-b, color="k", ls="--", lw=1.0)
        floor = b * 1.1
        ax.legend(loc="best", fontsize="small")
    _symmetric_ylim(ax, steer_deg, floor=floor)
    ax.set_xlabel(_ITER_LABEL)
    ax.set_ylabel("steering angle delta [deg]")
    ax.set_title(_title("Steering angle", result))
    ax.grid(True, alpha=0.3)
    if k.size:
        ax.set_xlim(0, max(int(k[-1]), 1))


# --------------------------------------------------------------------------- figure builders
def _make_trajectory(result: SimResult, title: str | None = None) -> Figure:
    fig, axes = _new_figure(size=(7.0, 6.0))
    _draw_trajectory(axes[0, 0], result, title)
    return fig


def _make_lateral_deviation(result: SimResult, log_y: bool = False) -> Figure:
    fig, axes = _new_figure()
    _draw_lateral(axes[0, 0], result, log_y=log_y)
    return fig


def _make_heading_deviation(result: SimResult) -> Figure:
    fig, axes = _new_figure()
    _draw_heading(axes[0, 0], result)
    return fig


def _make_steering(result: SimResult) -> Figure:
    fig, axes = _new_figure()
    _draw_steering(axes[0, 0], result)
    return fig


def _has_accel_input(result: SimResult) -> bool:
    return "accel" in tuple(result.input_names)


def _make_speed(result: SimResult) -> Figure:
    with_accel = _has_accel_input(result)
    fig, axes = _new_figure(2 if with_accel else 1, 1, size=(7.0, 6.0 if with_accel else 4.5))
    k = _iterations(result)
    ax = axes[0, 0]
    ax.plot(k, np.asarray(result.v_mps, dtype=float), color=_DRIVEN_COLOR, lw=1.2, label="speed")
    # reference speed from the horizon references, when the model has a speed state
    names = tuple(result.state_names)
    refs = result.refs
    if "v" in names and refs is not None and np.ndim(refs) == 3 and refs.shape[0] == result.steps \
            and refs.shape[1] > 0 and refs.shape[2] > names.index("v"):
        ax.plot(k, refs[:, 0, names.index("v")], color=_REF_COLOR, ls="--", lw=1.0,
                label="reference speed")
    elif {"vx", "vy"} <= set(names) and refs is not None and np.ndim(refs) == 3 \
            and refs.shape[0] == result.steps and refs.shape[1] > 0 and refs.shape[2] == len(names):
        ref_v = np.hypot(refs[:, 0, names.index("vx")], refs[:, 0, names.index("vy")])
        ax.plot(k, ref_v, color=_REF_COLOR, ls="--", lw=1.0, label="reference speed")
    ax.set_ylabel("speed v [m/s]")
    ax.set_title(_title("Speed", result))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    ax.set_xlabel(_ITER_LABEL)
    if with_accel:
        ax2 = axes[1, 0]
        ax2.plot(k, np.asarray(result.accel_mps2, dtype=float), color="tab:purple", lw=1.2)
        ax2.axhline(0.0, color="k", lw=0.6)
        ax2.set_ylabel("acceleration a [m/s^2]")
        ax2.set_xlabel(_ITER_LABEL)
        ax2.set_title("Acceleration input")
        ax2.grid(True, alpha=0.3)
    return fig


def _make_overview(result: SimResult) -> Figure:
    fig, axes = _new_figure(2, 2, size=(12.0, 9.0))
    _draw_trajectory(axes[0, 0], result)
    _draw_lateral(axes[0, 1], result)
    _draw_heading(axes[1, 0], result)
    _draw_steering(axes[1, 1], result)
    name = _label(result)
    fig.suptitle(f"Run overview — {name}" if name else "Run overview")
    return fig


def _make_steering_comparison(results: Mapping[str, SimResult], title: str | None = None) -> Figure:
    if not results:
        raise ValueError("plot_steering_comparison needs at least one result")
    fig, axes = _new_figure(2, 1, size=(8.0, 6.5))
    ax, ax_rate = axes[0, 0], axes[1, 0]
    bound = None
    peak_rate = 0.0
    for label, res in results.items():
        k = _iterations(res)
        steer_deg = rad2deg(np.asarray(res.steer_rad, dtype=float))
        (line,) = ax.plot(k, steer_deg, lw=1.2, label=str(label))
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
    ax.set_title(title or "Steering angle comparison")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    ax.set_xlabel(_ITER_LABEL)
    ax_rate.axhline(0.0, color="k", lw=0.6)
    top = max(1.1 * peak_rate, 0.1)
    ax_rate.set_ylim(-top, top)
    ax_rate.set_ylabel("steering rate [deg/s]")
    ax_rate.set_xlabel(_ITER_LABEL)
    ax_rate.set_title("Steering rate (finite difference)")
    ax_rate.grid(True, alpha=0.3)
    return fig


# --------------------------------------------------------------------------- public API
def plot_trajectory(result: SimResult, path: str | os.PathLike, title: str | None = None) -> Path:
    """Reference path (blue) vs driven trajectory (red) in x/y [m], equal aspect, start marker,
    lane boundaries at +-``result.lane_half_width_m`` when set, and a few predicted horizons
    (thin grey, about every 10 % of the run).  Writes a PNG; returns ``path``."""
    return _save(_make_trajectory(result, title), path)


def plot_lateral_deviation(result: SimResult, path: str | os.PathLike, log_y: bool = False) -> Path:
    """|e_y| [m] over iterations (the paper's "distance deviation"); linear y from 0 unless
    ``log_y``.  Writes a PNG; returns ``path``."""
    return _save(_make_lateral_deviation(result, log_y=log_y), path)


def plot_heading_deviation(result: SimResult, path: str | os.PathLike) -> Path:
    """Heading error e_psi [deg] over iterations.  Writes a PNG; returns ``path``."""
    return _save(_make_heading_deviation(result), path)


def plot_steering(result: SimResult, path: str | os.PathLike) -> Path:
    """Applied steering angle [deg] over iterations, with +-``meta["max_steer_rad"]`` dashed when
    recorded.  Writes a PNG; returns ``path``."""
    return _save(_make_steering(result), path)


def plot_speed(result: SimResult, path: str | os.PathLike) -> Path:
    """Speed [m/s] over iterations (reference speed dashed when the model has a ``v`` state),
    plus the acceleration input [m/s^2] when the model has one.  Writes a PNG; returns ``path``."""
    return _save(_make_speed(result), path)


def plot_overview(result: SimResult, path: str | os.PathLike) -> Path:
    """2x2 grid: trajectory, lateral deviation, heading deviation, steering (the paper's four
    figures per experiment).  Writes a PNG; returns ``path``."""
    return _save(_make_overview(result), path)


def plot_steering_comparison(results: Mapping[str, SimResult], path: str | os.PathLike,
                             title: str | None = None) -> Path:
    """Overlaid steering angles [deg] and steering rates [deg/s] of several runs, keyed by legend
    label (the input-smoothing experiment, the paper's Fig. 12).  Writes a PNG; returns ``path``."""
    return _save(_make_steering_comparison(results, title), path)


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
    from mpcdrive.plots.laps import plot_lateral_acceleration, plot_speed_map

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
    fig, axes = _new_figure()
    ax = axes[0, 0]
    c = np.asarray(result.clearance_m, dtype=float)
    ax.plot(_iterations(result), c, color=_DRIVEN_COLOR, lw=1.2, label="footprint-to-obstacle clearance")
    ax.axhline(0.0, color="k", lw=1.0, ls="--", label="contact")
    ax.set_xlabel(_ITER_LABEL)
    ax.set_ylabel("clearance [m]")
    ax.set_title(_title("Obstacle clearance", result))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_clearance(result: SimResult, path: str | os.PathLike) -> Path:
    """Smallest footprint-to-obstacle distance [m] over iterations (negative = overlap)."""
    return _save(_make_clearance(result), path)


def _make_trajectory_overlay(results: Mapping[str, SimResult], title: str | None = None) -> Figure:
    fig, axes = _new_figure(size=(8.0, 4.5))
    ax = axes[0, 0]
    first = next(iter(results.values()))
    path = np.asarray(first.path_xy, dtype=float)
    ax.plot(path[:, 0], path[:, 1], color=_REF_COLOR, lw=1.2, label="reference path")
    if first.lane_half_width_m is not None and len(path) >= 2:
        left, right = _lane_boundaries(path, float(first.lane_half_width_m))
        ax.plot(left[:, 0], left[:, 1], color="k", lw=1.0, ls="--", label="lane boundary")
        ax.plot(right[:, 0], right[:, 1], color="k", lw=1.0, ls="--")
    _draw_obstacles(ax, first)
    for name, r in results.items():
        ax.plot(r.xy[:, 0], r.xy[:, 1], lw=1.4, label=name)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or "Trajectories")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_trajectory_overlay(results: Mapping[str, SimResult], path: str | os.PathLike,
                            title: str | None = None) -> Path:
    """Several runs on the same road overlaid (obstacles and lane from the first)."""
    return _save(_make_trajectory_overlay(results, title), path)


def _make_cost_map(X: np.ndarray, Y: np.ndarray, C: np.ndarray, title: str) -> Figure:
    fig, axes = _new_figure(size=(7.0, 4.5))
    ax = axes[0, 0]
    cs = ax.contourf(X, Y, C, levels=30, cmap="viridis")
    fig.colorbar(cs, ax=ax, label="obstacle cost [-]")
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    return fig


def plot_cost_map(X: np.ndarray, Y: np.ndarray, C: np.ndarray, path: str | os.PathLike,
                  title: str = "Obstacle cost map") -> Path:
    """Filled contours of an obstacle cost evaluated on a grid (the paper's Fig. 14)."""
    return _save(_make_cost_map(X, Y, C, title), path)
