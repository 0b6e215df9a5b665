"""Markdown report of ``mpcdrive bench --report DIR`` (reads bench results, never solves)."""

from __future__ import annotations

import os
import platform
from collections.abc import Mapping
from pathlib import Path

from mpcdrive.io.atomic import atomic_write_text

__all__ = ["render_bench_report", "write_bench_report"]


def _fmt(v, nd=1) -> str:
    return "—" if v is None else f"{v:,.{nd}f}"


def _by_count(sweep: Mapping) -> dict[int, Mapping]:
    """A sweep keyed by int (JSON turns the keys into strings)."""
    return {int(k): v for k, v in sweep.items()}


def _obstacle_section(obstacles: Mapping, figure: str | None) -> list[str]:
    sweep = _by_count(obstacles)
    counts = sorted(sweep)
    lines = [
        "",
        "## P3: per-step time as obstacles are added",
        "",
        "P3 (straight line, lane |y| <= 1.75 m, Gaussian obstacle cost) with n static obstacles "
        "spread over x in [3, 10] m, every one in the problem at every step (the Gaussian terms "
        "add into each predicted step's position cost: the QP keeps its size, building the terms "
        "grows with n). `ran` is the backend that actually ran (a requested backend that does not "
        "cover the problem falls back to OSQP); clearance is between the car's footprint and the "
        "nearest obstacle over the whole drive, failures are steps whose solve did not succeed.",
        "",
        "| obstacles | backend | ran | p50 [us] | p99 [us] | max [us] | steps | min clearance [m] "
        "| solver failures | rms e_y [m] |",
        "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for n in counts:
        for b, r in sweep[n].items():
            clear = r.get("min_obstacle_clearance_m")
            lines.append(
                f"| {n} | {b} | {r.get('backend', b)} | {_fmt(r['p50_us'])} | {_fmt(r['p99_us'])} "
                f"| {_fmt(r['max_us'])} | {r['steps']} | {_fmt(clear, 3)} "
                f"| {r.get('solver_failures', '—')} | {r['rms_lateral_error_m']:.5f} |"
            )
    reasons = sorted({r["fallback"] for n in counts for r in sweep[n].values() if r.get("fallback")})
    if reasons:
        lines += ["", "Fallbacks: " + "; ".join(reasons) + "."]
    if figure:
        lines += ["", f"![per-step time vs obstacle count]({figure})"]
    return lines


def render_bench_report(
    results: Mapping,
    sweep: Mapping | None = None,
    cold: Mapping | None = None,
    alloc: Mapping | None = None,
    figure: str | None = None,
    note: str = "",
    obstacles: Mapping | None = None,
    obstacle_figure: str | None = None,
) -> str:
    """The report text: latency per problem and implementation, speed-up over the cvxpy
    rebuild, per-step time against N and against the obstacle count, cold start and memory.

    sweep : :func:`mpcdrive.bench.extras.horizon_sweep`; obstacles :
    :func:`mpcdrive.bench.extras.obstacle_sweep`; figure / obstacle_figure : their figures'
    file names relative to the report."""
    lines = ["# mpcdrive bench", ""]
    lines.append(
        f"Per-step wall time of one controller call from Python (median / p99 / max over a "
        f"closed loop, warm-up excluded), all implementations measured in the same process run. "
        f"Machine: {platform.machine()}, {os.cpu_count()} CPU(s), Python {platform.python_version()}."
    )
    if note:
        lines += ["", note]
    lines += [
        "",
        "## Latency per step",
        "",
        "| problem | implementation | p50 [us] | p99 [us] | max [us] | steps | rms e_y [m] |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for prob, impls in results.items():
        for impl, r in impls.items():
            name = impl + (f" ({r['backend']})" if impl == "mpcdrive" and "backend" in r else "")
            lines.append(
                f"| {prob} | {name} | {_fmt(r['p50_us'])} | {_fmt(r['p99_us'])} | {_fmt(r['max_us'])} "
                f"| {r['steps']} | {r['rms_lateral_error_m']:.5f} |"
            )
    ratios = []
    for prob, impls in results.items():
        fast = impls.get("mpcdrive_fast")
        for ref in ("cvxpy_rebuild", "casadi_ipopt", "mpcdrive_osqp"):
            if fast and ref in impls and fast.get("backend") == "fast":
                ratios.append(
                    f"| {prob} | {ref} | {impls[ref]['p50_us'] / fast['p50_us']:,.0f}x "
                    f"| {impls[ref]['p99_us'] / fast['p99_us']:,.0f}x |"
                )
    if ratios:
        lines += [
            "",
            "## Speed-up of the fast path (ratios within this run)",
            "",
            "| problem | over | median | p99 |",
            "|---|---|---:|---:|",
            *ratios,
        ]
    if sweep:
        Ns = sorted(int(n) for n in sweep)
        backends = sorted({b for n in Ns for b in sweep[n]})
        lines += [
            "",
            "## P1: per-step time as the horizon grows",
            "",
            "| N | " + " | ".join(f"{b} p50 / p99 [us]" for b in backends) + " |",
            "|---:|" + "---:|" * len(backends),
        ]
        for n in Ns:
            cells = [
                f"{_fmt(sweep[n][b]['p50_us'])} / {_fmt(sweep[n][b]['p99_us'])}" if b in sweep[n] else "—"
                for b in backends
            ]
            lines.append(f"| {n} | " + " | ".join(cells) + " |")
        if figure:
            lines += ["", f"![per-step time vs horizon]({figure})"]
    if obstacles:
        lines += _obstacle_section(obstacles, obstacle_figure)
    if cold:
        lines += [
            "",
            "## Cold start and memory (P1, fresh processes, compile cache warm)",
            "",
            "| backend | import + build + first step [s] | whole process, 1000 steps [s] | peak RSS [MiB] |",
            "|---|---:|---:|---:|",
        ]
        for b, r in cold.items():
            lines.append(
                f"| {b} | {r['import_build_first_step_s']:.3f} | {r['process_1000_steps_s']:.3f} "
                f"| {r['peak_rss_mib']:.0f} |"
            )
    if alloc:
        lines += [
            "",
            "## Python-heap allocations per step (tracemalloc, P1)",
            "",
            "| backend | peak extra bytes during 200 steps | retained bytes per step |",
            "|---|---:|---:|",
        ]
        for b, r in alloc.items():
            lines.append(f"| {b} | {r['peak_extra_bytes']:,} | {r['retained_bytes_per_step']:.0f} |")
    lines.append("")
    return "\n".join(lines)


def write_bench_report(
    out_dir: str | os.PathLike,
    results,
    sweep=None,
    cold=None,
    alloc=None,
    figure: str | None = None,
    note: str = "",
    obstacles=None,
    obstacle_figure: str | None = None,
) -> Path:
    """Write ``out_dir/bench.md`` (arguments as :func:`render_bench_report`); returns its path."""
    return atomic_write_text(
        Path(out_dir) / "bench.md",
        render_bench_report(results, sweep, cold, alloc, figure, note, obstacles, obstacle_figure),
    )
