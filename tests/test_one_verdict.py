"""One verdict, computed once and shown everywhere: ``metrics.json["verdict"]`` (its parts, each
``ok`` with a reason when it fails), the summary line, ``report.html``, ``mpcdrive sweep`` and
``mpcdrive run --check`` say the same, and no field of ``metrics.json`` contradicts another."""

import json
import subprocess
import sys

import pytest
import yaml
from test_verdict import COLLIDE

from mpcdrive.scenarios import build_experiment, load_scenario, run_experiment, validate_scenario_data
from mpcdrive.sim import compute_metrics, run_verdict
from mpcdrive.sweep import SuccessCriteria, plan_sweep, run_sweep

# the 1:10 car starts 0.5 m beside a 1 m straight path with 5 degrees of steering: it reaches the
# path's end still about 0.45 m off it (there is no road to leave)
OFF_AT_THE_END = {
    "id": "off-at-the-end",
    "dt_s": 0.01,
    "duration_s": 3.0,
    "vehicle": {"model": "kinematic3", "speed_mps": 1.0},
    "path": {"type": "straight", "start": [0.0, 0.0], "end": [1.0, 0.0]},
    "initial_state": {"x_m": 0.0, "y_m": 0.5, "yaw_deg": 0.0},
    "controller": {"horizon": 10, "Q": [1, 1, 1], "R": [1], "max_steer_deg": 5.0},
}


def cli(*args):
    return subprocess.run([sys.executable, "-m", "mpcdrive.cli", *args], capture_output=True, text=True)


def write(tmp_path, data, name="s.yaml"):
    p = tmp_path / name
    p.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
    return p


def test_reaching_the_path_end_off_the_path_is_not_the_goal_and_no_field_says_otherwise(tmp_path):
    out = tmp_path / "out"
    r = cli("run", str(write(tmp_path, OFF_AT_THE_END)), "--out", str(out), "-q", "--check")
    assert r.returncode == 3, r.stdout + r.stderr  # --check: the verdict failed
    m = json.loads((out / "metrics.json").read_text())
    assert m["final_lateral_error_m"] > 0.3
    # how the run ended, without claiming the goal; the goal judged once, the same everywhere
    assert m["termination"] == "path_end_reached"
    assert m["goal_region_reached"] is True and m["goal_reached"] is False
    v = m["verdict"]
    assert v["passed"] is False and v["unsafe"] is False and v["headline"] == "FAILED"
    goal = v["parts"]["goal"]
    assert (
        goal["ok"] is False
        and "ended 0.4" in goal["reason"]
        and "m from the path (the goal allows 0.135 m)" in goal["reason"]
    )
    assert v["reasons"] == [goal["reason"]]
    assert m["criteria"]["max_final_lateral_error_m"] == pytest.approx(0.135)  # half the car's 0.27 m
    # the summary line is the verdict, verbatim; --check names the same reason
    line = r.stdout.splitlines()[0]
    assert line.startswith("FAILED: off-at-the-end: ") and line.split(" | ")[0] == "FAILED: off-at-the-end: " + v[
        "text"
    ].removeprefix("FAILED: ")
    assert goal["reason"] in r.stderr
    # the verdict read back from metrics.json is the one written
    assert run_verdict(m).as_dict() == v


def test_the_goal_tolerance_is_set_in_the_scenario_file(tmp_path):
    data = {**OFF_AT_THE_END, "verdict": {"max_final_lateral_error_m": 0.6}}
    r = cli("run", str(write(tmp_path, data)), "--out", str(tmp_path / "out"), "-q", "--check")
    assert r.returncode == 0, r.stdout + r.stderr
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert m["goal_reached"] is True and m["verdict"]["passed"] and m["criteria"]["max_final_lateral_error_m"] == 0.6
    assert "verdict:" in (tmp_path / "out" / "scenario.yaml").read_text()


