"""SUMO traffic around a CommonRoad drive: the co-simulation and each pitfall it works around.

Real SUMO (libsumo, in-process) on the scenario files of ``tests/data/commonroad``; the extra
``sumo`` (eclipse-sumo, libsumo, commonroad-sumo) is installed by the README's test command.
"""

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mpcdrive.adapters.commonroad import available as commonroad_available

if not commonroad_available():
    pytest.skip("the commonroad extra is not installed", allow_module_level=True)

from mpcdrive.adapters import commonroad_sumo as cs  # noqa: E402

if not cs.available():
    pytest.skip("the sumo extra (eclipse-sumo, libsumo, commonroad-sumo) is not installed", allow_module_level=True)

from mpcdrive.adapters.commonroad import load_commonroad  # noqa: E402
from mpcdrive.adapters.commonroad_traffic import prepare, with_traffic  # noqa: E402
from mpcdrive.models import KinematicBicycle4, KinematicParams  # noqa: E402
from mpcdrive.scenarios import build_experiment  # noqa: E402
from mpcdrive.sim import Plant  # noqa: E402
from mpcdrive.sim.closed_loop import EpisodicPlant, ObservedPlant, TrafficPlant  # noqa: E402

DIR = Path(__file__).resolve().parent / "data" / "commonroad"
US101 = DIR / "USA_US101-3_1_T-1.xml"
EGO_SHAPE = (4.5, 1.8)


@pytest.fixture(scope="module")
def us101():
    """US-101's import and its SUMO files (built once for the module)."""
    imp = load_commonroad(US101)
    tmp = cs.tempdir()
    files = cs.build_sumo_files(imp.scenario, Path(tmp.name))
    yield imp, files
    tmp.cleanup()


def _plant(imp, files):
    """The ego as mpcdrive's kinematic bicycle among US-101's SUMO traffic."""
    return cs.SumoTrafficPlant(
        Plant(KinematicBicycle4(KinematicParams(1.3, 1.4))),
        files,
        dt_s=imp.spec.dt_s,
        ego_shape=EGO_SHAPE,
        centerline=imp.centerline,
    )


def _x0(imp) -> np.ndarray:
    s = imp.spec.initial_state
    return np.array([s.x_m, s.y_m, math.radians(s.yaw_deg), s.v_mps])


def _drive(imp, files, brake_at: int | None, steps: int = 60, decel: float = 8.0):
    """Drive the ego straight at its start speed, braking at ``decel`` from step ``brake_at``;
    the speeds of every SUMO vehicle per step and the id of the ego's follower at the start."""
    plant = _plant(imp, files)
    try:
        xp = plant.initial_state(_x0(imp))
        follower = plant.session._ls.vehicle.getFollower(cs.EGO_ID, 50.0)[0]
        speeds = {}
        for k in range(steps):
            a = -decel if brake_at is not None and k >= brake_at else 0.0
            xp = plant.step(xp, np.array([0.0, a]), imp.spec.dt_s)
            for vid, s in plant.session.states().items():
                speeds.setdefault(vid, []).append(s.v_mps)
        return follower, speeds, plant
    finally:
        plant.close()


def test_the_plant_is_an_observed_plant_with_traffic_that_runs_until_the_loop_ends(us101):
    imp, files = us101
    plant = _plant(imp, files)
    assert isinstance(plant, ObservedPlant) and isinstance(plant, TrafficPlant)
    # commonroad-sumo's own loop stops at the goal (3.3 s on a time-only goal): this plant never
    # ends the episode itself, the closed loop does
    assert not isinstance(plant, EpisodicPlant)


