"""Bench problem P4 (three-lane road with 20 cars): its definition, and that the closed loop runs
and passes the slower car without collision. Checked by structure and outcome, never by time."""

import math
from dataclasses import replace

import numpy as np
import pytest

from mpcdrive.bench import PROBLEMS, run_bench
from mpcdrive.bench.problems import P4_SEED, p4, p4_traffic
from mpcdrive.bench.runner import make_controller, time_closed_loop
from mpcdrive.models.kinematic import KinematicBicycle4
from mpcdrive.models.presets import get_preset
from mpcdrive.scene.geometry import shape_distance
from mpcdrive.scene.obstacles import ConstantVelocity
from mpcdrive.sim.closed_loop import Plant

KEYS = {
    "p50_us",
    "p99_us",
    "max_us",
    "steps",
    "rms_lateral_error_m",
    "collision_steps",
    "min_obstacle_clearance_m",
    "max_lane_excess_m",
    "solver_failures",
}


def test_p4_is_the_three_lane_traffic_problem():
    prob = PROBLEMS["P4"]()
    pre = get_preset("commonroad_bmw_320i")
    assert isinstance(prob.model, KinematicBicycle4)
    assert prob.model.params.lf_m == pre.params.lf_m and prob.model.params.lr_m == pre.params.lr_m
    assert (prob.footprint.length_m, prob.footprint.width_m) == (pre.length_m, pre.width_m)
    assert prob.dt_s == prob.problem.dt_s == 0.1 and prob.problem.N == 30 and prob.steps == 300
    assert prob.x0[3] == 20.0 and prob.x0[1] == 0.0
    road = prob.problem.road  # the road is the three lanes, the ego in the middle one
    assert road.min_width_m == 3 * 3.5 and road.left_m[0] == 1.5 * 3.5 and road.right_m[0] == -1.5 * 3.5
    assert prob.avoidance.formulation == "hard"
    assert prob.path.length_m == 300.0
    cars = prob.obstacles
    assert len(cars) == 20
    lanes = {}
    for ob in cars:
        assert isinstance(ob.motion, ConstantVelocity) and ob.motion.vy_mps == 0.0
        assert 12.0 <= ob.motion.vx_mps <= 25.0
        pts = ob.at(0.0).points
        assert np.ptp(pts[:, 0]) == pytest.approx(4.5) and np.ptp(pts[:, 1]) == pytest.approx(1.8)
        x, y, _ = ob.pose
        assert 0.0 <= x <= 300.0
        lanes.setdefault(y, []).append((x, ob.motion.vx_mps))
    assert sorted(lanes) == [-3.5, 0.0, 3.5] and all(len(v) >= 6 for v in lanes.values())
    # one slower car ahead of the ego in its lane, nothing behind it there
    ego_lane = sorted(lanes[0.0])
    lead_x, lead_v = ego_lane[0]
    assert lead_x > prob.x0[0] and lead_v < prob.x0[3]
    # in each lane no car is faster than the one ahead: the predictions never meet over the drive
    T = prob.steps * prob.dt_s
    for entries in lanes.values():
        entries.sort()
        for (xa, va), (xb, vb) in zip(entries, entries[1:]):
            assert xb - xa >= 20.0 and vb >= va
            assert (xb + vb * T) - (xa + va * T) >= 4.5


def test_p4_traffic_is_fixed_by_its_seed():
    poses = [(ob.pose, ob.motion) for ob in p4_traffic()]
    assert poses == [(ob.pose, ob.motion) for ob in p4_traffic(P4_SEED)]
    assert poses != [(ob.pose, ob.motion) for ob in p4_traffic(P4_SEED + 1)]


