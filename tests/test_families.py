"""The generated scenario families (``scenario_families.py``): each generator is deterministic and
gives valid scenarios (quick), and the controller passes at least 9 of the 10 seeds of each
family on CommonRoad's ST model of the BMW 320i (slow: 60 closed-loop runs).

The runs take the path ``mpcdrive run FILE.xml --plant st --vehicle bmw_320i`` takes (read, map,
vehicle, recorded traffic, the initial-overlap and path checks, :func:`mpcdrive.runs.run_into`
with the CommonRoad outputs, whose checks -- the drivability checker and CommonRoad's solution
checker -- judge the run) and the same verdict; only the figures and the HTML replay are not
drawn (they are most of a run's time and no part of its verdict).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from mpcdrive.adapters.commonroad import available

if not available():
    pytest.skip(
        "the commonroad extra (commonroad-io, commonroad-drivability-checker) is not installed", allow_module_level=True
    )

import scenario_families as sf  # noqa: E402

SEEDS = sf.TEST_SEEDS
MIN_PASSED = 9  # of the 10 seeds of a family
PLANT, VEHICLE = "st", "bmw_320i"


def drive(path: Path, out_dir: Path, monkeypatch) -> dict:
    """Run the CommonRoad file ``path`` as ``mpcdrive run`` does (module docstring) into
    ``out_dir``; returns the written metrics' verdict (``passed``, ``line``, ``problems``,
    ``reasons``)."""
    from mpcdrive.adapters import commonroad_figures
    from mpcdrive.adapters.commonroad import load_commonroad, with_vehicle
    from mpcdrive.adapters.commonroad_traffic import with_traffic
    from mpcdrive.adapters.commonroad_vehicles import commonroad_plant
    from mpcdrive.runs import run_into
    from mpcdrive.scenarios import reject_initial_overlap, warn_suspicious

    monkeypatch.setattr("mpcdrive.plots.write_run_figures", lambda result, out_dir: [])
    monkeypatch.setattr("mpcdrive.report.write_run_html", lambda *a, **k: None)
    monkeypatch.setattr(
        commonroad_figures, "write_scene_figure", lambda imp, result, out_dir, step: Path(out_dir) / "scene.png"
    )
    imp = with_traffic(with_vehicle(load_commonroad(path), VEHICLE, PLANT), None, None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        warn_suspicious(reject_initial_overlap(imp.spec, str(path)), str(path))
    _, metrics, _, _ = run_into(
        imp.spec,
        out_dir,
        source=str(path),
        extra_outputs=imp.write_outputs,
        prepare=imp.prepare_experiment,
        plant_factory=commonroad_plant,
    )
    v = metrics.verdict
    return {"passed": v.passed, "line": v.line(imp.spec.id), "problems": v.problems(), "reasons": list(v.reasons)}


# -- quick: deterministic, valid -----------------------------------------------------------------------
@pytest.mark.parametrize("family", sorted(sf.FAMILIES))
def test_generator_is_deterministic_per_seed(family, tmp_path):
    a = sf.write_scenario(family, 3, tmp_path / "a").read_bytes()
    b = sf.write_scenario(family, 3, tmp_path / "b").read_bytes()
    c = sf.write_scenario(family, 4, tmp_path / "c").read_bytes()
    assert a == b
    assert a != c


def _ego_rectangle(init, length: float, width: float):
    from shapely.geometry import Polygon

    x, y = np.asarray(init.position, float)
    yaw = float(init.orientation)
    c, s = math.cos(yaw), math.sin(yaw)
    corners = [(dx, dy) for dx, dy in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
    return Polygon(
        [
            (x + 0.5 * length * dx * c - 0.5 * width * dy * s, y + 0.5 * length * dx * s + 0.5 * width * dy * c)
            for dx, dy in corners
        ]
    )


@pytest.mark.parametrize("family", sorted(sf.FAMILIES))
def test_generated_scenarios_are_valid(family, tmp_path):
    """Every seed: readable by commonroad-io, a route the project's reader finds to the goal
    within the time window, the ego's body inside its lanelet at t = 0 and clear of every
    obstacle, the window 8-15 s long at most, every moving car on the road."""
    import shapely
    from commonroad.common.file_reader import CommonRoadFileReader

    from mpcdrive.adapters.commonroad import load_commonroad, with_vehicle
    from mpcdrive.scenarios import reject_initial_overlap

    for seed in SEEDS:
        path = sf.write_scenario(family, seed, tmp_path)
        scenario, pps = CommonRoadFileReader(str(path)).open()
        pp = next(iter(pps.planning_problem_dict.values()))
        net = scenario.lanelet_network
        imp = with_vehicle(load_commonroad(path), VEHICLE, PLANT)
        label = f"{family} seed {seed}"
        assert imp.plan.note.startswith("drives into the goal region"), f"{label}: {imp.plan.note}"
        goal = pp.goal.state_list[0]
        assert 8.0 <= goal.time_step.end * scenario.dt <= 15.0 + 1e-9, label
        reject_initial_overlap(imp.spec, label)
        v = imp.spec.vehicle
        ego = _ego_rectangle(pp.initial_state, v.length_m, v.width_m)
        lane = net.find_lanelet_by_id(imp.route[0]).polygon.shapely_object.buffer(1e-6)
        assert lane.contains(ego), f"{label}: the ego's body is not inside lanelet {imp.route[0]} at t = 0"
        road = shapely.union_all([ll.polygon.shapely_object.buffer(0.01) for ll in net.lanelets])
        for o in scenario.obstacles:
            shape = o.occupancy_at_time(0).shape.shapely_object
            assert shape.distance(ego) > 0.5, f"{label}: obstacle {o.obstacle_id} touches the ego at t = 0"
            states = getattr(getattr(o, "prediction", None), "trajectory", None)
            for st in states.state_list if states is not None else []:
                occ = o.occupancy_at_time(st.time_step).shape.shapely_object
                assert road.contains(occ), f"{label}: obstacle {o.obstacle_id} off the road at step {st.time_step}"


# -- slow: the controller on each family ---------------------------------------------------------------
#: families the maneuver planner does not yet drive 9 of 10: the pass counts measured on ST / BMW
#: 320i (docs/planning.md, "Where it stands"). The lane rules it replaced passed parked_follower
#: 8, congestion_follower 5, left_turn 2, blocked_oncoming 0, road_end 10, roundabout_exit 9.
BELOW_TARGET: dict[str, int] = {}  # every family at 9 or 10 of 10 since the goal is judged for the car


@pytest.mark.slow
@pytest.mark.parametrize(
    "family",
    [
        pytest.param(f, marks=pytest.mark.xfail(reason=f"{BELOW_TARGET[f]}/10 today: below the target of 9"))
        if f in BELOW_TARGET
        else f
        for f in sorted(sf.FAMILIES)
    ],
)
def test_family_passes_nine_of_ten(family, tmp_path, monkeypatch):
    outcomes = {}
    for seed in SEEDS:
        path = sf.write_scenario(family, seed, tmp_path)
        outcomes[seed] = drive(path, tmp_path / f"run-{seed}", monkeypatch)
    passed = [s for s, o in outcomes.items() if o["passed"]]
    failed = "\n".join(f"  seed {s}: {o['line']}" for s, o in outcomes.items() if not o["passed"])
    assert len(passed) >= MIN_PASSED, f"{family}: {len(passed)}/10 passed; failed:\n{failed}"


def test_the_generator_writes_held_out_seeds_and_refuses_bad_arguments(tmp_path):
    """``--seeds 10:12`` writes seeds 10 and 11 (files -11 and -12), the same bytes as
    :func:`write_scenario`; an unknown family or a malformed range is refused in one line."""
    paths = sf.main([str(tmp_path / "a"), "road_end", "--seeds", "10:12"])
    assert [p.name for p in paths] == ["ZAM_RoadEnd-11_1_T-1.xml", "ZAM_RoadEnd-12_1_T-1.xml"]
    assert paths[0].read_bytes() == sf.write_scenario("road_end", 10, tmp_path / "b").read_bytes()
    for bad in (["road_end", "--seeds", "10"], ["no_such_family"]):
        with pytest.raises(SystemExit, match="seeds|unknown"):
            sf.main([str(tmp_path / "c"), *bad])