def test_a_sumo_follower_brakes_when_the_ego_brakes(us101):
    imp, files = us101
    follower, cruise, _ = _drive(imp, files, brake_at=None)
    follower_b, braking, _ = _drive(imp, files, brake_at=20)
    assert follower == follower_b and follower != ""
    vid = int(follower)
    v_cruise, v_brake = np.array(cruise[vid]), np.array(braking[vid])
    # the same until the ego brakes (SUMO is deterministic with its seed)
    np.testing.assert_array_equal(v_cruise[:20], v_brake[:20])
    assert v_cruise[-1] > 7.0  # behind an ego at constant speed it drives on
    assert v_brake.min() < 0.5 * v_cruise[-1]  # behind a braking ego it brakes too


def test_repeated_runs_are_identical(us101):
    imp, files = us101
    _, a, _ = _drive(imp, files, brake_at=10, steps=30)
    _, b, _ = _drive(imp, files, brake_at=10, steps=30)
    assert a.keys() == b.keys()
    for vid in a:
        assert a[vid] == b[vid]


def test_map_matching_radius_keeps_the_car_behind_the_ego(us101, tmp_path):
    imp, files = us101
    narrow = cs.build_sumo_files(imp.scenario, tmp_path, cs.SumoSettings(map_matching_m=5.0))
    follower, _, _ = _drive(imp, files, brake_at=None, steps=1)
    ids_narrow = {v.id for v in narrow.vehicles}
    ids = {v.id for v in files.vehicles}
    assert len(ids) >= 30 > len(ids_narrow)  # 35 recorded: 30 routed at 12 m, 18 at commonroad-sumo's 5 m
    assert int(follower) in ids - ids_narrow
    # the vehicles SUMO cannot route stay recorded obstacles
    assert set(files.unrouted) == {int(o.obstacle_id) for o in imp.scenario.dynamic_obstacles} - ids


def test_the_ego_is_driven_at_its_real_speed_in_sumo(us101):
    """Speed mode 0: SUMO takes the pushed speed as it is, braking harder than its own limits."""
    imp, files = us101
    x = _x0(imp)
    s = cs.SumoSession(files, imp.spec.dt_s)
    s.start(tuple(x[:3]), x[3], EGO_SHAPE, cs.route_edges(files.net, imp.centerline))
    try:
        got_checked = []
        got = []
        v = x[3]
        pose = x[:3].copy()
        for k in range(8):
            v -= 0.8  # 8 m/s^2 at dt 0.1 s: beyond SUMO's default deceleration of 4.5 m/s^2
            pose[:2] += v * imp.spec.dt_s * np.array([math.cos(pose[2]), math.sin(pose[2])])
            s.push_ego(tuple(pose), v)
            if k >= 4:  # with SUMO's checks on (its default speed mode) the speed is its own
                s._ls.vehicle.setSpeedMode(cs.EGO_ID, 31)
            s.step()
            (got if k < 4 else got_checked).append((v, s.ego_state().v_mps))
    finally:
        s.close()
    for pushed, in_sumo in got:
        assert in_sumo == pytest.approx(pushed, abs=1e-6)
    assert any(abs(in_sumo - pushed) > 0.1 for pushed, in_sumo in got_checked)


def test_recorded_vehicles_are_free_to_speed_up_past_their_start_speed(us101):
    imp, files = us101
    _, speeds, _ = _drive(imp, files, brake_at=None, steps=40)
    start = {int(o.obstacle_id): float(o.initial_state.velocity) for o in imp.scenario.dynamic_obstacles}
    gains = [max(v) - start[vid] for vid, v in speeds.items()]
    assert max(gains) > 1.0  # a capped vehicle (commonroad-sumo's start) never exceeds its start speed


