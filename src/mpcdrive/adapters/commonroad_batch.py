"""Drive many CommonRoad files and judge each with CommonRoad's checkers (``mpcdrive commonroad``).

Each file is imported (:func:`~.commonroad.load_commonroad`), driven, written into
``OUT/<file stem>/`` exactly as ``mpcdrive run`` writes a run (:func:`mpcdrive.runs.run_into`)
and checked with the drivability checker; ``OUT/summary.json`` maps each file name to its row
(:data:`ROW_FIELDS`) and ``OUT/summary.md`` shows them as a table. A file that cannot be read,
routed or driven is a row with its ``error``, never the end of the batch. Runs go to a local
process pool or to Ray (:func:`mpcdrive.sweep.runner.run_parallel`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from ..sim.verdict import LANE_TOLERANCE_M

ROW_FIELDS = (
    "passed",
    "collision_free",
    "road_compliant",
    "ks_feasible",
    "goal_reached",
    "min_obstacle_clearance_m",
    "solver_failures",
    "solve_time_us",
    "wall_s",
    "error",
    "whole_drive",
)
SUFFIXES = (".xml", ".xml.gz")


def file_stem(path: str | Path) -> str:
    """The file name without ``.xml`` / ``.xml.gz`` (the name of its output folder)."""
    name = Path(path).name
    for suf in (".xml.gz", ".xml"):
        if name.lower().endswith(suf):
            return name[: -len(suf)]
    return Path(name).stem


def collect_files(args) -> list[Path]:
    """The scenario files named by ``args`` (files, or folders: their ``.xml`` / ``.xml.gz``
    files, sorted); ValueError for a name that is neither or a folder without any."""
    files: list[Path] = []
    for a in args:
        p = Path(a)
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if f.is_file() and f.name.lower().endswith(SUFFIXES))
            if not found:
                raise ValueError(f"{p}: no CommonRoad files (.xml, .xml.gz) in this folder")
            files += found
        elif p.is_file():
            files.append(p)
        else:
            raise ValueError(f"{p}: no such file or folder")
    stems = [file_stem(f) for f in files]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise ValueError(f"two files would share the output folder {dup[0]!r}: pass one of them")
    return files


def configure_import(imp, vehicle=None, plant=None, traffic=None, prediction=None):
    """``imp`` with the vehicle and plant (:func:`~.commonroad.with_vehicle`), then the traffic
    and prediction (:func:`~.commonroad_traffic.with_traffic`)."""
    from .commonroad import with_vehicle
    from .commonroad_traffic import with_traffic

    return with_traffic(with_vehicle(imp, vehicle, plant), traffic, prediction)


@dataclass(frozen=True)
class BatchTask:
    """One file to drive into ``out_dir`` (``configure(imp) -> imp`` adapts the import, e.g. the
    vehicle; a top-level function so a process pool can ship it)."""

    file: str
    out_dir: str
    configure: object = None


def _empty_row() -> dict:
    return {
        "passed": False,
        "collision_free": None,
        "road_compliant": None,
        "ks_feasible": None,
        "goal_reached": None,
        "min_obstacle_clearance_m": None,
        "solver_failures": None,
        "solve_time_us": {"p50": None, "p99": None},
        "wall_s": 0.0,
        "error": None,
        "min_obstacle_clearance_whole_run_m": None,
        "solution_valid": None,
        "solution_check": None,
        "plan": None,
        "traffic": None,
        "prediction": None,
        "sumo": None,
        "whole_drive": None,
        "planner": None,
    }


def crashed_row(task: BatchTask, reason: str) -> dict:
    """The row of a file whose run's process died (a crash in compiled code): an error naming it;
    no run folder is kept."""
    import shutil

    row = _empty_row()
    row.update(file=Path(task.file).name, error=f"the run crashed: {reason}")
    shutil.rmtree(task.out_dir, ignore_errors=True)
    return row


def drive_file(task: BatchTask) -> dict:
    """Import, drive, write and check one file; its summary row (with ``file``). Never raises:
    a failure is the row's ``error``."""
    from ..runs import run_into
    from .commonroad import load_commonroad
    from .commonroad_vehicles import commonroad_plant

    t0 = time.perf_counter()
    row = _empty_row()
    row["file"] = Path(task.file).name
    try:
        imp = load_commonroad(task.file)
        if task.configure is not None:
            imp = task.configure(imp)
        row.update(traffic=imp.traffic, prediction=imp.prediction)
        res, m, _, _ = run_into(
            imp.spec,
            Path(task.out_dir),
            source=task.file,
            extra_outputs=imp.write_outputs,
            prepare=imp.prepare_experiment,
            plant_factory=commonroad_plant,
        )
        cr = m.commonroad
        if cr is None:
            raise RuntimeError("the run has no CommonRoad checks")
        st = m.solve_time_us
        row.update(
            passed=bool(cr.passed),
            collision_free=cr.collision_free,
            road_compliant=cr.road_compliant,
            ks_feasible=cr.ks_feasible,
            goal_reached=cr.goal_reached,
            # over the drive the checker judged (up to the goal), and over the whole run
            min_obstacle_clearance_m=_min_clearance(res, cr.states_checked),
            min_obstacle_clearance_whole_run_m=_min_clearance(res, None),
            solver_failures=m.solver_failures,
            solve_time_us={"p50": st.p50, "p99": st.p99},
            solution_valid=cr.solution_valid,
            solution_check=cr.solution_check,
            vehicle_model=cr.vehicle_model,
            plan=cr.plan,
            sumo=_sumo_row(Path(task.out_dir)),
            whole_drive=None if cr.whole_drive is None else cr.whole_drive.as_dict(),
            planner=m.planner,
        )
    except Exception as e:  # a file's failure is its row; the batch goes on
        import shutil

        row["error"] = " ".join(f"{type(e).__name__}: {e}".split())[:400]
        shutil.rmtree(task.out_dir, ignore_errors=True)  # no half-written run folder
    row["wall_s"] = time.perf_counter() - t0
    return row


