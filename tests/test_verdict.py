"""Unsafe outcomes never look like success: the run summary says collisions (which obstacle, when),
lane excess, the goal and how failed solves were handled; ``goal_reached`` has one definition;
``mpcdrive run --check`` exits 3 on a collided, off-road or goal-missing run."""

import json
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from mpcdrive.scenarios import build_experiment, load_scenario, run_experiment
from mpcdrive.sim import LANE_TOLERANCE_M, compute_metrics, run_verdict
from mpcdrive.types import ScenarioWarning

# a car at 1 m/s on a straight path through a rock (index 1; index 0 is off the road); the
# potential cost with weight 0 does not avoid it, so the body first overlaps the rock at
# x = 1.52 - 0.3 - 0.25 (its front) = 0.97 m, at t = 0.97 s (between the logged steps)
COLLIDE = """\
id: collide
dt_s: 0.05
duration_s: 4.0
vehicle: {model: kinematic3, speed_mps: 1.0}
path: {type: straight, start: [0.0, 0.0], end: [3.0, 0.0]}
road: {lane_width_m: 1.0}
initial_state: {x_m: 0.0, y_m: 0.0, yaw_deg: 0.0}
obstacles:
  - {shape: circle, position: [1.5, 3.0], radius_m: 0.2, name: tree}
  - {shape: circle, position: [1.52, 0.0], radius_m: 0.3, name: rock}
avoidance: {formulation: potential, weight: 0.0}
controller: {horizon: 10, Q: [1, 1, 1], R: [1]}
"""

CLEAN = """\
id: clean
dt_s: 0.05
duration_s: 1.5
vehicle: {model: kinematic3, speed_mps: 1.0}
path: {type: straight, start: [0.0, 0.0], end: [1.0, 0.0]}
road: {lane_width_m: 1.0}
initial_state: {x_m: 0.0, y_m: 0.0, yaw_deg: 0.0}
obstacles:
  - {shape: circle, position: [0.5, 2.0], radius_m: 0.2}
controller: {horizon: 10, Q: [1, 1, 1], R: [1]}
"""

# the 1:10 car at 100 m/s, heading 60 deg off a straight path with 10 deg of ideal steering: it
# passes the path's end (the goal region) after leaving the 1 m lane
FAST = """\
id: fast
dt_s: 0.01
duration_s: 1.0
vehicle: {model: kinematic3, speed_mps: 100.0}
path: {type: straight, start: [0.0, 0.0], end: [8.0, 0.0]}
road: {lane_width_m: 1.0}
initial_state: {x_m: 0.0, y_m: 0.0, yaw_deg: 60.0}
controller: {horizon: 10, Q: [1, 1, 1], R: [1], max_steer_deg: 10.0}
plant: {steering_actuator: ideal}
"""

# OSQP gets one iteration per solve (the relax rung two): every solve fails and the ladder
# answers with the shifted plan until it is N - 1 steps old, then brakes
FAILING = """\
id: failing
dt_s: 0.01
duration_s: 0.3
path: {type: circle, radius_m: 1.5}
initial_state: {x_m: 1.6, y_m: 0.0, yaw_deg: 80}
road: {lane_width_m: 1.0}
controller: {horizon: 10, Q: [1, 1, 1], R: [1], osqp_max_iter: 1, backend: osqp}
"""

CR = Path(__file__).resolve().parent / "data" / "commonroad"


def cli(*args):
    return subprocess.run([sys.executable, "-m", "mpcdrive.cli", *args], capture_output=True, text=True)