def test_drivers_see_the_ego_as_it_is_not_one_step_late(us101):
    """The ego stops dead at step k (its state after step k has speed 0): its follower brakes in
    SUMO's step k + 1, as it would behind a SUMO vehicle; pushing the ego's state of the step
    it starts (commonroad-sumo's order) shows it one step later."""
    imp, files = us101
    x = _x0(imp)
    first = {}
    for order in ("after", "before"):
        s = cs.SumoSession(files, imp.spec.dt_s)
        s.start(tuple(x[:3]), x[3], EGO_SHAPE, cs.route_edges(files.net, imp.centerline))
        try:
            fol = s._ls.vehicle.getFollower(cs.EGO_ID, 50.0)[0]
            pose, v = x[:3].copy(), float(x[3])
            states = [(pose.copy(), v)]
            fv = []
            for k in range(12):
                if k == 5:
                    v = 0.0
                pose[:2] += v * imp.spec.dt_s * np.array([math.cos(pose[2]), math.sin(pose[2])])
                states.append((pose.copy(), v))
                push = states[k + 1] if order == "after" else states[k]
                s.push_ego(tuple(push[0]), push[1])
                s.step()
                fv.append(s.states()[int(fol)].v_mps)
        finally:
            s.close()
        dv = np.diff(fv)
        first[order] = int(np.flatnonzero(dv < -0.3)[0]) + 1  # the step whose speed shows the braking
    assert first["after"] == 6  # braking in SUMO's step 6, the step after the ego's stop
    assert first["before"] == first["after"] + 1


def _route_junction_lanes(ls, route: list[str]) -> set[str]:
    """The junction lanes that lead from each edge of ``route`` to the next (SUMO's links, their
    internal lanes followed to the next edge)."""
    out = set()
    for a, b in zip(route, route[1:]):
        for i in range(ls.edge.getLaneNumber(a)):
            for link in ls.lane.getLinks(f"{a}_{i}"):
                to, via = link[0], link[4]
                if ls.lane.getEdgeID(to) != b:
                    continue
                while via and via.startswith(":"):
                    out.add(via)
                    nxt = [lk[4] or lk[0] for lk in ls.lane.getLinks(via)]
                    via = nxt[0] if nxt else ""
    return out


def test_at_a_junction_the_ego_stays_on_the_lanes_of_its_route(tmp_path):
    """DEU_Backnang's route crosses a junction: placed anywhere (commonroad-sumo's moveToXY),
    the ego lands on the junction's nearest lane, of another connection, where a car behind it
    on its route does not see it; kept to its route, it is on its route's connection."""
    imp = load_commonroad(DIR / "DEU_Backnang-9_1_T-1.xml")
    files = cs.build_sumo_files(imp.scenario, tmp_path)
    route = cs.route_edges(files.net, imp.centerline)
    c = np.asarray(imp.centerline, float)
    yaw = np.arctan2(np.gradient(c[:, 1]), np.gradient(c[:, 0]))
    junction = {}
    for name, edges in (("route", route), ("anywhere", [])):
        s = cs.SumoSession(files, imp.spec.dt_s)
        s.start((c[2, 0], c[2, 1], yaw[2]), 5.0, EGO_SHAPE, edges)
        lanes = []
        try:
            allowed = _route_junction_lanes(s._ls, s.ego_route if edges else route)
            for i in range(3, len(c), 2):
                s.push_ego((c[i, 0], c[i, 1], yaw[i]), 5.0)
                s.step()
                lanes.append(s.ego_lane())
        finally:
            s.close()
        junction[name] = {ln for ln in lanes if ln.startswith(":")}
    assert junction["route"] and junction["route"] <= allowed
    assert junction["anywhere"] - allowed  # the pitfall this works around


def test_static_obstacles_and_unrouted_vehicles_stay_commonroad_obstacles():
    imp = with_traffic(load_commonroad(DIR / "ZAM_Tutorial-1_2_T-1.xml"), "sumo")
    assert imp.prediction == "lane" and imp.spec.duration_s >= cs.DURATION_S
    exp = prepare(imp, build_experiment(imp.spec))
    try:
        plant = exp.plant
        static = [o for o in imp.scenario.static_obstacles]
        assert len(static) == 1
        assert [o.name for o in exp.obstacles] == [f"{o.obstacle_type.value}-{o.obstacle_id}" for o in static]
        assert not any(o.moving for o in exp.obstacles)
        assert len(plant.files.vehicles) == len(imp.scenario.dynamic_obstacles) == 2
    finally:
        exp.plant.close()
        imp.runtime["tempdir"].cleanup()