def _sumo_row(out_dir: Path) -> dict | None:
    """A SUMO drive's figures for the row (from its ``sumo.json``): vehicles, SUMO's step time
    [ms], the whole drive's checks, progress [m] and comfort of the ego and of the SUMO driver."""
    import json

    f = out_dir / "sumo.json"
    if not f.is_file():
        return None
    d = json.loads(f.read_text())
    keys = ("progress_m", "rms_accel_mps2", "rms_jerk_mps3", "goal_reached")
    return {
        "vehicles_simulated": d["vehicles_simulated"],
        "vehicles_recorded": len(d["vehicles_recorded"]),
        "step_ms": {"p50": d["sumo_step_ms"]["p50"], "p99": d["sumo_step_ms"]["p99"]},
        "cosim_step_ms": {k: (d.get("cosim_step_ms") or {}).get(k) for k in ("p50", "p99")},
        "whole_drive": d["whole_drive"],
        "position_jumps": len(d.get("position_jumps", [])),
        "ego": {k: d["ego"].get(k) for k in keys},
        "sumo_driver": {k: d["sumo_driver"].get(k) for k in keys},
    }


def _min_clearance(result, n: int | None) -> float | None:
    """Smallest footprint-to-obstacle distance [m] over the first ``n`` states (all: None);
    None without obstacles."""
    import numpy as np

    c = result.clearance_m
    if c is None:
        return None
    c = np.asarray(c, float)[:n]
    c = c[np.isfinite(c)]
    return float(c.min()) if c.size else None


def verdict(row: dict) -> str:
    """One word or phrase for a row: passed, the failed checks, or error."""
    if row.get("error"):
        return f"error: {row['error']}"
    if row["passed"]:
        return "passed"
    infeasible = f"{row.get('vehicle_model') or 'KS'}-infeasible"  # under the solution's model
    failed = [
        name
        for key, name in (
            ("collision_free", "collision"),
            ("road_compliant", "off road"),
            ("ks_feasible", infeasible),
            ("goal_reached", "goal missed"),
        )
        if row.get(key) is False
    ]
    if not failed and row.get("solution_valid") is False:
        failed = [f"solution rejected by valid_solution ({row.get('solution_check')})"]
    failed += [name for name in _whole_drive_failures(row) if name not in failed]
    return "failed: " + ", ".join(failed or ["unknown"])


