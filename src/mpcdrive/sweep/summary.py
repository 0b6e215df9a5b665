"""A sweep's results: the table (CSV, and Parquet when pyarrow is installed), the summary (JSON and
markdown, explaining every failed run), histograms, and the scenario of every failed run."""

from __future__ import annotations

import csv
import io
import math
from collections import Counter
from pathlib import Path

import numpy as np

from ..io import write_json
from ..io.atomic import atomic_write_bytes, atomic_write_text
from ..types import FALLBACK_KINDS
from .runner import METRIC_COLUMNS, SweepPlan

__all__ = ["result_columns", "summarize", "summary_markdown", "write_sweep_outputs"]


def result_columns(plan: SweepPlan) -> list[str]:
    return ["run_id", "seed", *plan.varied_names, *METRIC_COLUMNS]


def _num(rows, key) -> np.ndarray:
    vals = [r.get(key) for r in rows]
    return np.array(
        [v for v in vals if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)], float
    )


def _pcts(a: np.ndarray) -> dict | None:
    if a.size == 0:
        return None
    return {
        "p5": float(np.percentile(a, 5)),
        "p50": float(np.percentile(a, 50)),
        "p95": float(np.percentile(a, 95)),
        "max": float(a.max()),
    }


def _category(reason: str) -> list[str]:
    """Short failure categories of a reason string (for counting)."""
    out = []
    for part in reason.split("; "):
        if part.startswith("invalid scenario"):
            out.append("invalid scenario")
        elif part.startswith("error:"):
            out.append("error: " + part.split(":")[1].strip())
        elif "collision" in part or part.startswith("collided"):
            out.append("collision")
        elif part.startswith("left the"):
            out.append("left the lane, already outside at the start" if "already" in part else "left the lane")
        elif "from the path (the goal allows" in part:
            out.append("final lateral error too large")
        elif part.startswith("goal not reached"):
            out.append("goal not reached")
        elif "diverged" in part:
            out.append("diverged")
        elif part:
            out.append(part)
    return out


