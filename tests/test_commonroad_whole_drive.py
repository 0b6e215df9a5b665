"""The whole drive is judged, not only the drive up to the goal: a CommonRoad run that reaches
its goal and then collides, leaves the road or drives past the end of the mapped road has not
passed; and where the route ends at the road's end, the car stops with its whole body on it.

The road-end scenarios are the generated ``road_end`` family (``scenario_families.py``): a single
lane whose last lanelet has no successor, the goal region just before its end.
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mpcdrive.adapters.commonroad import available

if not available():
    pytest.skip(
        "the commonroad extra (commonroad-io, commonroad-drivability-checker) is not installed", allow_module_level=True
    )

import scenario_families as sf  # noqa: E402

from mpcdrive.adapters import commonroad_figures  # noqa: E402
from mpcdrive.adapters.commonroad import check_drives, load_commonroad  # noqa: E402
from mpcdrive.adapters.commonroad_goal import FRONT_REACH_M, ROAD_MARGIN_M  # noqa: E402
from mpcdrive.scenarios import build_experiment, run_experiment  # noqa: E402
from mpcdrive.sim import apply_goal_region, compute_metrics  # noqa: E402

DIR = Path(__file__).resolve().parent / "data" / "commonroad"


def _line_length(line: np.ndarray) -> float:
    return float(np.sum(np.hypot(*np.diff(line, axis=0).T)))


def test_the_road_ends_where_the_network_does_and_the_path_stops_inside_it(tmp_path):
    """The road_end family: the route's last lanelet has no successor, so the road's ``end_m``
    is its end (the lanelet's closing edge, as far along the path as the lane reaches), and the
    path ends the longest CommonRoad car's front overhang and the road margin before it. A route
    whose lanes go on has no end there (USA_Lanker-1_1_T-1 starts mid-network)."""
    for seed in (0, 1):
        imp = load_commonroad(sf.write_scenario("road_end", seed, tmp_path))
        net = imp.scenario.lanelet_network
        last = net.find_lanelet_by_id(imp.route[-1])
        assert not last.successor
        road = imp.spec.road
        # the closing edge, straight across the lane: its centre is the road's end along the path
        path = build_experiment(imp.spec).path
        s_end, _ = path.project(np.asarray(last.center_vertices[-1], float), path.length_m, 10.0)
        assert road.end_m == pytest.approx(s_end, abs=0.02)
        assert _line_length(imp.centerline) == pytest.approx(road.end_m - FRONT_REACH_M - ROAD_MARGIN_M, abs=0.05)
        first = net.find_lanelet_by_id(imp.route[0])
        assert not first.predecessor and road.start_m is not None and road.start_m < 0.0  # the lane begins behind
    lanker = load_commonroad(DIR / "USA_Lanker-1_1_T-1.xml")
    assert lanker.spec.road.start_m is None


def _run(path: Path, out_dir: Path, monkeypatch) -> dict:
    """Drive ``path`` (the default vehicle and plant) and judge it as ``mpcdrive run`` does:
    (the written ``commonroad`` block, the metrics, the verdict)."""
    monkeypatch.setattr(
        commonroad_figures, "write_scene_figure", lambda imp, result, out_dir, step: Path(out_dir) / "scene.png"
    )
    imp = load_commonroad(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_experiment(build_experiment(imp.spec))
    out_dir.mkdir(parents=True)
    cr = imp.write_outputs(res, out_dir)["commonroad"]
    m = apply_goal_region(compute_metrics(res), cr.goal_reached, cr)
    return {"cr": cr, "m": m, "v": m.verdict, "res": res, "imp": imp}


def test_a_car_stopping_past_the_road_end_after_the_goal_fails_and_one_stopping_inside_passes(tmp_path, monkeypatch):
    """The road_end family driven as shipped: the car reaches the goal and stops with its whole
    body inside the mapped road. The same drive with its states after the goal moved 3 m on
    along the car's heading (and the road's measure of them taken again), so that the body ends
    past the road's end: CommonRoad's checks up to the goal pass as before, the whole drive leaves
    the road after the goal, and the run fails, saying so."""
    scenario = sf.write_scenario("road_end", 0, tmp_path)
    got = _run(scenario, tmp_path / "run", monkeypatch)
    assert got["cr"].passed and got["v"].passed, got["v"].text()
    assert got["cr"].whole_drive.past_road_end_m == 0.0 and got["m"].max_lane_excess_m <= 1e-3
    imp, res = got["imp"], got["res"]
    goal, _ = check_drives(imp, res)
    g = goal.goal_step
    assert g is not None and g + 1 < len(res.t_s)
    x, s = res.x.copy(), res.s_m.copy()
    yaw = x[-1, 2]
    x[g + 1 :, 0] += 3.0 * np.cos(yaw)
    x[g + 1 :, 1] += 3.0 * np.sin(yaw)
    s[g + 1 :] += 3.0
    exp = build_experiment(imp.spec)
    road = exp.road.whole()
    end = road.measure_end_excess_m(exp.path, x, s, exp.mpc.footprint)
    excess = np.maximum(road.measure_excess_m(exp.path, x, s, exp.mpc.footprint), end)
    past = replace(res, x=x, s_m=s, lane_excess_m=excess, meta={**res.meta, "road_end_excess_m": end})
    assert end[: g + 1].max() == 0.0 and end[-1] > 1.0
    (tmp_path / "past").mkdir()
    cr = imp.write_outputs(past, tmp_path / "past")["commonroad"]
    assert cr.goal_reached and cr.collision_free and cr.road_compliant and cr.ks_feasible and not cr.passed
    w = cr.whole_drive
    assert w is not None and not w.road_compliant and w.collision_free
    assert w.past_road_end_m == pytest.approx(end.max()) and w.off_road_t_s > w.goal_t_s
    m = apply_goal_region(compute_metrics(past), cr.goal_reached, cr)
    v = m.verdict
    assert v.failed and v.unsafe and v.part("goal").ok is True
    assert v.part("road").reason.startswith("left the road after the goal at t = ")
    assert "m beyond the road's start or end" in v.part("road").reason
    assert "whole drive: OFF THE ROAD after the goal" in v.part("commonroad").reason
    # mpcdrive's own measure of the road agrees: the body left it past the end
    assert m.max_lane_excess_m == pytest.approx(w.past_road_end_m, abs=1e-3)


def test_a_collision_after_the_goal_fails_the_whole_drive_only(tmp_path, monkeypatch):
    """ZAM_Tutorial_Urban-3_2 driven, then its states after the goal moved onto the parked car:
    the checks up to the goal pass as before, the whole drive's collision check fails at the
    first moved state, and the verdict says the collision came after the goal."""
    got = _run(DIR / "ZAM_Tutorial_Urban-3_2.xml", tmp_path / "run", monkeypatch)
    imp, res = got["imp"], got["res"]
    assert got["cr"].passed and got["cr"].whole_drive.passed
    goal, whole = check_drives(imp, res)
    g = goal.goal_step
    assert g is not None and g + 1 < len(res.t_s) and whole.steps_checked == len(res.t_s)
    parked = next(o for o in imp.scenario.obstacles if o.obstacle_role.value == "static")
    x = res.x.copy()
    x[g + 1 :, :2] = np.asarray(parked.initial_state.position, float)
    hit = replace(res, x=x)
    goal, whole = check_drives(imp, hit)
    assert goal.collision_free and goal.road_compliant and goal.feasible and goal.goal_step == g
    assert not whole.collision_free and whole.collision_step == g + 1
    (tmp_path / "hit").mkdir()
    cr = imp.write_outputs(hit, tmp_path / "hit")["commonroad"]
    assert not cr.passed and cr.collision_free and not cr.whole_drive.collision_free
    assert cr.whole_drive.collision_t_s == pytest.approx(hit.t_s[g + 1])
    v = apply_goal_region(compute_metrics(hit), cr.goal_reached, cr).verdict
    assert v.unsafe and v.collided and v.part("goal").ok is True
    assert f"after the goal at t = {hit.t_s[g + 1]:.2f} s" in v.part("collision").reason


def test_the_batch_row_and_table_say_what_failed_over_the_whole_drive():
    from mpcdrive.adapters.commonroad_batch import _empty_row, summary_markdown, verdict

    up_to_goal = dict(collision_free=True, road_compliant=True, ks_feasible=True, goal_reached=True)
    whole = {"collision_free": True, "road_compliant": False, "feasible": True, "passed": False}
    whole.update(off_road_t_s=9.5, past_road_end_m=2.26, collision_t_s=None, infeasible_t_s=None)
    past_end = {**_empty_row(), **up_to_goal, "solution_valid": True, "whole_drive": whole}
    hit = {**past_end, "whole_drive": {**whole, "road_compliant": True, "collision_free": False, "collision_t_s": 7.3}}
    hit["whole_drive"]["past_road_end_m"] = 0.0
    clean = {**past_end, "passed": True, "whole_drive": {**whole, "road_compliant": True, "passed": True}}
    assert verdict(past_end) == "failed: off road beyond the road's start or end"
    assert verdict(hit) == "failed: collision after the goal"
    assert verdict(clean) == "passed"
    md = summary_markdown({"a.xml": past_end, "b.xml": hit, "c.xml": clean})
    assert "| whole drive |" in md
    assert (
        "| `a.xml` | failed: off road beyond the road's start or end | yes | yes | yes | yes | no: off road 9.5 s (2.26 m"
        in md
    )
    assert "| `b.xml` | failed: collision after the goal | yes | yes | yes | yes | no: collision 7.3 s |" in md
    assert "| `c.xml` | passed | yes | yes | yes | yes | yes |" in md


def test_past_the_goal_the_car_drives_on_along_its_lane_where_the_network_goes_on():
    """DEU_Cologne-63_5_I-1: the car starts in the goal region, on lanelet 6, which goes on into
    lanelet 22. The route used to end with lanelet 6 and the car stopped at its end with its
    nose in lanelet 22 ("stops in it"); now the route goes on along the lane (each lanelet the
    one the lane continues into) far enough that the reference is still driving when the run
    ends, at the goal window's end."""
    from mpcdrive.adapters.commonroad_route import next_in_lane

    imp = load_commonroad(DIR / "DEU_Cologne-63_5_I-1.xml.gz")
    plan, net = imp.plan, imp.scenario.lanelet_network
    assert plan.mode == "through goal" and "stops" not in plan.note, plan.note
    assert imp.route[0] == 6 and len(imp.route) > 2
    for k in range(1, len(imp.route)):
        assert imp.route[k] == next_in_lane(net, imp.route[k - 1], imp.route[:k])
    prof = build_experiment(imp.spec).speed_profile
    assert imp.spec.duration_s == pytest.approx(plan.goal_window_s[1] + imp.spec.dt_s)
    assert prof.time_at(prof.path.length_m) > imp.spec.duration_s + 1.0