def test_the_ego_id_is_no_vehicle_id_and_the_ego_is_where_it_is_pushed(us101):
    """Generated traffic takes ids SUMO counts up; the scenario's vehicles have CommonRoad's
    numbers: the ego's id is neither, so no vehicle is teleported onto it."""
    imp, files = us101
    assert not cs.EGO_ID.isdigit()
    assert cs.EGO_ID not in {str(v.id) for v in files.vehicles}
    plant = _plant(imp, files)
    try:
        xp = plant.initial_state(_x0(imp))
        for _ in range(10):
            xp = plant.step(xp, np.array([0.02, 0.5]), imp.spec.dt_s)
            s = plant.session.ego_state()
            assert (s.x_m, s.y_m) == pytest.approx((xp[0], xp[1]), abs=1e-6)
    finally:
        plant.close()


def test_netconvert_is_found_without_sumo_home_and_sumo_runs_in_process(tmp_path):
    """A fresh interpreter with neither SUMO_HOME nor the environment's scripts on its PATH
    converts a scenario and simulates it in-process: no SUMO program runs as a child process
    (the GUI binary hangs headless)."""
    code = (
        "import os, sys\n"
        "from pathlib import Path\n"
        "from mpcdrive.adapters import commonroad_sumo as cs\n"
        "from mpcdrive.adapters.commonroad import load_commonroad\n"
        "imp = load_commonroad(sys.argv[1])\n"
        "files = cs.build_sumo_files(imp.scenario, Path(sys.argv[2]))\n"
        "s = cs.SumoSession(files, imp.spec.dt_s)\n"
        "st = imp.spec.initial_state\n"
        "import math\n"
        "s.start((st.x_m, st.y_m, math.radians(st.yaw_deg)), st.v_mps, (4.5, 1.8), [])\n"
        "kids = [p for p in os.listdir('/proc') if p.isdigit() and open(f'/proc/{p}/stat').read().split()[3] == str(os.getpid())]\n"
        "s.step(); s.close()\n"
        "print(len(files.vehicles), len(kids))\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "SUMO_HOME"}
    env["PATH"] = "/usr/bin:/bin"
    out = subprocess.run(
        [sys.executable, "-c", code, str(DIR / "ZAM_Tutorial-1_1_T-1.xml"), str(tmp_path)],
        env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    n_vehicles, n_children = (int(v) for v in out.stdout.split()[-2:])
    assert n_vehicles == 1 and n_children == 0


def test_sumo_with_a_known_future_is_refused():
    imp = load_commonroad(DIR / "ZAM_Tutorial-1_1_T-1.xml")
    with pytest.raises(ValueError, match="no known future"):
        with_traffic(imp, "sumo", "known")


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "mpcdrive.cli", *args], capture_output=True, text=True, cwd=cwd)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--traffic", "sumo", "--prediction", "known"], "--prediction known: SUMO traffic has no known future"),
        (["--traffic", "replay"], "--traffic: unknown traffic 'replay'"),
        (["--prediction", "oracle"], "--prediction: unknown prediction 'oracle'"),
    ],
)
def test_bad_traffic_flags_are_bad_input(args, message, tmp_path):
    for cmd in (["run", str(DIR / "ZAM_Tutorial-1_1_T-1.xml")], ["commonroad", str(DIR / "ZAM_Tutorial-1_1_T-1.xml")]):
        r = _cli(*cmd, *args, "--out", str(tmp_path / "out"), cwd=tmp_path)
        assert r.returncode == 2, r.stderr
        assert r.stderr.strip().splitlines()[-1] == f"mpcdrive: {message}" or message in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1
        assert not (tmp_path / "out").exists()


