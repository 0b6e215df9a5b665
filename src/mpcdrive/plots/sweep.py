"""Figures of a Monte Carlo sweep (rows of the results table); read results, never solve.

``make_*`` build a :class:`~matplotlib.figure.Figure` (tests check its structure); ``plot_*``
write it as PNG atomically and return the path.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from mpcdrive.plots.common import new_figure as _new_figure, save as _save

__all__ = ["make_sweep_histograms", "make_sweep_varied", "plot_sweep_histograms", "plot_sweep_varied"]

#: (column, axis label with unit) of the histogram panels
HISTOGRAMS = (
    ("rms_lateral_error_m", "RMS lateral error [m]"),
    ("final_lateral_error_m", "final |lateral error| [m]"),
    ("max_abs_steer_rad", "max |steering| [rad]"),
    ("max_lane_excess_m", "max lane excess [m]"),
    ("fallbacks", "fallback steps per run [-]"),
    ("solve_time_p99_us", "step time p99 [us]"),
)


def _values(rows, key) -> np.ndarray:
    out = []
    for r in rows:
        v = r.get(key)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
            out.append(float(v))
    return np.array(out, float)


def make_sweep_histograms(rows: list[dict], lane: bool = True) -> Figure:
    """Histograms of the key metrics over the runs that ran (one panel each)."""
    panels = [(k, lab) for k, lab in HISTOGRAMS if lane or k != "max_lane_excess_m"]
    ncols = 3
    nrows = math.ceil(len(panels) / ncols)
    fig, axes = _new_figure(nrows, ncols, size=(11.0, 3.2 * nrows))
    n_ok = sum(1 for r in rows if r.get("success"))
    fig.suptitle(f"Sweep: {len(rows)} runs, {n_ok} successful")
    for ax, (key, label) in zip(axes.flat, panels):
        v = _values(rows, key)
        if v.size:
            ax.hist(v, bins=min(30, max(5, int(math.sqrt(v.size)) + 1)), color="tab:blue", alpha=0.8)
        else:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        ax.set_xlabel(label)
        ax.set_ylabel("runs [-]")
    for ax in list(axes.flat)[len(panels) :]:
        ax.set_visible(False)
    return fig


def make_sweep_varied(rows: list[dict], names: list[str], metric: str = "rms_lateral_error_m") -> Figure:
    """Each varied value against ``metric`` (one panel per varied value), failed runs in red."""
    ncols = min(3, len(names))
    nrows = math.ceil(len(names) / ncols)
    fig, axes = _new_figure(nrows, ncols, size=(3.8 * ncols, 3.2 * nrows))
    ok = [r for r in rows if r.get("success")]
    bad = [r for r in rows if not r.get("success")]
    for ax, name in zip(axes.flat, names):
        for group, colour, label in ((ok, "tab:blue", "success"), (bad, "tab:red", "failed")):
            pts = [
                (r[name], r.get(metric))
                for r in group
                if isinstance(r.get(metric), (int, float)) and r.get(metric) is not None and math.isfinite(r[metric])
            ]
            if pts:
                a = np.array(pts, float)
                ax.plot(a[:, 0], a[:, 1], "o", ms=3, color=colour, label=label)
        ax.set_xlabel(name)
        ax.set_ylabel("RMS lateral error [m]" if metric == "rms_lateral_error_m" else metric)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    for ax in list(axes.flat)[len(names) :]:
        ax.set_visible(False)
    return fig


def plot_sweep_histograms(rows: list[dict], path: str | os.PathLike, lane: bool = True) -> Path:
    return _save(make_sweep_histograms(rows, lane), path)


def plot_sweep_varied(rows: list[dict], names: list[str], path: str | os.PathLike) -> Path:
    return _save(make_sweep_varied(rows, names), path)
