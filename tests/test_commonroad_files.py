"""Every published CommonRoad file reads and drives, or is refused with one line naming the file,
the element and the reason (``tests/data/commonroad``; provenance in its README)."""

from pathlib import Path

import numpy as np
import pytest

from mpcdrive.adapters.commonroad import available

if not available():
    pytest.skip(
        "the commonroad extra (commonroad-io, commonroad-drivability-checker) is not installed", allow_module_level=True
    )

from mpcdrive.adapters.commonroad import load_commonroad  # noqa: E402

DIR = Path(__file__).resolve().parent / "data" / "commonroad"


def test_a_trajectory_repeating_its_initial_time_step_reads_once():
    """DEU_Cologne-63_5_I-1 (written by the interactive-scenario simulation) begins every
    recorded trajectory at the initial time step, repeating the initial state: that step is read
    once, and the obstacles move as recorded."""
    imp = load_commonroad(DIR / "DEU_Cologne-63_5_I-1.xml.gz")
    dynamic = {o.obstacle_id: o for o in imp.scenario.dynamic_obstacles}
    assert len(dynamic) == 34 and len(imp.spec.obstacles) == 34
    for o, entry in zip(imp.scenario.obstacles, imp.spec.obstacles):
        traj = entry.trajectory
        assert traj is not None, entry.name
        t = np.asarray(traj.t_s)
        assert t[0] == pytest.approx(o.initial_state.time_step * imp.spec.dt_s)
        assert np.all(np.diff(t) > 0), entry.name
        recorded = o.prediction.trajectory.state_list
        assert recorded[0].time_step == o.initial_state.time_step  # the repeat is in the file
        # one point per recorded step (the repeated one once), over the obstacle's lifetime
        assert len(traj.points) == len(recorded)
        assert traj.points[0] == pytest.approx(tuple(recorded[0].position))
        assert traj.points[-1] == pytest.approx(tuple(recorded[-1].position))
        assert entry.lifetime_s == pytest.approx((t[0], t[-1]))


def test_a_route_ending_where_its_lanelet_ends_keeps_the_lanes_width():
    """DEU_Gar-1_1_T-1's goal is on its start lanelet 47240, whose end is a slanted closing edge.
    A route ending there (as the file's did before the route went on past the goal along the
    lane) measured at its last point the road 0.05 m to its left, and the file was refused as
    narrower than the car. The edges are measured on into the successor: the road is the lane's
    width (2.2 m at the narrowest, the lane's end) up to the route's end."""
    from mpcdrive.adapters import commonroad_route as cr
    from mpcdrive.adapters.commonroad import _road

    imp = load_commonroad(DIR / "DEU_Gar-1_1_T-1.xml")
    assert imp.route[0] == 47240
    net = imp.scenario.lanelet_network
    line = cr.route_centerline(net, [47240], np.asarray(imp.planning_problem.initial_state.position, float))
    _, left, right, _ = _road(net, (47240,), line)
    assert (left + right).min() > 2.1
    assert left[-1] == pytest.approx(left[-2], abs=0.06) and right[-1] == pytest.approx(right[-2], abs=0.06)