def test_traffic_flags_are_for_commonroad_files(tmp_path):
    r = _cli("run", "paper-exp1", "--traffic", "sumo", cwd=tmp_path)
    assert r.returncode == 2 and "are for CommonRoad files" in r.stderr


@pytest.mark.slow
def test_a_drive_among_sumo_traffic_is_judged_against_the_vehicles_as_sumo_drove_them(tmp_path):
    """``mpcdrive run FILE --traffic sumo``: the checks, the scene figure and the replay take the
    SUMO vehicles' actual trajectories; sumo.json has the co-simulation's figures."""
    import json

    out = tmp_path / "run"
    r = _cli("run", str(DIR / "ZAM_Tutorial-1_2_T-1.xml"), "--traffic", "sumo", "-q", "--out", str(out), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "metrics.json").read_text())
    d = json.loads((out / "sumo.json").read_text())
    assert d["vehicles_simulated"] == d["vehicles_in_sumo"] == 2 and d["vehicles_recorded"] == []
    assert d["sumo_step_ms"]["steps"] == m["steps"] + 1  # one SUMO step per loop step, and one inserting the car
    assert m["commonroad"]["goal_step"] == 35
    assert m["steps"] > 35 + 50  # the drive goes on past the goal (commonroad-sumo's loop stops there)
    assert d["whole_drive"]["states"] == m["steps"] and d["whole_drive"]["collision_free"] is True
    assert m["commonroad"]["goal_reached"] is True
    base = d["sumo_driver"]
    assert base["steps"] > 0 and base["progress_m"] > 0 and d["ego"]["progress_m"] > 0
    # the replay holds the static obstacle and the SUMO vehicles, moving, as SUMO drove them
    html = (out / "report.html").read_text()
    i = html.index('"obstacles":') + len('"obstacles":')
    obstacles, _ = json.JSONDecoder().raw_decode(html[i:])
    moving = [o for o in obstacles if np.ndim(o["p"]) == 3]
    assert len(obstacles) == 3 and len(moving) == 2
    assert all(len(o["p"]) == m["steps"] for o in moving)
    assert (out / "commonroad_scene.png").stat().st_size > 10_000


@pytest.mark.slow
def test_the_batch_table_names_traffic_and_prediction(tmp_path):
    import json

    out = tmp_path / "cr"
    f = str(DIR / "ZAM_Tutorial-1_1_T-1.xml")
    r = _cli("commonroad", f, "--traffic", "recorded", "--prediction", "lane", "--workers", "1", "--out", str(out))
    assert r.returncode == 0, r.stderr
    row = json.loads((out / "summary.json").read_text())["ZAM_Tutorial-1_1_T-1.xml"]
    assert (row["traffic"], row["prediction"], row["sumo"]) == ("recorded", "lane", None)
    line = next(ln for ln in (out / "summary.md").read_text().splitlines() if ln.startswith("| `ZAM_Tutorial-1_1"))
    verdict = "passed" if row["passed"] else "failed"
    assert line.startswith(f"| `ZAM_Tutorial-1_1_T-1.xml` | {verdict}") and line.endswith("| recorded / lane |")


def test_a_car_moved_across_a_gap_of_the_converted_net_is_reported():
    """Where a converted junction lane does not join the lane it leads to, SUMO moves a car
    across the gap in one step (DEU_Backnang: 19 m at 11.8 m/s): sumo.json lists it."""
    from types import SimpleNamespace

    from mpcdrive.adapters.commonroad_traffic import position_jumps

    log = cs.TrafficLog(0.1)
    for k, x in enumerate([0.0, 1.2, 2.4, 21.4, 22.6]):
        log.record(k, {7: cs.VehicleState(x, 0.0, 0.0, 12.0), 8: cs.VehicleState(0.0, 1.2 * k, 1.57, 12.0)})
    assert position_jumps(SimpleNamespace(dt_s=0.1, log=log)) == [{"vehicle": 7, "step": 3, "jump_m": 19.0}]