def test_p4_bench_entries_run_without_collision_and_its_length_caps_the_steps(monkeypatch):
    # P4 with its own length cut to 25 steps: asked for 1000, every entry runs 25
    monkeypatch.setitem(PROBLEMS, "P4", lambda: replace(p4(), steps=25))
    res = run_bench(["P4"], steps=1000)["P4"]
    assert set(res) >= {"mpcdrive", "mpcdrive_osqp", "mpcdrive_fast"}
    for rec in res.values():
        assert KEYS <= set(rec) and rec["steps"] == 25
        assert rec["solver_failures"] == 0 and rec["collision_steps"] == 0
        assert rec["min_obstacle_clearance_m"] > 0 and rec["max_lane_excess_m"] == 0.0
    assert res["mpcdrive_fast"]["backend"] == "fast"  # the compiled path covers P4
    # both backends drove the same closed loop
    assert res["mpcdrive_fast"]["rms_lateral_error_m"] == pytest.approx(
        res["mpcdrive_osqp"]["rms_lateral_error_m"], rel=1e-3, abs=1e-5
    )


def test_p4_ego_overtakes_the_slower_car_without_touching_anything():
    prob = p4()
    ctrl = make_controller(prob)
    plant = Plant(prob.model)
    x = prob.x0.copy()
    warm = ctrl.initial_warm(x)
    lead = next(ob for ob in prob.obstacles if ob.name == "lead")
    clear = math.inf
    steps = 110  # 11 s: the ego closes the 45 m gap at 6 m/s and gets past
    for k in range(steps):
        out = ctrl.step(x, warm)
        assert out.status in ("ok", "inaccurate") and not out.fallback
        warm = out.warm
        body = prob.footprint.polygon(*x[:3])
        clear = min(clear, min(shape_distance(body, ob.at(k * prob.dt_s)) for ob in prob.obstacles))
        x = plant.step(x, out.u, prob.dt_s)
    assert clear > 0.0
    # ahead of the slower car, back near its lane centre, near the reference speed
    assert x[0] - lead.pose_at(steps * prob.dt_s)[0] > prob.footprint.length_m
    assert abs(x[1]) < 1.75 and abs(x[3] - 20.0) < 2.0


def test_casadi_baseline_gets_the_same_obstacle_rows():
    pytest.importorskip("casadi")
    from mpcdrive.bench.baselines import CasadiIpoptMpc

    prob = p4()
    base = CasadiIpoptMpc(prob)
    assert len(base.rows_a) == prob.problem.N
    assert base.rows_b.shape == (base.core.problem.obstacle_rows, prob.problem.N)
    rec = time_closed_loop(base, prob, 3)
    assert rec["solver_failures"] == 0 and rec["collision_steps"] == 0


def test_casadi_baseline_plans_within_the_steering_rate_limit():
    """P4 is the first problem with an input-rate limit: the NLP must keep it as the QP does (a
    plan that ignores it is not what the car can do once the command is clipped)."""
    pytest.importorskip("casadi")
    from mpcdrive.bench.baselines import CasadiIpoptMpc

    prob = p4()
    base = CasadiIpoptMpc(prob)
    dmax = prob.problem.du_max_per_s[0] * prob.dt_s
    plant = Plant(prob.model)
    x = prob.x0.copy()
    warm = base.initial_warm(x)
    worst = 0.0
    for _ in range(70):  # into the lane change around the slower car
        u_prev = warm.u_prev[0]
        out = base.step(x, warm)
        warm = out.warm
        worst = max(worst, float(np.max(np.abs(np.diff(np.concatenate([[u_prev], warm.U[:, 0]]))))))
        x = plant.step(x, out.u, prob.dt_s)
    assert worst > 0.5 * dmax  # the limit is reached ...
    assert worst <= dmax + 1e-4  # ... and kept, to IPOPT's constraint tolerance (constr_viol_tol)


def test_the_documented_p4_traffic_is_the_one_built():
    """docs/benchmarks.md lists P4's cars; they must be those p4_traffic draws (to the rounding
    of the printed figures: half a unit of the last digit)."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md").read_text()
    rows = re.findall(r"^\| (lead|right\d|left\d|ego-lane\d) \| ([-\d.]+) \| ([-\d.]+) \| ([-\d.]+) \|$", text, re.M)
    built = {ob.name: (ob.pose[0], ob.pose[1], ob.motion.vx_mps) for ob in p4_traffic()}
    assert {r[0] for r in rows} == set(built) and len(rows) == len(built)
    for name, x, y, v in rows:
        bx, by, bv = built[name]
        assert abs(float(x) - bx) <= 0.05 and abs(float(y) - by) <= 0.05 and abs(float(v) - bv) <= 0.005