def _make_cases():
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_cases", DIR.parent / "commonroad_cases" / "make_cases.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _tapering_file(tmp_path, with_neighbour: bool = True) -> Path:
    """A straight road along +x: lane 1 (the start lane, y = 0) 3.5 m wide up to x = 60, then
    tapering to 0.2 m at its end x = 100 (its left side stays, its right side comes in; no
    successor), and, ``with_neighbour``, lane 2 to its left going the same way (y = 3.5, to
    x = 200). The goal is a time only: the car drives its lane forward, into the taper."""
    from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
    from commonroad.common.util import Interval
    from commonroad.planning.goal import GoalRegion
    from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
    from commonroad.scenario.lanelet import Lanelet, LaneletType
    from commonroad.scenario.scenario import Location, Tag
    from commonroad.scenario.state import CustomState

    mc = _make_cases()
    x = np.linspace(0.0, 100.0, 101)
    right = np.where(x <= 60.0, -1.75, -1.75 + (3.5 - 0.2) * (x - 60.0) / 40.0)
    left = np.full_like(x, 1.75)
    lane1 = Lanelet(
        np.column_stack([x, left]),
        np.column_stack([x, 0.5 * (left + right)]),
        np.column_stack([x, right]),
        1,
        adjacent_left=2 if with_neighbour else None,
        adjacent_left_same_direction=True if with_neighbour else None,
        lanelet_type={LaneletType.HIGHWAY},
    )
    lanelets = [lane1]
    if with_neighbour:
        x2 = np.linspace(0.0, 200.0, 201)
        lanelets.append(
            Lanelet(
                np.column_stack([x2, np.full_like(x2, 5.25)]),
                np.column_stack([x2, np.full_like(x2, 3.5)]),
                np.column_stack([x2, np.full_like(x2, 1.75)]),
                2,
                adjacent_right=1,
                adjacent_right_same_direction=True,
                lanelet_type={LaneletType.HIGHWAY},
            )
        )
    sc = mc._scenario(9, lanelets)
    goal = GoalRegion([CustomState(time_step=Interval(30, 60))])
    pps = PlanningProblemSet([PlanningProblem(1000, mc._initial(10.0, 0.0, 0.0, 8.0), goal)])
    path = tmp_path / "ZAM_Taper-1_1_T-1.xml"
    writer = CommonRoadFileWriter(sc, pps, tags={Tag.HIGHWAY, Tag.LANE_CHANGE}, location=Location())
    writer.write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    return path


def test_a_route_lane_that_tapers_away_takes_in_the_lane_beside_it(tmp_path):
    """The start lane tapers to 0.2 m (a merge lane): it was refused as "not wider than the car".
    Where it is narrower than any car the road takes in the lane beside it going its way, so the
    car can leave the lane it is in; before the taper the road is the lane and the lane beside
    it its neighbour."""
    from mpcdrive.adapters.commonroad import TAPER_WIDTH_M

    imp = load_commonroad(_tapering_file(tmp_path))
    assert imp.route == (1,)
    w = np.array(imp.spec.road.widths)
    x = imp.centerline[:, 0]
    before, tip = x < 55.0, x > 95.0
    assert np.allclose(w[before, 1:].sum(axis=1), 3.5, atol=0.1)
    # lane 2 beside it, a lane the planner may change into, 3.5 m wide left of the route lane
    lanes = [np.asarray(ln.rows) for ln in imp.spec.road.lane_rows or [] if not ln.oncoming]
    lane2 = [r for r in lanes if r[before, 2].min() > 1.0]
    assert len(lane2) == 1 and np.allclose((lane2[0][:, 1] - lane2[0][:, 2])[before], 3.5, atol=0.15)
    assert np.all(w[tip, 1:].sum(axis=1) > 3.5)  # the route lane and lane 2 together
    # the lane's own width where the road takes lane 2 in: narrower than TAPER_WIDTH_M
    own = 1.75 - np.interp(x, [0, 60, 100], [-1.75, -1.75, 1.45])
    assert np.all(w[own < TAPER_WIDTH_M - 0.1, 1] > 3.0)


def _bottleneck_file(tmp_path, narrowest_m: float) -> Path:
    """One lane along +x, 3.5 m wide, narrowing to ``narrowest_m`` between x = 70 and 80 (from
    60, back to 3.5 m by 90), no lane beside it; the goal lies past the narrows at x = 120."""
    from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
    from commonroad.scenario.lanelet import Lanelet, LaneletType
    from commonroad.scenario.scenario import Location, Tag

    mc = _make_cases()
    x = np.linspace(0.0, 150.0, 151)
    half = 0.5 * np.interp(x, [0, 60, 70, 80, 90, 150], [3.5, 3.5, narrowest_m, narrowest_m, 3.5, 3.5])
    lane = Lanelet(
        np.column_stack([x, half]),
        np.column_stack([x, np.zeros_like(x)]),
        np.column_stack([x, -half]),
        7,
        lanelet_type={LaneletType.URBAN},
    )
    sc = mc._scenario(8, [lane])
    pps = mc._problem(1000, mc._initial(10.0, 0.0, 0.0, 8.0), (120.0, 0.0), 0.0, 10.0, 3.0, 150)
    path = tmp_path / "ZAM_Narrows-1_1_T-1.xml"
    writer = CommonRoadFileWriter(sc, pps, tags={Tag.URBAN}, location=Location())
    writer.write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    return path