@pytest.mark.parametrize("name", ["FRA_Anglet-1_1_T-1.xml", "DEU_Backnang-9_1_T-1.xml"])
def test_the_ego_route_runs_the_ego_way_so_the_cars_behind_see_it(name, tmp_path):
    """Matched by distance to an edge's middle line alone (commonroad-sumo's map matcher), the
    ego's route began on the lane of the opposite direction: SUMO held the ego at that lane's
    start and a motorcycle behind it (FRA_Anglet), a car behind it (DEU_Backnang) drove into
    it. The route matched lane by lane and direction: the ego moves along its lane, and the car
    behind has it as its leader."""
    imp = load_commonroad(DIR / name)
    files = cs.build_sumo_files(imp.scenario, tmp_path)
    route = cs.route_edges(files.net, imp.centerline)
    x = _x0(imp)
    s = cs.SumoSession(files, imp.spec.dt_s)
    s.start(tuple(x[:3]), x[3], EGO_SHAPE, route)
    try:
        V = s._ls.vehicle
        track = [(V.getRoadID(cs.EGO_ID), V.getLanePosition(cs.EGO_ID))]
        pose, v = x[:3].copy(), float(x[3])
        leaders = set()
        for _ in range(10):
            pose[:2] += v * imp.spec.dt_s * np.array([math.cos(pose[2]), math.sin(pose[2])])
            s.push_ego(tuple(pose), v)
            s.step()
            track.append((V.getRoadID(cs.EGO_ID), V.getLanePosition(cs.EGO_ID)))
            for vid in V.getIDList():
                lead = V.getLeader(vid, 100.0) if vid != cs.EGO_ID else None
                if lead and lead[0] == cs.EGO_ID:
                    leaders.add(vid)
        assert all(road in route or road.startswith(":") for road, _ in track)  # its route and its junctions
        moves = [b - a for (ra, a), (rb, b) in zip(track, track[1:]) if ra == rb]
        assert moves and min(moves) > 0.5 * v * imp.spec.dt_s  # along its lane, not held at a lane's start
        assert leaders  # some car drives behind the ego, seeing it
    finally:
        s.close()


def test_the_scenario_judged_and_drawn_holds_the_vehicles_as_sumo_drove_them(us101):
    """The checks and the scene figure take a copy of the scenario in which each SUMO vehicle
    follows the states SUMO gave it; the vehicles SUMO could not route stay as recorded."""
    from mpcdrive.adapters.commonroad_traffic import driven_scenario

    imp, files = us101
    plant = _plant(imp, files)
    try:
        xp = plant.initial_state(_x0(imp))
        for _ in range(15):
            xp = plant.step(xp, np.array([0.0, -3.0]), imp.spec.dt_s)
    finally:
        plant.close()
    sc = driven_scenario(imp, plant)
    for vid, states in plant.log.states.items():
        o = sc.obstacle_by_id(vid)
        for k, s in states.items():
            st = o.state_at_time(k)
            assert tuple(st.position) == pytest.approx((s.x_m, s.y_m))
            assert st.orientation == pytest.approx(s.yaw_rad) and st.velocity == pytest.approx(s.v_mps)
        recorded = imp.scenario.obstacle_by_id(vid).prediction.trajectory.state_at_time_step(15)
        if recorded is not None and 15 in states:  # SUMO drove it elsewhere than the recording
            assert tuple(recorded.position) != pytest.approx((states[15].x_m, states[15].y_m), abs=1e-3)
    assert files.unrouted
    for vid in files.unrouted:
        got, rec = sc.obstacle_by_id(vid), imp.scenario.obstacle_by_id(vid)
        for k in (0, 10):
            a, b = got.occupancy_at_time(k), rec.occupancy_at_time(k)
            assert (a is None) == (b is None)
            if a is not None:
                np.testing.assert_allclose(a.shape.center, b.shape.center)