def _whole_drive_failures(row: dict) -> list[str]:
    """The checks of the whole drive (``row["whole_drive"]``) that failed where the checks up to
    the goal did not: ``collision after the goal``, ``off road beyond the road's start or end``, ..."""
    w = row.get("whole_drive") or {}
    after = " after the goal" if row.get("goal_reached") else ""
    out = []
    for key, up_to_goal, name in (
        ("collision_free", "collision_free", "collision"),
        ("road_compliant", "road_compliant", "off road"),
        ("feasible", "ks_feasible", f"{row.get('vehicle_model') or 'KS'}-infeasible"),
    ):
        if w.get(key) is False and row.get(up_to_goal) is not False:
            beyond = key == "road_compliant" and (w.get("past_road_end_m") or 0.0) > LANE_TOLERANCE_M
            out.append(name + (" beyond the road's start or end" if beyond else after))
    return out


def _whole_drive_cell(r: dict) -> str:
    """``yes``, or what failed first over the whole drive and when: ``no: off road 10.7 s (2.25 m
    beyond its start or end)``; ``-`` without the checks."""
    w = r.get("whole_drive")
    if not w:
        return "-"
    if w.get("passed"):
        return "yes"
    failed = []
    for key, t_key, name in (
        ("collision_free", "collision_t_s", "collision"),
        ("road_compliant", "off_road_t_s", "off road"),
        ("feasible", "infeasible_t_s", "infeasible"),
    ):
        if w.get(key) is False:
            t = w.get(t_key)
            failed.append(name + ("" if t is None else f" {t:.1f} s"))
            if key == "road_compliant" and (w.get("past_road_end_m") or 0.0) > LANE_TOLERANCE_M:
                failed[-1] += f" ({w['past_road_end_m']:.2f} m beyond its start or end)"
    return "no: " + ", ".join(failed)


def _cell(v, fmt="{:.2f}") -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return fmt.format(v)
    return str(v)


def _clearance_cell(r: dict) -> str:
    c, whole = r["min_obstacle_clearance_m"], r.get("min_obstacle_clearance_whole_run_m")
    if whole is not None and (c is None or whole < c):
        return f"{_cell(c)} ({_cell(whole)})"
    return _cell(c)


def _planner_cell(r: dict) -> str:
    """The replanning column: wall time p50 / p99 [us] and pairs checked / sampled (medians)."""
    p = r.get("planner")
    if not p or not p.get("replannings"):
        return "-"
    t = p["plan_time_us"]
    return f"{t['p50']:.0f} / {t['p99']:.0f} ({p['checked']['p50']:.0f} / {p['sampled']['p50']:.0f})"


