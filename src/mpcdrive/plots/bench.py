"""Figures of the bench report: per-step time against the horizon length and against the
obstacle count (read results, never solve)."""

from __future__ import annotations

import io
import os
from collections.abc import Mapping
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mpcdrive.io.atomic import atomic_write_bytes

__all__ = ["make_horizon_figure", "make_obstacle_figure", "plot_horizon_scaling", "plot_obstacle_scaling"]

_COLORS = {"fast": "tab:green", "osqp": "tab:blue"}


def _latency_lines(ax, sweep: Mapping[int, Mapping[str, Mapping]]) -> dict:
    """Median (solid) and p99 (dashed) lines per backend of a sweep ``{x: {backend: figures}}``
    (integer x); returns ``{backend: [(x, figures), ...]}``."""
    xs_all = sorted(sweep)
    out = {}
    for b in sorted({b for n in xs_all for b in sweep[n]}):
        pts = [(n, sweep[n][b]) for n in xs_all if b in sweep[n]]
        xs = [n for n, _ in pts]
        color = _COLORS.get(b)
        ax.plot(xs, [r["p50_us"] for _, r in pts], "o-", color=color, label=f"{b} median")
        ax.plot(xs, [r["p99_us"] for _, r in pts], "s--", color=color, alpha=0.6, label=f"{b} p99")
        out[b] = pts
    return out


def make_horizon_figure(
    sweep: Mapping[int, Mapping[str, Mapping]], title: str = "P1: per-step time vs horizon"
) -> Figure:
    """Median (solid) and p99 (dashed) per-step time [us] against N for each backend, log scale.

    sweep : ``{N: {backend: {"p50_us", "p99_us", ...}}}`` as :func:`mpcdrive.bench.extras.horizon_sweep`."""
    fig = Figure(figsize=(7.0, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    _latency_lines(ax, {int(n): v for n, v in sweep.items()})
    ax.set_yscale("log")
    ax.set_xlabel("horizon N [steps]")
    ax.set_ylabel("controller step [us]")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return fig


def make_obstacle_figure(
    sweep: Mapping[int, Mapping[str, Mapping]], title: str = "P3: per-step time vs obstacle count"
) -> Figure:
    """Median (solid) and p99 (dashed) per-step time [us] against the obstacle count for each
    requested backend, log scale; where a backend fell back to another one (its ``backend``
    field differs from the requested name) the point is also circled, open.

    sweep : ``{n: {backend: {"p50_us", "p99_us", "backend", ...}}}`` as
    :func:`mpcdrive.bench.extras.obstacle_sweep` (keys may be strings, as read from JSON)."""
    fig = Figure(figsize=(7.0, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    sweep = {int(n): v for n, v in sweep.items()}
    counts = sorted(sweep)
    for b, pts in _latency_lines(ax, sweep).items():
        color = _COLORS.get(b)
        fell = [(n, r) for n, r in pts if r.get("backend", b) != b]
        if fell:
            ran = sorted({r["backend"] for _, r in fell})
            ax.scatter(
                [n for n, _ in fell] * 2,
                [r["p50_us"] for _, r in fell] + [r["p99_us"] for _, r in fell],
                s=140,
                facecolors="none",
                edgecolors=color,
                label=f"{b} requested, {', '.join(ran)} ran",
            )
    ax.set_yscale("log")
    ax.set_xticks(counts)
    ax.set_xlabel("obstacles [count]")
    ax.set_ylabel("controller step [us]")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")
    return fig


def _write_png(fig: Figure, path: str | os.PathLike) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    fig.clear()
    return atomic_write_bytes(path, buf.getvalue())


def plot_horizon_scaling(sweep, path: str | os.PathLike) -> Path:
    """Write :func:`make_horizon_figure` as a PNG atomically; return the path."""
    return _write_png(make_horizon_figure(sweep), path)


def plot_obstacle_scaling(sweep, path: str | os.PathLike) -> Path:
    """Write :func:`make_obstacle_figure` as a PNG atomically; return the path."""
    return _write_png(make_obstacle_figure(sweep), path)