def write(tmp_path, text, name="s.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_summary_names_the_obstacle_and_time_of_a_collision_and_check_exits_3(tmp_path):
    p = write(tmp_path, COLLIDE)
    r = cli("run", str(p), "--out", str(tmp_path / "plain"), "-q")
    assert r.returncode == 0, r.stderr  # without --check a collision is reported, not an error
    line = r.stdout.splitlines()[0]
    # the front touches the rock at x = 0.97 m, between two logged steps (0.95 s, 1.00 s)
    assert line.startswith("UNSAFE: collide: collided with obstacle 1 (rock) at t = 0.97 s"), line
    assert "goal not reached (the goal region was reached, but not safely)" in line
    m = json.loads((tmp_path / "plain" / "metrics.json").read_text())
    assert m["collisions"] == 1 and m["first_collision"]["obstacle"] == 1
    assert m["first_collision"]["t_s"] == pytest.approx(0.97, abs=2e-3) and m["first_collision"]["name"] == "rock"
    assert [e["obstacle"] for e in m["collision_events"]] == [1]
    assert m["goal_region_reached"] is True and m["goal_reached"] is False
    # --check: exit code 3, outputs still written, the reason on stderr
    out = tmp_path / "checked"
    r = cli("run", str(p), "--out", str(out), "-q", "--check")
    assert r.returncode == 3, r.stderr
    assert (out / "metrics.json").is_file() and (out / "trajectory.csv").is_file()
    assert "--check" in r.stderr and "collision" in r.stderr


def test_check_exits_0_on_a_clean_run(tmp_path):
    r = cli("run", str(write(tmp_path, CLEAN)), "--out", str(tmp_path / "out"), "-q", "--check")
    assert r.returncode == 0, r.stderr
    line = r.stdout.splitlines()[0]
    assert line.startswith("clean: no collision (min clearance ") and "inside the lane; goal reached" in line
    assert "UNSAFE" not in r.stdout


def test_goal_is_not_reached_by_a_car_that_left_the_road(tmp_path):
    """The fast car passes the path's end (the old ``goal_reached: true``) after leaving the lane."""
    p = write(tmp_path, FAST)
    with pytest.warns(ScenarioWarning, match="vehicle.speed_mps"):
        spec = load_scenario(p)
    exp = build_experiment(spec)
    res = run_experiment(exp)
    m = compute_metrics(res)
    assert res.goal_reached is True and m["goal_region_reached"] is True
    assert m["max_lane_excess_m"] > 0.1
    assert m["goal_reached"] is False
    v = run_verdict(m)
    assert v.off_road and v.unsafe and v.failed and v.text().startswith("UNSAFE: left the lane by ")


def test_failed_solves_say_how_they_were_handled(tmp_path):
    p = write(tmp_path, FAILING)
    exp = build_experiment(load_scenario(p))
    m = compute_metrics(run_experiment(exp))
    assert m["solver_failures"] == 30 and m["fallbacks"] == 30
    text = run_verdict(m).text()
    assert "30 failed solves: 27 recovered by shifted_plan, 3 by brake" in text, text


@pytest.mark.parametrize(
    "counts, failures, words",
    [
        ({"relax": 5, "shifted_plan": 0, "brake": 0, "hold_last": 0}, 5, "5 failed solves, all recovered by relax"),
        (
            {"relax": 0, "shifted_plan": 3, "brake": 2, "hold_last": 0},
            5,
            "5 failed solves: 3 recovered by shifted_plan, 2 by brake",
        ),
        ({"relax": 1, "shifted_plan": 0, "brake": 0, "hold_last": 0}, 1, "1 failed solve, recovered by relax"),
        ({"relax": 0, "shifted_plan": 0, "brake": 0, "hold_last": 0}, 0, "no failed solves"),
    ],
)
def test_fallback_phrases(counts, failures, words):
    m = {
        "solver_failures": failures,
        "fallback_counts": counts,
        "collisions": 0,
        "max_lane_excess_m": 0.0,
        "goal_reached": True,
    }
    assert words in run_verdict(m).text()


def _goal(region, excess=0.0, collisions=0, final=0.0):
    m = {
        "goal_region_reached": region,
        "max_lane_excess_m": excess,
        "collisions": collisions,
        "final_lateral_error_m": final,
        "criteria": {"max_final_lateral_error_m": 0.1},
    }
    return run_verdict(m).part("goal").ok


def test_goal_definition_needs_region_lane_no_collision_and_the_end_near_the_path():
    assert _goal(True) is True
    assert _goal(True, excess=LANE_TOLERANCE_M) is True
    assert _goal(True, excess=2 * LANE_TOLERANCE_M) is False
    assert _goal(True, collisions=1) is False
    assert _goal(True, final=0.1) is True and _goal(True, final=0.1001) is False
    assert _goal(False) is False
    # no goal region: judged on where the run ends
    assert _goal(None, final=0.05) is True and _goal(None, final=0.5) is False


def test_commonroad_checker_verdicts_make_a_run_unsafe():
    m = {
        "collisions": 0,
        "max_lane_excess_m": 0.0,
        "goal_reached": False,
        "solver_failures": 0,
        "commonroad": {
            "collision_free": False,
            "road_compliant": True,
            "ks_feasible": True,
            "goal_reached": True,
            "goal_step": 12,
        },
    }
    v = run_verdict(m)
    assert v.collided and v.unsafe
    assert "CommonRoad checker: COLLISION, road-compliant, KS-feasible, goal reached at step 12" in v.text()


@pytest.mark.parametrize("name", ["C-DEU_B471-2_1.xml", "FRA_Anglet-1_1_T-1.xml"])
def test_commonroad_goal_reached_follows_the_planning_problem(tmp_path, name):
    pytest.importorskip("commonroad_dc")
    out = tmp_path / "out"
    r = cli("run", str(CR / name), "--out", str(out), "-q", "--check")
    assert r.returncode == 0, r.stdout + r.stderr
    m = json.loads((out / "metrics.json").read_text())
    cr = m["commonroad"]
    assert cr["goal_reached"] is True and cr["collision_free"] and cr["road_compliant"]
    assert m["goal_region_reached"] is True and m["goal_reached"] is True
    assert "CommonRoad checker: collision-free, road-compliant" in r.stdout and "UNSAFE" not in r.stdout


def test_no_warning_on_builtin_or_commonroad_scenarios():
    """Nor is any of them rejected for an obstacle on the start."""
    from mpcdrive.scenarios import builtin_ids, reject_initial_overlap, warn_suspicious

    with warnings.catch_warnings():
        warnings.simplefilter("error", ScenarioWarning)
        for sid in builtin_ids():
            load_scenario(sid)
        try:
            from mpcdrive.adapters.commonroad import available, load_commonroad
        except ImportError:
            return
        if not available():
            return
        checked = 0
        for f in sorted(CR.glob("*.xml*")):
            try:
                imp = load_commonroad(f)
            except Exception:  # files the importer cannot map are tested in test_commonroad.py
                continue
            warn_suspicious(reject_initial_overlap(imp.spec, str(f)), str(f))
            checked += 1
        assert checked >= 8


def _commonroad_run(whole: dict, events=()) -> dict:
    """The metrics of a CommonRoad run that passed CommonRoad's checks up to the goal (step 40,
    t = 4 s), with ``whole`` the checks of its whole drive."""
    block = {"collision_free": True, "road_compliant": True, "feasible": True, "states_checked": 90}
    block.update(goal_t_s=4.0, collision_t_s=None, off_road_t_s=None, infeasible_t_s=None, past_road_end_m=None)
    block.update(whole)
    block["passed"] = block["collision_free"] and block["road_compliant"] and block["feasible"]
    return {
        "collisions": len(events),
        "collision_events": list(events),
        "min_obstacle_clearance_m": 1.0,
        "road_given": True,
        "max_lane_excess_m": 0.0,
        "goal_region_reached": True,
        "commonroad": {
            "collision_free": True,
            "road_compliant": True,
            "ks_feasible": True,
            "goal_reached": True,
            "goal_step": 40,
            "vehicle_model": "ST",
            "solution_valid": True,
            "passed": block["passed"],
            "whole_drive": block,
        },
    }


def test_a_drive_that_reaches_the_goal_and_then_collides_or_leaves_the_road_is_not_passed():
    clean = run_verdict(_commonroad_run({}))
    assert clean.passed and "whole drive clean (90 states)" in clean.text()
    # a collision 3.3 s after the goal that only CommonRoad's checker saw
    hit = run_verdict(_commonroad_run({"collision_free": False, "collision_t_s": 7.3}))
    assert hit.failed and hit.unsafe and hit.collided
    assert hit.part("collision").reason.startswith(
        "the CommonRoad checker found a collision after the goal at t = 7.30 s"
    )
    assert hit.part("commonroad").reason.endswith("; whole drive: COLLISION after the goal at t = 7.30 s")
    assert hit.part("goal").ok is True  # the goal was reached safely: what came after fails the drive
    # past the mapped road's end after the goal (the drivability checker's boundary is open there)
    off = run_verdict(_commonroad_run({"road_compliant": False, "off_road_t_s": 9.5, "past_road_end_m": 2.24}))
    assert off.failed and off.off_road and off.part("goal").ok is True
    assert (
        off.part("road").reason
        == "left the road after the goal at t = 9.50 s (the body 2.24 m beyond the road's start or end)"
    )
    assert "whole drive: OFF THE ROAD after the goal at t = 9.50 s (the body 2.24 m beyond" in off.text()
    # infeasible after the goal: failed, not unsafe
    slip = run_verdict(_commonroad_run({"feasible": False, "infeasible_t_s": 6.0}))
    assert slip.failed and not slip.unsafe
    assert slip.reasons == [
        "CommonRoad checker: collision-free, road-compliant, ST-feasible, goal reached at step 40; "
        "whole drive: not ST-feasible after the goal at t = 6.00 s"
    ]
    # mpcdrive's own contact before the goal still means the goal was not reached safely; one after it does not
    event = {"obstacle": 0, "name": "car", "step": 0, "steps": 1, "depth_m": 0.1}
    before = run_verdict(_commonroad_run({"collision_free": False, "collision_t_s": 3.0}, [{**event, "t_s": 3.0}]))
    after = run_verdict(_commonroad_run({"collision_free": False, "collision_t_s": 5.0}, [{**event, "t_s": 5.0}]))
    assert before.part("goal").ok is False and after.part("goal").ok is True
    assert before.collided and after.collided