def test_the_sweep_counts_a_run_by_its_verdict_and_its_flags_override_the_tolerances(tmp_path):
    spec = validate_scenario_data(OFF_AT_THE_END, "off")
    m = compute_metrics(run_experiment(build_experiment(spec)))
    (row,) = run_sweep(plan_sweep(spec, 1, 0), workers=1)
    assert row["success"] is m.verdict.passed is False
    assert row["failure_reason"] == "; ".join(m.verdict.reasons)
    assert row["termination"] == "path_end_reached"
    # --max-final-error overrides the verdict's tolerance of every run
    plan = plan_sweep(spec, 1, 0, criteria=SuccessCriteria(max_final_lateral_error_m=0.6))
    assert plan.base.verdict.max_final_lateral_error_m == 0.6
    (row,) = run_sweep(plan, workers=1)
    assert row["success"] is True and row["failure_reason"] == ""
    # on the command line: the summary states the criteria the runs were judged by
    out = tmp_path / "sweep"
    r = cli("sweep", str(write(tmp_path, OFF_AT_THE_END)), "--runs", "1", "--workers", "1", "--out", str(out), "-q")
    assert r.returncode == 0, r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["successes"] == 0 and s["criteria"]["max_final_lateral_error_m"] == pytest.approx(0.135)
    assert s["failure_categories"] == {"final lateral error too large": 1}
    r = cli(
        "sweep", str(write(tmp_path, OFF_AT_THE_END)), "--runs", "1", "--workers", "1", "--out", str(tmp_path / "s2"),
        "-q", "--max-final-error", "0.6",
    )  # fmt: skip
    assert r.returncode == 0 and json.loads((tmp_path / "s2" / "summary.json").read_text())["successes"] == 1


def test_report_html_opens_with_the_verdict_sentence(tmp_path):
    out = tmp_path / "out"
    r = cli("run", str(write(tmp_path, COLLIDE)), "--out", str(out), "-q")
    assert r.returncode == 0, r.stderr
    html = (out / "report.html").read_text()
    m = json.loads((out / "metrics.json").read_text())
    sentence = "Verdict: <strong>UNSAFE</strong>: collided with obstacle 1 (rock) at t = 0.97 s"
    assert sentence in html
    body = html[html.index("<body") :]
    assert body.index(sentence) < body.index('id="replay"') and body.index(sentence) < body.index('class="metrics"')
    assert m["verdict"]["unsafe"] is True and m["verdict"]["parts"]["collision"]["ok"] is False
    assert r.stdout.startswith("UNSAFE: collide: collided with obstacle 1 (rock)")


def test_each_part_says_ok_or_why_not():
    m = {
        "termination": "completed",
        "collisions": 1,
        "collision_events": [{"obstacle": 0, "name": "", "step": 3, "t_s": 0.3, "steps": 2, "depth_m": 0.01}],
        "road_given": True,
        "max_lane_excess_m": 0.2,
        "goal_region_reached": True,
        "final_lateral_error_m": 0.0,
        "criteria": {"max_final_lateral_error_m": 0.1},
    }
    v = run_verdict(m)
    assert [n for n, _ in v.parts] == ["divergence", "collision", "road", "goal"]
    assert v.part("divergence").ok is True and v.part("divergence").reason is None
    assert v.part("collision").reason == "collided with obstacle 0 at t = 0.30 s, 0.01 m deep"
    assert v.part("road").reason == "left the lane by 0.2 m"
    assert v.part("goal").reason == "goal not reached (the goal region was reached, but not safely)"
    assert v.unsafe and v.problems() == ["collision", "left the road", "goal not reached"]
    # a run without obstacles or road has nothing to judge there; the lane tolerance is a criterion
    clean = run_verdict({"road_given": False, "goal_region_reached": None, "final_lateral_error_m": 0.01})
    assert clean.part("collision").ok is None and clean.part("road").ok is None and clean.passed
    assert run_verdict({**m, "collisions": 0, "collision_events": [], "criteria": {"max_lane_excess_m": 0.5}}).passed


def test_an_external_checker_is_a_part_of_the_verdict():
    cr = {"collision_free": True, "road_compliant": True, "ks_feasible": False, "goal_reached": True, "passed": False}
    v = run_verdict({"goal_region_reached": True, "commonroad": cr})
    assert [n for n, _ in v.parts][-1] == "commonroad" and v.failed and not v.unsafe
    assert v.reasons == ["CommonRoad checker: collision-free, road-compliant, not KS-feasible, goal reached"]


@pytest.mark.parametrize("drive_through", [False, True])
def test_obstacle_blocked_passes_when_it_stops_before_the_barrier_and_fails_when_it_hits_it(drive_through):
    spec = load_scenario("obstacle-blocked")
    assert spec.verdict.goal == "standstill"
    if drive_through:  # an obstacle cost of weight 0: the barrier is not avoided
        data = spec.model_dump(mode="json", exclude_unset=True)
        data["avoidance"] = {"formulation": "potential", "weight": 0.0}
        spec = validate_scenario_data(data, "through")
    m = compute_metrics(run_experiment(build_experiment(spec)))
    if drive_through:
        assert m.collisions >= 1 and m.verdict.failed and m.verdict.unsafe
        assert m.goal_reached is False
    else:
        assert m.verdict.passed and m.goal_reached is True and m.termination == "completed"
        assert m.final_speed_mps <= spec.verdict.max_final_speed_mps and m.min_obstacle_clearance_m > 0.1
        assert "goal reached (a standstill)" in m.verdict.text()