def _cli(monkeypatch, capsys, *args) -> tuple[int, str]:
    """(exit code, stderr) of ``mpcdrive ARGS`` run in this process."""
    import sys

    from mpcdrive.cli import main

    monkeypatch.setattr(sys, "argv", ["mpcdrive", *map(str, args)])
    with pytest.raises(SystemExit) as ex:
        main()
    return int(ex.value.code), capsys.readouterr().err


def test_a_road_narrower_than_the_car_is_refused_in_one_line_naming_the_lanelet(tmp_path, monkeypatch, capsys):
    """A lane that narrows to 1.2 m with no lane beside it, and the goal past it: the car cannot
    get through. ``mpcdrive run`` exits 2 with one line: the file, the lanelet, the reason."""
    f = _bottleneck_file(tmp_path, 1.2)
    with pytest.raises(ValueError) as e:
        load_commonroad(f)
    msg = str(e.value)
    assert "\n" not in msg and "validation error" not in msg
    assert msg.startswith("lanelet 7, ") and "not wider than the car" in msg
    code, err = _cli(monkeypatch, capsys, "run", f, "--out", tmp_path / "out", "-q")
    assert code == 2 and err.count("\n") == 1
    assert err.startswith(f"mpcdrive: {f}: lanelet 7, ") and "not wider than the car" in err
    assert not (tmp_path / "out").exists()


def test_a_car_too_wide_for_the_narrows_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    """Narrows of 1.75 m let the Ford Escort (1.674 m wide) through but not the VW Vanagon
    (1.844 m): --vehicle vw_vanagon is refused in one line naming the lanelet."""
    from mpcdrive.adapters.commonroad import with_vehicle

    f = _bottleneck_file(tmp_path, 1.75)
    imp = load_commonroad(f)  # the Ford Escort fits
    with pytest.raises(ValueError) as e:
        with_vehicle(imp, "vw_vanagon")
    assert "\n" not in str(e.value) and str(e.value).startswith("lanelet 7, ")
    code, err = _cli(monkeypatch, capsys, "run", f, "--vehicle", "vw_vanagon", "--out", tmp_path / "out", "-q")
    assert code == 2 and err.count("\n") == 1 and err.startswith(f"mpcdrive: {f}: lanelet 7, ")
    assert "vehicle.width_m 1.844" in err


def test_a_refused_obstacle_is_one_line_naming_it(tmp_path, monkeypatch, capsys):
    """An obstacle the schema refuses (here DEU_Cologne-63_5_I-1's repeated time steps, read as
    they were before they were read once) is one line naming the obstacle's CommonRoad id and
    the reason, and how many more were refused: not pydantic's dump of all 34 errors."""
    import mpcdrive.adapters.commonroad as cr

    monkeypatch.setattr(cr, "_distinct_steps", lambda states: states)
    f = DIR / "DEU_Cologne-63_5_I-1.xml.gz"
    from commonroad.common.file_reader import CommonRoadFileReader

    from mpcdrive.adapters.commonroad_file import read_file

    oid = (
        read_file(CommonRoadFileReader, f)[0].obstacles[0].obstacle_id
    )  # the first obstacle's id, as the file gives it
    with pytest.raises(ValueError) as e:
        cr.load_commonroad(f)
    msg = str(e.value)
    assert "\n" not in msg and "errors.pydantic.dev" not in msg
    assert msg.startswith(f"obstacle {oid} (obstacles.0.trajectory): t_s must be strictly increasing (and 33 more")
    code, err = _cli(monkeypatch, capsys, "run", f, "--out", tmp_path / "out", "-q")
    assert code == 2 and err == f"mpcdrive: {f}: {msg}\n"
