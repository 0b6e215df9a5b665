"""Record commonroad-route-planner's routes for the CommonRoad files beside this script.

commonroad-route-planner pins osqp 0.6.7, which cannot sit next to mpcdrive's osqp >= 1, so it is
an oracle run in its own environment, not a dependency. Regenerate the fixture with:

    python -m venv rp && rp/bin/pip install commonroad-route-planner commonroad-io==2024.3
    rp/bin/python tests/data/commonroad/record_routes.py

It writes ``route_planner_routes.json`` beside this script: per file, the planner's version, the
start and goal lanelets it found and every route it planned (lanelet ids, start to goal; a
survival route when the goal names no lanelet). ``tests/test_commonroad.py`` compares mpcdrive's
routes with it.
"""

from __future__ import annotations

import gzip
import json
import sys
from importlib.metadata import version
from pathlib import Path

from commonroad.common.file_reader import CommonRoadFileReader
from commonroad_route_planner.route_planner import RoutePlanner

HERE = Path(__file__).resolve().parent


def _read(path: Path):
    if path.suffix == ".gz":
        with gzip.open(path, "rt", encoding="utf-8") as f:
            text = f.read()
        tmp = HERE / ".route_planner_tmp.xml"
        tmp.write_text(text, encoding="utf-8")
        try:
            return CommonRoadFileReader(str(tmp)).open()
        finally:
            tmp.unlink()
    return CommonRoadFileReader(str(path)).open()


def main() -> int:
    out = {"commonroad-route-planner": version("commonroad-route-planner"), "files": {}}
    for path in sorted([*HERE.glob("*.xml"), *HERE.glob("*.xml.gz")]):
        scenario, problems = _read(path)
        pp = next(iter(problems.planning_problem_dict.values()))
        rp = RoutePlanner(scenario.lanelet_network, pp, scenario)
        try:
            routes = [list(map(int, r.lanelet_ids)) for r in rp.plan_routes()]
            err = None
        except Exception as exc:  # recorded, never hidden
            routes, err = [], f"{type(exc).__name__}: {exc}"
        out["files"][path.name] = {
            "start_lanelets": sorted(int(i) for i in rp._id_lanelets_start),
            "goal_lanelets": sorted(int(i) for i in rp._ids_lanelets_goal),
            "routes": routes,
            "error": err,
        }
        print(path.name, out["files"][path.name]["goal_lanelets"], routes[:3], err or "", file=sys.stderr)
    (HERE / "route_planner_routes.json").write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
