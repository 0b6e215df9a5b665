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


def render_bench_report(results: Mapping, sweep: Mapping | None = None, cold: Mapping | None = None,
                        alloc: Mapping | None = None, figure: str | None = None, note: str = "") -> str:
    """The report text: latency per problem and implementation, speed-up over the cvxpy
    rebuild, per-step time against N, cold start and memory."""
    lines = ["# mpcdrive bench", ""]
    lines.append(f"Per-step wall time of one controller call from Python (median / p99 / max over a "
                 f"closed loop, warm-up excluded), all implementations measured in the same process run. "
                 f"Machine: {platform.machine()}, {os.cpu_count()} CPU(s), Python {platform.python_version()}.")
    if note:
        lines += ["", note]
    lines += ["", "## Latency per step", "",
              "| problem | implementation | p50 [us] | p99 [us] | max [us] | steps | rms e_y [m] |",
              "|---|---|---:|---:|---:|---:|---:|"]
    for prob, impls in results.items():
        for impl, r in impls.items():
            name = impl + (f" ({r['backend']})" if impl == "mpcdrive" and "backend" in r else "")
            lines.append(f"| {prob} | {name} | {_fmt(r['p50_us'])} | {_fmt(r['p99_us'])} | {_fmt(r['max_us'])} "
                         f"| {r['steps']} | {r['rms_lateral_error_m']:.5f} |")
    ratios = []
    for prob, impls in results.items():
        fast = impls.get("mpcdrive_fast")
        for ref in ("cvxpy_rebuild", "casadi_ipopt", "mpcdrive_osqp"):
            if fast and ref in impls and fast.get("backend") == "fast":
                ratios.append(f"| {prob} | {ref} | {impls[ref]['p50_us'] / fast['p50_us']:,.0f}x "
                              f"| {impls[ref]['p99_us'] / fast['p99_us']:,.0f}x |")
    if ratios:
        lines += ["", "## Speed-up of the fast path (ratios within this run)", "",
                  "| problem | over | median | p99 |", "|---|---|---:|---:|", *ratios]
    if sweep:
        Ns = sorted(int(n) for n in sweep)
        backends = sorted({b for n in Ns for b in sweep[n]})
        lines += ["", "## P1: per-step time as the horizon grows", "",
                  "| N | " + " | ".join(f"{b} p50 / p99 [us]" for b in backends) + " |",
                  "|---:|" + "---:|" * len(backends)]
        for n in Ns:
            cells = [f"{_fmt(sweep[n][b]['p50_us'])} / {_fmt(sweep[n][b]['p99_us'])}" if b in sweep[n] else "—"
                     for b in backends]
            lines.append(f"| {n} | " + " | ".join(cells) + " |")
        if figure:
            lines += ["", f"![per-step time vs horizon]({figure})"]
    if cold:
        lines += ["", "## Cold start and memory (P1, fresh processes, compile cache warm)", "",
                  "| backend | import + build + first step [s] | whole process, 1000 steps [s] | peak RSS [MiB] |",
                  "|---|---:|---:|---:|"]
        for b, r in cold.items():
            lines.append(f"| {b} | {r['import_build_first_step_s']:.3f} | {r['process_1000_steps_s']:.3f} "
                         f"| {r['peak_rss_mib']:.0f} |")
    if alloc:
        lines += ["", "## Python-heap allocations per step (tracemalloc, P1)", "",
                  "| backend | peak extra bytes during 200 steps | retained bytes per step |", "|---|---:|---:|"]
        for b, r in alloc.items():
            lines.append(f"| {b} | {r['peak_extra_bytes']:,} | {r['retained_bytes_per_step']:.0f} |")
    lines += ["", "Obstacle sweep (0..20 obstacles): not yet measured -- the QP has no obstacle terms yet.", ""]
    return "\n".join(lines)


def write_bench_report(out_dir: str | os.PathLike, results, sweep=None, cold=None, alloc=None,
                       figure: str | None = None, note: str = "") -> Path:
    """Write ``out_dir/bench.md``; returns its path."""
    return atomic_write_text(Path(out_dir) / "bench.md",
                             render_bench_report(results, sweep, cold, alloc, figure, note))
