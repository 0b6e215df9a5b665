"""CommonRoad import / export, judged by CommonRoad's own drivability checker.

The scenario files are real CommonRoad scenarios kept in ``tests/data/commonroad`` (provenance,
licences and checksums in the README there).
"""

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mpcdrive.adapters.commonroad import available

if not available():
    pytest.skip("the commonroad extra (commonroad-io, commonroad-drivability-checker) is not installed",
                allow_module_level=True)

from mpcdrive.adapters.commonroad import check_drive, load_commonroad, write_solution  # noqa: E402
from mpcdrive.scenarios import build_experiment, run_experiment  # noqa: E402
from mpcdrive.sim import compute_metrics  # noqa: E402

DIR = Path(__file__).resolve().parent / "data" / "commonroad"

# scenario file -> (route lanelets, obstacles); the first route lanelet holds the start
EXPECTED_IMPORT = {
    "ZAM_Tutorial_Urban-3_2.xml": ((1,), 1),
    "ZAM_Tutorial-1_1_T-1.xml": ((1,), 1),
    "ZAM_Tutorial-1_2_T-1.xml": ((1,), 3),
    "C-DEU_B471-2_1.xml": ((31538, 31540), 0),
    "FRA_Anglet-1_1_T-1.xml": ((85819,), 8),
}

_DRIVES: dict = {}


def drive(name: str):
    """Import, build and run a scenario once per session: (import, result, metrics)."""
    if name not in _DRIVES:
        imp = load_commonroad(DIR / name)
        exp = build_experiment(imp.spec)
        res = run_experiment(exp)
        _DRIVES[name] = (imp, res, compute_metrics(res, exp.footprint))
    return _DRIVES[name]


@pytest.mark.parametrize("name", sorted(EXPECTED_IMPORT))
def test_import_maps_route_obstacles_and_initial_state(name):
    imp = load_commonroad(DIR / name)
    route, n_obstacles = EXPECTED_IMPORT[name]
    assert imp.route == route
    spec = imp.spec
    assert len(spec.obstacles) == n_obstacles
    assert spec.dt_s == pytest.approx(imp.scenario.dt)
    init = imp.planning_problem.initial_state
    assert (spec.initial_state.x_m, spec.initial_state.y_m) == pytest.approx(tuple(init.position))
    assert math.radians(spec.initial_state.yaw_deg) == pytest.approx(init.orientation)
    assert spec.initial_state.v_mps == pytest.approx(init.velocity)
    assert spec.vehicle.model == "kinematic4" and spec.vehicle.preset == "commonroad_ford_escort"
    assert spec.avoidance.formulation == "hard"
    # the path starts next to the car and the lane is the route lanelets' narrowest width
    assert np.hypot(*(imp.centerline[0] - init.position)) < 3.0
    net = imp.scenario.lanelet_network
    widths = [np.hypot(*(net.find_lanelet_by_id(i).left_vertices - net.find_lanelet_by_id(i).right_vertices).T).min()
              for i in route]
    assert spec.road.lane_width_m == pytest.approx(min(widths))
    # dynamic obstacles carry their recorded trajectories as known predictions
    for o, entry in zip(imp.scenario.obstacles, spec.obstacles):
        if o.obstacle_role.value == "dynamic":
            states = o.prediction.trajectory.state_list
            last = states[-1]
            assert entry.trajectory.points[-2] == pytest.approx(tuple(last.position))
            assert entry.trajectory.t_s[-2] == pytest.approx(last.time_step * spec.dt_s)
            # then extended at the last velocity
            v = (last.position - states[-2].position) / spec.dt_s
            extra = entry.trajectory.t_s[-1] - entry.trajectory.t_s[-2]
            assert entry.trajectory.points[-1] == pytest.approx(tuple(last.position + v * extra))
        else:
            assert entry.trajectory is None