def test_a_missed_goal_says_which_of_its_parts_the_closest_state_missed(tmp_path, monkeypatch):
    """The road_end family driven, then cut short or late: the run says why the goal was missed.
    Cut 2 s before it reaches the goal, the drive's last state is the closest, outside the goal's
    position by about the way it had left to go; the whole drive shifted 100 s late is in the
    position but outside the time window; and the verdict's words carry the reason."""
    from mpcdrive.adapters.commonroad import goal_miss
    from mpcdrive.sim.verdict import checker_phrase

    got = _run(sf.write_scenario("road_end", 0, tmp_path), tmp_path / "run", monkeypatch)
    imp, res = got["imp"], got["res"]
    assert got["cr"].goal_reached and got["cr"].goal_miss is None
    g = got["cr"].goal_step
    dt = imp.spec.dt_s
    k = g - int(round(2.0 / dt))
    short = replace(res, t_s=res.t_s[: k + 1], x=res.x[: k + 1])
    why = goal_miss(imp, short)
    assert why is not None and why.startswith(f"closest at t = {res.t_s[k]:.2f} s: outside the goal's position (")
    gap = float(why.split("(")[1].split(" m away")[0])
    # the way left along the (straight) lane to the goal state, less the region's reach behind it
    left_m = float(np.hypot(*(res.x[g, :2] - res.x[k, :2])))
    assert 0.0 < gap <= left_m + 0.1
    late = replace(res, t_s=res.t_s + 100.0)
    why_late = goal_miss(imp, late)
    assert why_late is not None and "outside the goal's time window" in why_late
    assert "goal's position" not in why_late
    words = checker_phrase({"goal_reached": False, "goal_miss": why, "collision_free": True, "road_compliant": True})
    assert f"goal not reached ({why})" in words