def summary_markdown(rows: dict, header: str = "") -> str:
    """``summary.md``: one table row per file, then the errors in words."""
    n = len(rows)
    passed = sum(1 for r in rows.values() if r["passed"])
    lines = [
        "# CommonRoad batch",
        "",
        header,
        "",
        f"{passed} of {n} files passed (collision-free, on the road, feasible and at the goal, as "
        "CommonRoad's drivability checker judges the drive up to the goal, and the solution accepted by "
        "CommonRoad's solution checker; and the whole drive, start to end of the run, collision-free, on "
        "the road and not past its mapped end, and feasible). Feasible: under the solution's vehicle model, "
        "KS (ST for a drive on the ST plant). The columns collision-free to goal reached are up to the goal; "
        "whole drive: the checks of the whole drive (what failed first, when).",
        "",
        "Min clearance: footprint to obstacle over the checked drive (whole run in brackets when smaller). "
        "Step: the controller's whole step (maneuver planner, obstacle terms, QP), wall time. "
        "Replanning: the maneuver planner's call, wall time, median / p99, and the candidate pairs it "
        "checked of those it sampled (median).",
        "",
        "Traffic: recorded (replayed) or sumo (SUMO drives the vehicles, reacting to the ego); prediction: "
        "known (the recorded futures) or lane (constant speed along the lane, growing uncertainty).",
        "",
        "| file | verdict | collision-free | road-compliant | feasible | goal reached | whole drive | "
        "min clearance [m] | solver failures | step p50 / p99 [us] | replanning p50 / p99 [us] (checked / sampled) | "
        "wall [s] | traffic / prediction |",
        "|" + "---|" * 13,
    ]
    for name, r in rows.items():
        st = r["solve_time_us"]
        lines.append(
            f"| `{name}` | {'error' if r.get('error') else verdict(r).split(' (')[0]} | {_cell(r['collision_free'])} | "
            f"{_cell(r['road_compliant'])} | {_cell(r['ks_feasible'])} | {_cell(r['goal_reached'])} | "
            f"{_whole_drive_cell(r)} | {_clearance_cell(r)} | {_cell(r['solver_failures'])} | "
            f"{_cell(st['p50'], '{:.0f}')} / {_cell(st['p99'], '{:.0f}')} | {_planner_cell(r)} | "
            f"{_cell(r['wall_s'], '{:.1f}')} | "
            f"{r.get('traffic') or '-'} / {r.get('prediction') or '-'} |"
        )
    rejected = [
        (k, r.get("solution_check"))
        for k, r in rows.items()
        if not r.get("error") and r.get("solution_valid") is False and verdict(r).startswith("failed: solution")
    ]
    if rejected:
        lines += ["", "## Solutions CommonRoad's solution checker rejects", ""] + [f"- `{k}`: {e}" for k, e in rejected]
    sumo = [(k, r["sumo"]) for k, r in rows.items() if r.get("sumo")]
    if sumo:
        lines += [
            "",
            "## Among SUMO traffic",
            "",
            "Whole drive: the drivability checker over the whole drive against the vehicles as SUMO drove them. "
            "Progress along the reference path [m] and RMS acceleration [m/s^2] of the ego, and of a SUMO driver "
            "put in its place on its route (same start, same traffic). SUMO step: wall time [ms].",
            "",
            "| file | vehicles (SUMO / recorded) | whole drive collision-free / on road | ego progress / RMS accel | "
            "SUMO driver progress / RMS accel | SUMO step p50 / p99 [ms] |",
            "|" + "---|" * 6,
        ]
        for k, d in sumo:
            w = d.get("whole_drive") or {}
            e, b = d["ego"], d["sumo_driver"]
            lines.append(
                f"| `{k}` | {d['vehicles_simulated']} / {d['vehicles_recorded']} | {_cell(w.get('collision_free'))} / "
                f"{_cell(w.get('road_compliant'))} | {_cell(e['progress_m'], '{:.1f}')} / "
                f"{_cell(e['rms_accel_mps2'])} | {_cell(b['progress_m'], '{:.1f}')} / {_cell(b['rms_accel_mps2'])} | "
                f"{_cell(d['step_ms']['p50'])} / {_cell(d['step_ms']['p99'])} |"
            )
    errors = [(k, r["error"]) for k, r in rows.items() if r.get("error")]
    if errors:
        lines += ["", "## Errors", ""] + [f"- `{k}`: {e}" for k, e in errors]
    return "\n".join(lines) + "\n"


def run_batch(
    files, out_dir: Path, *, workers: int | None = None, backend: str = "local", configure=None, progress=None
) -> dict:
    """Drive every file into ``out_dir/<stem>/``, write ``summary.json`` and ``summary.md``, and
    return the rows by file name (in the order given). ``progress(k, n, row)`` as each finishes."""
    from ..io import write_json
    from ..io.atomic import atomic_write_text
    from ..sweep.runner import run_parallel

    out_dir = Path(out_dir)
    tasks = [BatchTask(str(f), str(out_dir / file_stem(f)), configure) for f in files]
    got = run_parallel(drive_file, tasks, backend, workers, progress=progress, crashed=crashed_row)
    by_name = {r["file"]: r for r in got}
    rows = {Path(f).name: {k: v for k, v in by_name[Path(f).name].items() if k != "file"} for f in files}
    write_json(out_dir / "summary.json", rows)
    atomic_write_text(out_dir / "summary.md", summary_markdown(rows, f"{len(rows)} files, backend {backend}."))
    return rows