def test_bad_xml_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "broken.xml"
    bad.write_text("<commonRoad><lanelet")
    r = subprocess.run([sys.executable, "-m", "mpcdrive.cli", "run", str(bad), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "broken.xml" in lines[0] and "CommonRoad" in lines[0]
    assert not (tmp_path / "o").exists()


# checker verdicts we expect per scenario: (collision-free, road-compliant, KS-feasible, goal reached)
EXPECTED_VERDICTS = {
    "ZAM_Tutorial-1_1_T-1.xml": (True, True, True, True),
    "ZAM_Tutorial-1_2_T-1.xml": (True, True, True, True),
    "C-DEU_B471-2_1.xml": (True, True, True, True),
    "FRA_Anglet-1_1_T-1.xml": (True, True, True, True),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(EXPECTED_VERDICTS))
def test_drive_is_judged_safe_by_the_drivability_checker(name, capsys):
    imp, res, m = drive(name)
    rep = check_drive(imp, res)
    n = rep.steps_checked
    clearance = None if res.clearance_m is None else float(np.min(res.clearance_m[:n]))
    with capsys.disabled():
        print(f"\n{name}: checker: {rep.line()}; ours: rms |e_y| {m['rms_lateral_error_m']:.3f} m, "
              f"max |e_y| {np.max(np.abs(res.e_y_m[:n])):.3f} m, min clearance "
              f"{'-' if clearance is None else f'{clearance:.2f} m'}, solver failures {m['solver_failures']}")
    assert (rep.collision_free, rep.road_compliant, rep.feasible, rep.goal_step is not None) == EXPECTED_VERDICTS[name]
    # our own metric agrees with the checker: no footprint overlap up to the goal
    if clearance is not None:
        assert clearance > 0.0


@pytest.mark.slow
def test_checker_catches_a_colliding_and_an_off_road_trajectory():
    """The same drive moved onto the parked car, then off the road, must fail those checks."""
    imp, res, _ = drive("ZAM_Tutorial-1_2_T-1.xml")
    parked = next(o for o in imp.scenario.obstacles if o.obstacle_role.value == "static")
    n = check_drive(imp, res).steps_checked
    x = res.x.copy()
    k = int(np.argmin(np.abs(x[:n, 0] - parked.initial_state.position[0])))
    x[:, :2] += np.asarray(parked.initial_state.position) - x[k, :2]  # through the parked car at step k
    hit = check_drive(imp, replace(res, x=x))
    assert not hit.collision_free
    x = res.x.copy()
    x[:, 1] -= 1.5  # across the right edge of the rightmost lane (the boundary marks the edge)
    off = check_drive(imp, replace(res, x=x))
    assert not off.road_compliant
    x = res.x.copy()
    x[1:, 0] += 3.0  # a 3 m jump in one 0.1 s step: no KS input does that
    assert not check_drive(imp, replace(res, x=x)).feasible


@pytest.mark.slow
def test_solution_file_round_trips(tmp_path):
    from commonroad.common.solution import CommonRoadSolutionReader

    imp, res, _ = drive("ZAM_Tutorial-1_1_T-1.xml")
    rep = check_drive(imp, res)
    path = write_solution(imp, res, tmp_path, rep.goal_step)
    sol = CommonRoadSolutionReader.open(str(path))
    pps = sol.planning_problem_solutions[0]
    assert pps.planning_problem_id == imp.planning_problem.planning_problem_id
    states = pps.trajectory.state_list
    assert len(states) == rep.goal_step + 1
    k = len(states) - 1
    assert states[k].position == pytest.approx(res.x[k, :2], abs=1e-6)
    assert states[k].orientation == pytest.approx(res.x[k, 2], abs=1e-6)
    assert states[k].velocity == pytest.approx(res.x[k, 3], rel=1e-2)  # rear-axle speed, v cos(beta)


@pytest.mark.slow
def test_cli_runs_a_commonroad_file(tmp_path):
    out = tmp_path / "run"
    r = subprocess.run([sys.executable, "-m", "mpcdrive.cli", "run", str(DIR / "ZAM_Tutorial-1_1_T-1.xml"),
                        "--out", str(out), "-q"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    cr = json.loads((out / "metrics.json").read_text())["commonroad"]
    assert cr["goal_reached"] and cr["collision_free"] and cr["road_compliant"] and cr["ks_feasible"]
    assert (out / "solution.xml").is_file() and (out / "trajectory.csv").is_file()


@pytest.mark.slow
def test_blocked_lane_stops_behind_the_parked_car(capsys):
    """ZAM_Tutorial_Urban-3_2 ("critical evasive"): a parked car blocks the route lanelet 12 m ahead
    at 9 m/s. The lane is the route lanelet, so the controller does not change lanes: it stops behind
    the car -- collision-free, on the road and KS-feasible, but the goal (past the car) is not
    reached. The first 6 s of the 100 s scenario show it."""
    imp = load_commonroad(DIR / "ZAM_Tutorial_Urban-3_2.xml")
    imp = replace(imp, spec=imp.spec.model_copy(update={"duration_s": 6.0}))
    exp = build_experiment(imp.spec)
    res = run_experiment(exp)
    m = compute_metrics(res, exp.footprint)
    rep = check_drive(imp, res)
    with capsys.disabled():
        print(f"\nZAM_Tutorial_Urban-3_2.xml (first 6 s): checker: {rep.line()}; ours: final speed "
              f"{res.x_final[3]:.2f} m/s, min clearance {np.min(res.clearance_m):.2f} m, "
              f"solver failures {m['solver_failures']}")
    assert rep.collision_free and rep.road_compliant and rep.feasible
    assert rep.goal_step is None
    parked = imp.scenario.obstacles[0].initial_state.position
    assert res.x_final[3] < 0.2 and res.x_final[0] < parked[0]
    assert np.min(res.clearance_m) > 0.0
