"""Figure of the bench report: per-step time against the horizon length (reads results)."""

from __future__ import annotations

import io
import os
from collections.abc import Mapping
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mpcdrive.io.atomic import atomic_write_bytes

__all__ = ["make_horizon_figure", "plot_horizon_scaling"]

_COLORS = {"fast": "tab:green", "osqp": "tab:blue"}


def make_horizon_figure(sweep: Mapping[int, Mapping[str, Mapping]], title: str = "P1: per-step time vs horizon") -> Figure:
    """Median (solid) and p99 (dashed) per-step time [us] against N for each backend, log scale.

    sweep : ``{N: {backend: {"p50_us", "p99_us", ...}}}`` as :func:`mpcdrive.bench.extras.horizon_sweep`."""
    fig = Figure(figsize=(7.0, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    Ns = sorted(int(n) for n in sweep)
    backends = sorted({b for n in Ns for b in sweep[n]})
    for b in backends:
        pts = [(n, sweep[n][b]) for n in Ns if b in sweep[n]]
        xs = [n for n, _ in pts]
        color = _COLORS.get(b)
        ax.plot(xs, [r["p50_us"] for _, r in pts], "o-", color=color, label=f"{b} median")
        ax.plot(xs, [r["p99_us"] for _, r in pts], "s--", color=color, alpha=0.6, label=f"{b} p99")
    ax.set_yscale("log")
    ax.set_xlabel("horizon N [steps]")
    ax.set_ylabel("controller step [us]")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return fig


def plot_horizon_scaling(sweep, path: str | os.PathLike) -> Path:
    """Write :func:`make_horizon_figure` as a PNG atomically; return the path."""
    fig = make_horizon_figure(sweep)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    fig.clear()
    return atomic_write_bytes(path, buf.getvalue())