def test_a_car_placed_at_the_road_start_drives_off_and_is_not_behind_the_road(tmp_path, monkeypatch):
    """ZAM-Ramp-1_1-T-1 places the car at rest with its centre on the mapped road's start (its
    rear 2.25 m behind it). The ground it stands on counts as road (``START_CLEAR_M`` behind its
    start), so the whole drive is not off the road at t = 0; the wanted speed, which starts from
    0 there, is looked up ahead, so the car drives off and reaches the goal. CommonRoad's own
    solution checker still rejects the solution: its road boundary is closed at the road's
    start, and the initial state already touches it (the file's doing), which the run says."""
    from mpcdrive.adapters.commonroad import START_CLEAR_M

    got = _run(DIR / "ZAM-Ramp-1_1-T-1.xml", tmp_path / "run", monkeypatch)
    imp, cr, res = got["imp"], got["cr"], got["res"]
    assert imp.spec.road.start_m is not None and imp.spec.road.start_m <= imp.plan.start_m - START_CLEAR_M + 1e-9
    assert res.x[-1, 3] > 5.0 and cr.goal_reached
    assert cr.whole_drive.road_compliant and cr.whole_drive.past_road_end_m == 0.0
    assert not cr.solution_valid and "lanelet boundaries" in cr.solution_check and not cr.passed