def summarize(plan: SweepPlan, rows: list[dict], backend: str = "local") -> dict:
    """Summary of a sweep: success rate, failures (each explained), collisions, lane excess,
    fallbacks by kind, solver failures, solve-time percentiles and metric distributions."""
    n = len(rows)
    ok = [r for r in rows if r["success"]]
    failed = [r for r in rows if not r["success"]]
    ran = [r for r in rows if r["termination"] not in ("invalid", "error")]
    lane = plan.base.road is not None
    excess = _num(ran, "max_lane_excess_m")
    cats = Counter(c for r in failed for c in _category(r["failure_reason"]))
    by_kind = {k: int(sum(r.get(f"fallbacks_{k}") or 0 for r in ran)) for k in FALLBACK_KINDS}
    return {
        "scenario": plan.base.id,
        "source": plan.source,
        "runs": n,
        "seed": plan.seed,
        "backend": backend,
        "vary": [str(v) for v in plan.variations],
        "set": [str(s) for s in plan.settings],
        "criteria": plan.base.verdict.model_dump(mode="json"),  # the runs' verdict criteria, overrides applied
        "successes": len(ok),
        "failures": len(failed),
        "success_rate": len(ok) / n if n else None,
        "failure_categories": dict(cats.most_common()),
        "failed_runs": [
            {
                "run_id": r["run_id"],
                "seed": r["seed"],
                "reason": r["failure_reason"],
                "values": {k: r[k] for k in plan.varied_names},
            }
            for r in failed
        ],
        "collisions": {
            "runs": int(sum(1 for r in ran if r["collisions"])),
            "total": int(sum(r["collisions"] or 0 for r in ran)),
        },
        "lane": None
        if not lane
        else {
            "lane_width_m": plan.base.road.min_width_m,
            "runs_outside": int(np.sum(excess > 0)),
            "max_excess_m": _pcts(excess),
        },
        "fallbacks": {
            "runs_with": int(sum(1 for r in ran if r["fallbacks"])),
            "total": int(sum(r["fallbacks"] or 0 for r in ran)),
            "by_kind": by_kind,
        },
        "solver_failures": {
            "runs_with": int(sum(1 for r in ran if r["solver_failures"])),
            "total": int(sum(r["solver_failures"] or 0 for r in ran)),
        },
        # per-run percentiles combined over runs: median of the runs' p50, 99th percentile of the
        # runs' p99, largest step of all
        "solve_time_us": None
        if not ran
        else {
            "p50": float(np.median(_num(ran, "solve_time_p50_us"))),
            "p99": float(np.percentile(_num(ran, "solve_time_p99_us"), 99)),
            "max": float(np.max(_num(ran, "solve_time_max_us"))),
        },
        "metrics": {
            k: _pcts(_num(ran, k))
            for k in (
                "rms_lateral_error_m",
                "max_abs_lateral_error_m",
                "final_lateral_error_m",
                "max_abs_steer_rad",
                "max_lane_excess_m",
            )
        },
        "wall_s_per_run": _pcts(_num(rows, "wall_s")),
    }


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def summary_markdown(s: dict) -> str:
    """The summary as a markdown page."""
    L = [f"# Sweep of {s['scenario']}: {s['runs']} runs, seed {s['seed']}", ""]
    L.append(f"Backend `{s['backend']}`. Varied: " + (", ".join(f"`{v}`" for v in s["vary"]) or "nothing") + ".")
    if s["set"]:
        L.append("Set: " + ", ".join(f"`{v}`" for v in s["set"]) + ".")
    c = s["criteria"]
    L += [
        "",
        f"A run succeeds when its verdict passes: it runs without error or divergence, has no collision, "
        f"leaves the road by at most {c['max_lane_excess_m']:g} m, reaches its goal ({c['goal']}) safely and "
        f"ends within {c['max_final_lateral_error_m']:g} m of the path.",
        "",
    ]
    rate = "-" if s["success_rate"] is None else f"{100 * s['success_rate']:.1f} %"
    L += [
        "| quantity | value |",
        "|---|---|",
        f"| successes | {s['successes']} / {s['runs']} ({rate}) |",
        f"| collisions (runs / total) | {s['collisions']['runs']} / {s['collisions']['total']} |",
    ]
    if s["lane"]:
        mx = s["lane"]["max_excess_m"]
        L.append(
            f"| runs leaving the {s['lane']['lane_width_m']:g} m lane | {s['lane']['runs_outside']} "
            f"(largest excess {_fmt(mx and mx['max'])} m) |"
        )
    fb = s["fallbacks"]
    L.append(f"| fallback steps (runs with any) | {fb['total']} ({fb['runs_with']}) |")
    L.append("| fallback steps by kind | " + ", ".join(f"{k} {v}" for k, v in fb["by_kind"].items()) + " |")
    L.append(
        f"| solver failures (runs with any) | {s['solver_failures']['total']} ({s['solver_failures']['runs_with']}) |"
    )
    if s["solve_time_us"]:
        st = s["solve_time_us"]
        L.append(
            f"| step time [us]: median of run p50 / p99 of run p99 / max | {st['p50']:.0f} / {st['p99']:.0f} / {st['max']:.0f} |"
        )
    L += [
        "",
        "## Metric distributions over the runs that ran",
        "",
        "| metric | p5 | p50 | p95 | max |",
        "|---|---|---|---|---|",
    ]
    for k, p in s["metrics"].items():
        if p:
            L.append(f"| {k} | {_fmt(p['p5'])} | {_fmt(p['p50'])} | {_fmt(p['p95'])} | {_fmt(p['max'])} |")
    L += ["", f"## Failed runs ({s['failures']})", ""]
    if s["failure_categories"]:
        L.append("By cause: " + ", ".join(f"{k}: {v}" for k, v in s["failure_categories"].items()) + ".")
        L += [
            "",
            "Each failed run's scenario is in `failed/run-NNNN.yaml`: `mpcdrive run failed/run-NNNN.yaml` replays it.",
            "",
        ]
        names = list(s["failed_runs"][0]["values"])
        L.append("| run | seed | " + " | ".join(names) + " | reason |")
        L.append("|---|---|" + "---|" * len(names) + "---|")
        for f in s["failed_runs"]:
            L.append(
                f"| {f['run_id']} | {f['seed']} | "
                + " | ".join(_fmt(f["values"][k]) for k in names)
                + f" | {f['reason']} |"
            )
    else:
        L.append("None.")
    L += [
        "",
        "Figures: `histograms.png` (metric distributions), `varied.png` (each varied value against the "
        "lateral error, failures marked).",
        "",
    ]
    return "\n".join(L)


def _csv_cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def _write_table(rows: list[dict], columns: list[str], out: Path) -> list[Path]:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([_csv_cell(r.get(c)) for c in columns])
    written = [atomic_write_text(out / "runs.csv", buf.getvalue())]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return written
    table = pa.Table.from_pylist([{c: r.get(c) for c in columns} for r in rows])
    sink = io.BytesIO()
    pq.write_table(table, sink)
    written.append(atomic_write_bytes(out / "runs.parquet", sink.getvalue()))
    return written


def write_sweep_outputs(plan: SweepPlan, rows: list[dict], out: Path, backend: str = "local") -> dict:
    """Write the table, summary, figures and failed runs' scenarios into ``out``; return the summary."""
    import yaml

    from ..plots.sweep import plot_sweep_histograms, plot_sweep_varied
    from ..scenarios import dump_scenario

    out = Path(out)
    _write_table(rows, result_columns(plan), out)
    s = summarize(plan, rows, backend)
    write_json(out / "summary.json", s)
    atomic_write_text(out / "summary.md", summary_markdown(s))
    atomic_write_text(out / "base_scenario.yaml", dump_scenario(plan.base))
    tasks = {t.run_id: t for t in plan.tasks}
    for f in s["failed_runs"]:
        t = tasks[f["run_id"]]
        header = f"# sweep run {t.run_id} (seed {t.seed}) failed: {f['reason']}\n"
        body = (
            yaml.safe_dump(t.scenario, sort_keys=False)
            if t.scenario is not None
            else ("# not a valid scenario; the varied values were:\n" + yaml.safe_dump(t.values, sort_keys=False))
        )
        atomic_write_text(out / "failed" / f"run-{t.run_id:04d}.yaml", header + body)
    plot_sweep_histograms(rows, out / "histograms.png", lane=plan.base.road is not None)
    if plan.varied_names:
        plot_sweep_varied(rows, plan.varied_names, out / "varied.png")
    return s
