"""CommonRoad scenarios: import a scenario file as a :class:`ScenarioSpec`, export the driven
trajectory as a CommonRoad solution, and check it with the CommonRoad drivability checker.

Optional extra ``commonroad`` (commonroad-io, commonroad-drivability-checker, triangle for the
solution checker, commonroad-vehicle-models); imported lazily.

Import:

* **Values.** Interval-valued state fields read as the interval's middle, uncertain positions
  (shapes) as their centre (:mod:`.commonroad_route`).
* **Route, path, speed.** :func:`~.commonroad_goal.plan_drive`: the route to the goal over the
  lanelet network (or along the lane for a goal without a position), its smoothed centre line up
  to the route's end, and a curvature-limited speed profile braking to 0 there whose top speed
  puts the car in the goal region inside the goal's time window.
* **Road.** The route's lanelets edge by edge along the centre line (the controller keeps the
  body inside them), the same-direction lanes beside them as neighbour lanes; where the route
  lane tapers narrower than any car, the lanes beside it join the road there (:func:`_road`);
  where the route's first / last lanelet is where the mapped road begins / ends, the road's
  ``start_m`` / ``end_m`` (:func:`_road_ends`): a body beyond them is off the road.
* **Obstacles.** Static and dynamic obstacles with rectangle / circle / polygon shapes; a dynamic
  obstacle's recorded trajectory is its known prediction (:class:`TrajectoryMotion`).
* **Vehicle.** ``kinematic4`` (speed state) with the CommonRoad Ford Escort preset's wheelbase,
  length and width, steering and steering-rate limits (:func:`with_vehicle` for another vehicle
  or a CommonRoad plant); ``dt`` = the scenario's time step; ``hard`` avoidance; fallback ladder
  ``[shifted_plan, brake]``.

The car's reference point (the state's x, y) is its centre of gravity, as in CommonRoad's KS
states (its checker moves them to the rear axle itself).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..models.kinematic import path_steering, rear_axle_heading, slip_terms
from ..models.presets import PRESETS
from ..scenarios.schema import ScenarioSpec
from ..sim.metrics import CommonRoadCheck, WholeDriveCheck
from .commonroad_file import read_file
from .commonroad_goal import (
    FRONT_REACH_M,
    ROAD_MARGIN_M,
    WIDEST_M,
    DrivePlan,
    accel_limit,
    friction_accel,
    goal_miss,
    goal_spec,
    line_path,
    path_spec,
    plan_drive,
    road_ends_m,
)
from .commonroad_route import drivable_lanelets, lane_strips, point, route_edges, route_ends, scalar
from .commonroad_solution import solution_accepted
from .commonroad_traffic import lane_trajectories

PRESET = "commonroad_ford_escort"
#: the lanes beside the route (each lane of the carriageway, the first oncoming lane) are the
#: road's other lanes: the maneuver planner changes into them (mpcdrive.planning)
NEIGHBOUR_LANES = True
#: the most lanes beside the route lane given to the planner (the nearest)
MAX_LANES_BESIDE = 10
#: a lane whose edges lie within this [m] of the route lane's wherever it is found is the route
#: lane itself (the lane the path runs in), not a lane beside it: the lanes' edges are found on a
#: 0.1 m search across lanelets widened by 2 cm to close their seams, the route's edge by edge
ROUTE_LANE_SAME_M = 0.3
#: how far [m] behind the car's start (its reference point) the road reaches at least: the
#: longest CommonRoad body's corner (half its length and width) and half a metre, so a car
#: placed at the mapped road's start is not "behind the road" for standing where it was put
START_CLEAR_M = math.hypot(FRONT_REACH_M, 0.5 * WIDEST_M) + 0.5
#: a route lane narrower than this [m] (the widest CommonRoad vehicle and the road margin on both
#: sides) takes in the same-direction lanes beside it (:func:`_road`)
TAPER_WIDTH_M = WIDEST_M + 2 * ROAD_MARGIN_M
#: above this speed [m/s] (the urban limit, 50 km/h) the controller's steering weights grow as
#: v^4 and hold its lateral bandwidth at that speed's (MpcConfig.steer_weight_speed_mps): the
#: weights are the ones of the urban drives; on CommonRoad's ST and MB a braking car at 30 m/s
#: oversteers (its yaw gain up to 2.6 times the kinematic model's) and weaved with the
#: constant weights, growing on MB until it left its goal (DEU_A9-2)
STEER_WEIGHT_SPEED_MPS = 50.0 / 3.6


def available() -> bool:
    """True when the ``commonroad`` extra (commonroad-io, drivability checker) is installed."""
    try:
        import commonroad  # noqa: F401
        import commonroad_dc  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True, eq=False)
class CommonRoadImport:
    """A CommonRoad file read and mapped: ``spec`` runs with
    :func:`~mpcdrive.scenarios.build_experiment` (on a CommonRoad plant, :func:`with_vehicle`'s
    ``plant``, given :func:`~.commonroad_vehicles.commonroad_plant` as its ``plant_factory``)."""

    file: Path
    scenario: object  # commonroad Scenario
    planning_problem: object  # commonroad PlanningProblem
    spec: ScenarioSpec
    route: tuple[int, ...]
    centerline: np.ndarray  # (M, 2) [m]
    plan: DrivePlan | None = None
    problems: object = None  # commonroad PlanningProblemSet
    vehicle_type: str = "FORD_ESCORT"  # CommonRoad VehicleType name of the solution and the checks
    #: the traffic (recorded | sumo) and what the controller knows of it (known | lane):
    #: :func:`~.commonroad_traffic.with_traffic`; ``sumo`` its SUMO settings
    traffic: str = "recorded"
    prediction: str = "known"
    sumo: object = None
    runtime: dict = field(default_factory=dict, compare=False)  # one run's SUMO plant and files

    def prepare_experiment(self, exp):
        """The built experiment with this import's traffic and prediction
        (:func:`~.commonroad_traffic.prepare`)."""
        from .commonroad_traffic import prepare

        return prepare(self, exp)

    def write_outputs(self, result, out_dir: Path) -> dict:
        """Write ``solution.xml`` (up to the goal, else the whole drive) and ``commonroad_scene.png``
        (commonroad-io's renderer), hand the lanelet polygons to the replay (``result.meta``), and
        return the ``commonroad`` metrics (:class:`~mpcdrive.sim.CommonRoadCheck`): route, plan,
        goal step, the drivability checker's verdicts up to the goal, whether CommonRoad's
        solution checker accepts the solution, and the verdicts of the whole drive (one check of
        every state: :func:`check_drives`). Among SUMO traffic the checks and the figure take the
        vehicles as SUMO drove them, and ``sumo.json`` is written
        (:func:`~.commonroad_traffic.sumo_report`)."""
        from .commonroad_figures import lanelet_polygons, write_scene_figure

        plant = self.runtime.get("plant")
        if plant is not None:
            from ..io import write_json
            from .commonroad_traffic import driven_scenario, sumo_report

            plant.close()
            self = replace(self, scenario=driven_scenario(self, plant), runtime={})
        report, whole = check_drives(self, result)
        if plant is not None:
            write_json(Path(out_dir) / "sumo.json", sumo_report(self, plant, result, whole))
        path = write_solution(self, result, Path(out_dir), report.goal_step)
        # CommonRoad's own solution checker has the last word up to the goal (its road boundary is
        # a triangulation closed at the road's ends, stricter than the checks above); after the
        # goal the drive goes on, and the whole of it is judged too
        valid, why = solution_accepted(self, path) if report.passed else (False, "not checked: the drive did not pass")
        passed = report.passed and valid and whole.passed_whole
        fig = write_scene_figure(self, result, Path(out_dir), report.goal_step)
        result.meta["lanelets"] = lanelet_polygons(self.scenario)
        plan = self.plan
        return {
            "commonroad": CommonRoadCheck(
                file=self.file.name,
                route_lanelets=tuple(self.route),
                plan=None if plan is None else plan.note,
                goal_reached=report.goal_step is not None,
                goal_step=report.goal_step,
                collision_free=report.collision_free,
                road_compliant=report.road_compliant,
                ks_feasible=report.feasible,
                states_checked=report.steps_checked,
                passed=passed,
                solution=path.name,
                vehicle_type=self.vehicle_type,
                vehicle_model=solution_model(self, result),
                solution_valid=valid,
                solution_check=why,
                whole_drive=whole.whole_drive_check(result),
                goal_miss=None if report.goal_step is not None else goal_miss(self, result),
            ),
            "figures": [fig.name],
        }


def _obstacle_entry(o, dt: float) -> dict:
    from commonroad.geometry.shape import Circle, Polygon, Rectangle

    st = o.initial_state
    shape = o.obstacle_shape
    entry: dict = {"name": f"{o.obstacle_type.value}-{o.obstacle_id}"}
    if isinstance(shape, Rectangle):
        entry.update(shape="rectangle", length_m=float(shape.length), width_m=float(shape.width))
    elif isinstance(shape, Circle):
        entry.update(shape="circle", radius_m=float(shape.radius))
    elif isinstance(shape, Polygon):
        entry.update(shape="polygon", points=[tuple(map(float, p)) for p in shape.vertices[:-1]])
    else:
        raise ValueError(f"obstacle {o.obstacle_id}: unsupported shape {type(shape).__name__}")
    yaw = scalar(getattr(st, "orientation", None)) or 0.0
    p = point(st.position)
    entry.update(position=(float(p[0]), float(p[1])), yaw_deg=math.degrees(yaw))
    pred = getattr(o, "prediction", None)
    if pred is not None and getattr(pred, "trajectory", None) is not None:
        states = _distinct_steps([st] + list(pred.trajectory.state_list))
        yaws = list(np.unwrap([scalar(getattr(s, "orientation", None)) or yaw for s in states]))
        t = [scalar(s.time_step) * dt for s in states]
        pts = [tuple(map(float, point(s.position))) for s in states]
        entry["trajectory"] = {"t_s": t, "points": pts, "yaw_deg": [math.degrees(y) for y in yaws]}
        entry["lifetime_s"] = (t[0], t[-1])
    return entry


def _road(net, route, line: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(s, left, right, neighbours) of the road along the centre line ``line``: the route's
    lanelets edge by edge (a lane that narrows is followed as it narrows; measured on into the
    lanelets past the route's ends, :func:`~.commonroad_route.route_ends`), and how far the
    same-direction lanes beside them reach beyond its edges (the neighbour rows).

    A lane narrower than :data:`TAPER_WIDTH_M` is one to leave (a merge lane tapering to
    nothing, a lane that ends): there the road is the route lane together with the lanes beside
    it going its way, which the car may use to get out of it, and has no neighbours beyond. Only
    where that too is no wider than the car is the road refused (the scenario's check)."""
    ends = route_ends(net, route)
    s, left, right = route_edges(net, drivable_lanelets(net, route, neighbours=False) | ends, line)
    _, band_l, band_r = route_edges(net, drivable_lanelets(net, [*route, *ends], neighbours=True), line)
    taper = left + right < TAPER_WIDTH_M
    left = np.where(taper, np.maximum(left, band_l), left)
    right = np.where(taper, np.maximum(right, band_r), right)
    neighbours = np.column_stack([s, np.maximum(band_l - left, 0.0), np.maximum(band_r - right, 0.0)])
    return s, left, right, neighbours


def _lane_rows(net, route, line: np.ndarray, left: np.ndarray, right: np.ndarray) -> list[dict]:
    """The ``road.lane_rows`` of the lanes along the centre line ``line``
    (:func:`~.commonroad_route.lane_strips`: each lane of the carriageway, and the first oncoming
    lane, where the lanelets are): rows ``[s, left, right]`` of offsets [m] from it; where a lane
    is absent (ended, not begun) it has no width, at the road's edge on its side (``left``,
    ``right``: the route lane's widths [m])."""
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(np.asarray(line, float), axis=0).T))]
    lanes = []
    strips = lane_strips(net, route, line)
    # the planner takes at most MAX_LANES_BESIDE lanes: the nearest to the route
    strips.sort(key=lambda st: float(np.nanmean(np.abs(0.5 * (st[0] + st[1])))))
    for k, (lf, rt, oncoming) in enumerate(strips[:MAX_LANES_BESIDE]):
        found = np.isfinite(lf)
        if found.sum() < 2:
            continue
        if (
            not oncoming
            and np.all(np.abs(lf[found] - left[found]) <= ROUTE_LANE_SAME_M)
            and np.all(np.abs(rt[found] + right[found]) <= ROUTE_LANE_SAME_M)
        ):
            continue  # the lane the path runs in, wherever it is: the route lane itself
        mid = 0.5 * (lf[found] + rt[found])
        edge = np.where(np.mean(mid) >= 0.0, left, -right)
        lf = np.where(found, lf, edge)
        rt = np.where(found, rt, edge)
        lanes.append(
            {
                "name": f"{'oncoming' if oncoming else 'lane'}-{k + 1}",
                "oncoming": bool(oncoming),
                "rows": [[float(a), float(b), float(c)] for a, b, c in zip(s, lf, np.minimum(rt, lf))],
            }
        )
    return lanes


def _road_ends(net, plan: DrivePlan) -> tuple[float | None, float | None]:
    """(start_m, end_m) [m] along the reference path the run follows (built as the scenario's
    path is) where the mapped road begins / ends around the route
    (:func:`~.commonroad_goal.road_ends_m`; None where the lanelet network goes on)."""
    path = line_path(plan.centerline)
    start_m, end_m = road_ends_m(net, plan.route, path)
    if start_m is not None:
        # the ground the car stands on at its start is road: a scenario may place the car with its
        # rear behind the mapped road's start (that is the file's doing, not the drive's)
        start_m = min(start_m, plan.start_m - START_CLEAR_M)
    return start_m, end_m


def _distinct_steps(states: list) -> list:
    """``states`` with one state per time step: of states sharing a time step the later one.

    A CommonRoad trajectory should begin one step after the obstacle's initial state, but some
    published files (e.g. scenarios written by the interactive-scenario simulation) begin it *at*
    the initial time step, repeating the initial state; a repeated step has no time between its
    two states, so it is read once (the recording's own state, the later one), not refused. A
    time step that goes backwards is left in: the schema refuses it."""
    out: list = []
    for s in states:
        if out and scalar(s.time_step) == scalar(out[-1].time_step):
            out[-1] = s
        else:
            out.append(s)
    return out


def load_commonroad(file: str | Path) -> CommonRoadImport:
    """Read a CommonRoad scenario file and map it (first planning problem); ValueError on a file
    we cannot read or map."""
    from commonroad.common.file_reader import CommonRoadFileReader

    file = Path(file)
    try:
        scenario, pps = read_file(CommonRoadFileReader, file)
    except Exception as e:  # the reader raises anything from lxml errors to KeyError
        raise ValueError(f"not a readable CommonRoad scenario ({type(e).__name__}: {e})".splitlines()[0]) from None
    if not pps.planning_problem_dict:
        raise ValueError("no planning problem")
    pp = next(iter(pps.planning_problem_dict.values()))
    net = scenario.lanelet_network
    dt = float(scenario.dt)
    init = pp.initial_state
    p0 = point(init.position)
    yaw0 = scalar(init.orientation)
    v0 = max(0.0, scalar(getattr(init, "velocity", None)) or 0.0)
    plan = plan_drive(net, pp, p0, yaw0, v0, dt)
    s_k, left_k, right_k, _ = _road(net, plan.route, plan.centerline)
    start_m, end_m = _road_ends(net, plan)
    pre = PRESETS[PRESET]
    v_max = max(plan.v_cruise_mps, v0) + 2.0
    a_lim = accel_limit(v_max)
    obstacles = [_obstacle_entry(o, dt) for o in scenario.obstacles]
    # a moving vehicle known by its initial state only (an interactive scenario's traffic) drives
    # on along its lane: left standing, a car entering a single-lane ring at 7 m/s blocked the
    # drive. Present from its start on, its last pose held past the drive; CommonRoad's checks
    # judge against the file as it is (such a car exists at its initial time only)
    driven = lane_trajectories(scenario, dt, plan.duration_s)
    for o, entry in zip(scenario.obstacles, obstacles):
        if o.obstacle_id in driven:
            entry["trajectory"] = driven[o.obstacle_id]
    spec = _validated(
        {
            # named after the file the user passed (a file's internal benchmark id can be another's)
            "id": re.sub(r"[^A-Za-z0-9_.-]", "_", file.name.removesuffix(".gz").removesuffix(".xml")) or "commonroad",
            "description": f"CommonRoad {scenario.scenario_id}: route {list(plan.route)}, {len(obstacles)} obstacles, "
            f"{plan.note}",
            "dt_s": dt,
            "duration_s": plan.duration_s,
            "vehicle": {
                "model": "kinematic4",
                "preset": PRESET,
                "speed_mps": max(plan.v_cruise_mps, 0.1),
                "footprint_discs": 3,
            },
            "path": path_spec(plan.centerline),
            "road": {
                "widths": [[float(a), float(b), float(c)] for a, b, c in zip(s_k, left_k, right_k)],
                "lane_rows": _lane_rows(net, plan.route, plan.centerline, left_k, right_k) if NEIGHBOUR_LANES else None,
                "margin_m": ROAD_MARGIN_M,
                # where the mapped road begins / ends along the path (None: it goes on)
                "start_m": start_m,
                "end_m": end_m,
            },
            "initial_state": {"x_m": float(p0[0]), "y_m": float(p0[1]), "yaw_deg": math.degrees(yaw0), "v_mps": v0},
            # the maneuver planner's goal, and its pass through the oncoming lane when no lane
            # going the car's way serves
            "goal": goal_spec(pp, plan.centerline, plan),
            "planner": {"oncoming": True},
            # the project's plant steers instantly here: the commands keep within the vehicle's
            # steering rate and CommonRoad's checker judges the drive (KS feasibility); the
            # vehicle's own servo is --plant ks|st|mb (with a 0.4 rad/s servo on this kinematic
            # plant the evasive lane change of ZAM_Tutorial_Urban-3_2 overshoots off the road)
            "plant": {"steering_actuator": "ideal"},
            "obstacles": obstacles,
            "avoidance": {
                "formulation": "hard",
                "margin_m": 0.3,
                "max_obstacles": 4,
                "influence_m": max(20.0, v_max * 30 * dt + 10.0),
            },
            "controller": {
                "horizon": 30,
                "Q": [1.0, 1.0, 2.0, 1.0],
                "R": [10.0, 0.1],
                "Rc": [100.0, 1.0],
                "steer_weight_speed_mps": STEER_WEIGHT_SPEED_MPS,
                "max_steer_deg": math.degrees(pre.max_steer_rad),
                "max_steer_rate_deg_s": math.degrees(pre.max_steer_rate_rad_s) * 0.95,
                "accel_limits_mps2": (-a_lim, a_lim),
                "speed_limits_mps": (0.0, v_max),
                "speed_profile": plan.speed_profile_spec(),
                "horizon_step_m": 0.5,
                # no relax rung: it drops the speed bound and the rate limits and makes leaving the
                # lane cheap, which in dense recorded traffic gave commands KS rejects and road departures
                "fallback": ["shifted_plan", "brake"],
                "brake_decel_mps2": plan.accel_mps2,
                "friction_accel_mps2": friction_accel(pre.accel_limit_mps2(0.0)),
            },
        },
        scenario,
        pp,
        plan.route,
        plan.centerline,
    )
    return CommonRoadImport(file, scenario, pp, spec, tuple(plan.route), plan.centerline, plan, pps)


def _validated(data: dict, scenario, pp, route, centerline: np.ndarray, build=None) -> ScenarioSpec:
    """``data`` as a :class:`ScenarioSpec` (or ``build()``'s spec, made from ``data``), or a
    ValueError of one line: the file's element that the first refusal is about, the schema's
    reason, and how many refusals more (never pydantic's dump of every error)."""
    from pydantic import ValidationError

    try:
        return build() if build is not None else ScenarioSpec.model_validate(data)
    except ValidationError as e:
        errors = e.errors()
        where = [_element(err["loc"], scenario, pp, route, centerline, data) for err in errors]
        msg = str(errors[0]["msg"]).removeprefix("Value error, ")
        line = f"{where[0]} ({'.'.join(map(str, errors[0]['loc'])) or 'scenario'}): {msg}"
        if len(errors) > 1:
            others = list(dict.fromkeys(w for w in where[1:] if w != where[0]))
            named = f": {', '.join(others[:3])}{', ...' if len(others) > 3 else ''}" if others else ""
            line += f" (and {len(errors) - 1} more{named})"
        raise ValueError(" ".join(line.split())) from None


def _element(loc, scenario, pp, route, centerline: np.ndarray, data) -> str:
    """The element of the CommonRoad file a schema field ``loc`` comes from: an obstacle (by its
    CommonRoad id), the route lanelet where the road is narrowest, or the planning problem."""
    loc = tuple(loc)
    if loc[:1] == ("obstacles",) and len(loc) > 1 and isinstance(loc[1], int) and loc[1] < len(scenario.obstacles):
        return f"obstacle {scenario.obstacles[loc[1]].obstacle_id}"
    if loc[:1] == ("road",):
        widths = (data.get("road") or {}).get("widths")
        if widths:
            s, wl, wr = (np.asarray(c, float) for c in zip(*widths))
            k = int(np.argmin(wl + wr))
            arc = np.r_[0.0, np.cumsum(np.hypot(*np.diff(centerline, axis=0).T))]
            p = centerline[int(np.argmin(np.abs(arc - s[k])))]
            holding = {int(i) for ids in scenario.lanelet_network.find_lanelet_by_position([p]) for i in ids}
            on = [int(i) for i in route if int(i) in holding] or [int(i) for i in route]
            return f"lanelet {on[0]}, {s[k]:.1f} m along the path"
        return f"the road along lanelets {list(map(int, route))}"
    return f"planning problem {pp.planning_problem_id}"


def goal_step(imp: CommonRoadImport, result) -> int | None:
    """First step index after the start whose state is in the goal region (position, time,
    orientation, velocity as the goal gives them), or None (a solution has at least two states)."""
    from commonroad.scenario.state import CustomState

    for k in range(min(1, len(result.t_s) - 1), len(result.t_s)):
        x = result.x[k]
        st = CustomState(
            position=np.array([x[0], x[1]]),
            orientation=float(x[2]),
            velocity=float(x[3]),
            time_step=int(round(result.t_s[k] / imp.spec.dt_s)),
        )
        if imp.planning_problem.goal.is_reached(st):
            return k
    return None


#: plants whose rear axle rolls the way the body points (no tyre slip): their yaw is the KS orientation
_NO_SLIP_PLANTS = ("kinematic3", "kinematic4", "commonroad_ks")


def solution_trajectory(imp: CommonRoadImport, result, last_step: int | None = None):
    """The driven trajectory as a CommonRoad KS trajectory from step 0 to ``last_step``
    (default: all).

    Positions are the centre of gravity (CommonRoad's KS states are given there; its model moves
    the rear axle, ``lr`` behind, the way the orientation points). The orientation is that rear
    axle's heading dragged along the driven positions
    (:func:`~mpcdrive.models.kinematic.rear_axle_heading`), on a kinematic plant its yaw (the same
    up to the chords' second-order error, which the yaw does not have); on a plant whose tyres
    slip (CommonRoad's ST and MB, the dynamic models) the yaw plus the rear axle's slip angle,
    which a kinematic model cannot hold otherwise (the collision and road checks of
    :func:`check_drives` turn the body by its own yaw). The velocity is the rear axle's,
    ``v cos(beta)`` with the slip angle ``beta = atan(lr / L tan(delta))``. The steering angle of
    state k on a kinematic plant is the mean of the commands held before and after it (KS steers
    with a bounded rate, our plant holds each command for a step: the ramp through the means
    covers the same mean steering per step); on a plant whose tyres slip, the steering with which
    a KS car turns its rear axle along the drive, ``atan(L dtheta / ds)`` over the steps around
    the state (:func:`~mpcdrive.models.kinematic.path_steering`; where the car stands, the
    commands' mean): the wheels of a car that slips turn less or more than that for the same
    path (MB oversteers while braking), and the feasibility check asks whether a KS car, within
    its steering rate, drives that path."""
    from commonroad.scenario.state import KSState
    from commonroad.scenario.trajectory import Trajectory

    v = imp.spec.vehicle
    lr, wheelbase = v.lr_m, v.lf_m + v.lr_m
    n = len(result.t_s) if last_step is None else last_step + 1
    steer = np.asarray(result.steer_rad, float)
    X = np.asarray(result.x, float)
    steering = 0.5 * (np.concatenate((steer[:1], steer[: n - 1])) + steer[:n])
    if imp.spec.plant_model in _NO_SLIP_PLANTS:
        heading = X[:n, 2]
    else:
        heading = rear_axle_heading(X[:n, :2], float(X[0, 2]), lr)
        if n >= 2:
            from_path = path_steering(X[:n, :2], heading, wheelbase)
            steering = np.where(np.isnan(from_path), steering, from_path)
    speed = X[:n, 3] * slip_terms(steer[:n], lr / wheelbase, np)[2]  # v cos(beta)
    states = [
        KSState(
            time_step=int(round(result.t_s[k] / imp.spec.dt_s)),
            position=np.array([X[k, 0], X[k, 1]], float),
            steering_angle=float(steering[k]),
            velocity=float(speed[k]),
            orientation=float(heading[k]),
        )
        for k in range(n)
    ]
    return Trajectory(states[0].time_step, states)


def solution_model(imp: CommonRoadImport, result) -> str:
    """``"ST"`` when the drive ran on CommonRoad's single-track plant and logged its states (the
    solution is then the plant's own ST trajectory), else ``"KS"``."""
    states = result.meta.get("plant_states")
    if imp.spec.plant.model == "commonroad_st" and states is not None and len(states) == len(result.t_s):
        return "ST"
    return "KS"


def st_solution_trajectory(imp: CommonRoadImport, result, last_step: int | None = None):
    """The drive on the ST plant as CommonRoad ST states, steps 0 to ``last_step``: the plant's own
    state (centre of gravity, steering angle, speed, yaw, yaw rate, slip angle)."""
    from commonroad.scenario.state import STState
    from commonroad.scenario.trajectory import Trajectory

    P = np.asarray(result.meta["plant_states"], float)
    n = len(result.t_s) if last_step is None else last_step + 1
    states = [
        STState(
            time_step=int(round(result.t_s[k] / imp.spec.dt_s)),
            position=np.array(P[k, :2]),
            steering_angle=float(P[k, 2]),
            velocity=float(P[k, 3]),
            orientation=float(P[k, 4]),
            yaw_rate=float(P[k, 5]),
            slip_angle=float(P[k, 6]),
        )
        for k in range(n)
    ]
    return Trajectory(states[0].time_step, states)


def write_solution(imp: CommonRoadImport, result, out_dir: Path, last_step: int | None = None) -> Path:
    """Write ``solution.xml`` into ``out_dir``: a CommonRoad solution with the run's vehicle type
    and the model it was driven on (ST for the single-track plant, else KS)."""
    from commonroad.common.solution import (
        CommonRoadSolutionWriter,
        CostFunction,
        PlanningProblemSolution,
        Solution,
        VehicleModel,
        VehicleType,
    )

    if solution_model(imp, result) == "ST":
        traj, model = st_solution_trajectory(imp, result, last_step), VehicleModel.ST
    else:
        traj, model = solution_trajectory(imp, result, last_step), VehicleModel.KS
    pps = PlanningProblemSolution(
        planning_problem_id=imp.planning_problem.planning_problem_id,
        vehicle_type=VehicleType[imp.vehicle_type],
        vehicle_model=model,
        cost_function=CostFunction.SM1,
        trajectory=traj,
    )
    sol = Solution(imp.scenario.scenario_id, [pps])
    CommonRoadSolutionWriter(sol).write_to_file(output_path=str(out_dir), filename="solution.xml", overwrite=True)
    return Path(out_dir) / "solution.xml"


@dataclass(frozen=True)
class CheckReport:
    """The drivability checker's verdicts on a driven trajectory's first ``steps_checked`` states;
    ``feasible`` under the vehicle model ``model`` (``KS``, or ``ST`` for a drive on the ST plant).
    ``collision_step``, ``off_road_step``, ``infeasible_step``: the first state that failed each
    check (None: none did). ``past_end_m``: how far [m] the body reached behind the mapped
    road's start or past its end (mpcdrive's measure, ``meta["road_end_excess_m"]``; None: not
    judged, or a road without ends), counted as off the road (``off_road_step``) only in a
    report of the whole drive (:meth:`with_road_ends`): up to the goal CommonRoad's own checks
    judge, and its solution checker closes the road's ends itself."""

    collision_free: bool
    road_compliant: bool
    feasible: bool
    goal_step: int | None
    steps_checked: int
    model: str = "KS"
    collision_step: int | None = None
    off_road_step: int | None = None
    infeasible_step: int | None = None
    past_end_m: float | None = None

    @property
    def passed(self) -> bool:
        """Collision-free, on the road, feasible and at the goal."""
        return self.collision_free and self.road_compliant and self.feasible and self.goal_step is not None

    @property
    def passed_whole(self) -> bool:
        """Collision-free, on the road and feasible over the states checked (the goal aside)."""
        return self.collision_free and self.road_compliant and self.feasible

    def line(self) -> str:
        goal = "not reached" if self.goal_step is None else f"reached at step {self.goal_step}"
        return (
            f"collision-free {self.collision_free}, road-compliant {self.road_compliant}, "
            f"{self.model}-feasible {self.feasible}, goal {goal}, {self.steps_checked} states"
        )

    def until(self, last: int) -> CheckReport:
        """This report cut to states 0 .. ``last``: a check fails there when its first failing
        state is among them (the checks judge each state, or each step from the state before,
        on its own: the verdicts on a drive's first states are those of the whole drive's)."""
        if last + 1 >= self.steps_checked:
            return self
        collision, off_road, infeasible = (
            k if k is not None and k <= last else None
            for k in (self.collision_step, self.off_road_step, self.infeasible_step)
        )
        return replace(
            self,
            collision_free=collision is None,
            road_compliant=off_road is None,
            feasible=infeasible is None,
            steps_checked=last + 1,
            collision_step=collision,
            off_road_step=off_road,
            infeasible_step=infeasible,
        )

    def with_road_ends(self, result) -> CheckReport:
        """This report with the body's reach past the mapped road's start or end (more than
        :data:`~mpcdrive.sim.LANE_TOLERANCE_M`) counted as off the road: the drivability checker's
        road boundary is open at the road's ends (a car driving off the end of the map is on no
        boundary), mpcdrive's road knows them (:attr:`~mpcdrive.scene.Road.end_m`)."""
        from ..sim import LANE_TOLERANCE_M

        past = result.meta.get("road_end_excess_m")
        if past is None:
            return self
        past = np.asarray(past, float)[: self.steps_checked]
        beyond = np.flatnonzero(past > LANE_TOLERANCE_M)
        off = self.off_road_step
        if beyond.size:
            off = int(beyond[0]) if off is None else min(off, int(beyond[0]))
        return replace(
            self,
            road_compliant=off is None,
            off_road_step=off,
            past_end_m=float(past.max()) if past.size else 0.0,
        )

    def whole_drive_check(self, result) -> WholeDriveCheck:
        """This report of the whole drive as ``metrics.json["commonroad"]["whole_drive"]``, the
        first failing states as times [s] of ``result``."""
        t = np.asarray(result.t_s, float)

        def at(k: int | None) -> float | None:
            return None if k is None else float(t[k])

        return WholeDriveCheck(
            collision_free=self.collision_free,
            road_compliant=self.road_compliant,
            feasible=self.feasible,
            states_checked=self.steps_checked,
            collision_t_s=at(self.collision_step),
            off_road_t_s=at(self.off_road_step),
            infeasible_t_s=at(self.infeasible_step),
            past_road_end_m=self.past_end_m,
            goal_t_s=at(self.goal_step),
        )


def check_drives(imp: CommonRoadImport, result) -> tuple[CheckReport, CheckReport]:
    """(up to the goal, whole drive): the drivability checker's verdicts on the drive up to the
    goal (else all of it; CommonRoad's verdict, as :func:`check_drive`) and on the whole drive,
    step 0 to the end of the run, the body's reach past the mapped road's ends counted as off
    the road (:meth:`CheckReport.with_road_ends`). Every state is checked once: the report up to
    the goal is the whole drive's cut there (:meth:`CheckReport.until`)."""
    whole = _check_states(imp, result)
    goal = whole if whole.goal_step is None else whole.until(whole.goal_step)
    return goal, whole.with_road_ends(result)


def check_drive(imp: CommonRoadImport, result, whole_drive: bool = False) -> CheckReport:
    """Check the driven trajectory (up to the goal, else all of it; all of it with
    ``whole_drive``, the body's reach past the mapped road's ends then counted as off the road)
    with the drivability checker: collisions with the scenario's obstacles, road boundary, and
    feasibility of the solution's trajectory under its model (KS; ST for a drive on the ST
    plant) with the run's vehicle (:func:`check_drives` gives both at the cost of one)."""
    goal, whole = check_drives(imp, result)
    return whole if whole_drive else goal


def _check_states(imp: CommonRoadImport, result) -> CheckReport:
    """The drivability checker on every state of the drive, with the first state that fails
    each check; ``goal_step`` the planning problem's (:func:`goal_step`)."""
    from commonroad.geometry.shape import Rectangle
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.state import CustomState
    from commonroad.scenario.trajectory import Trajectory
    from commonroad_dc.boundary.boundary import create_road_boundary_obstacle
    from commonroad_dc.collision.collision_detection.pycrcc_collision_dispatch import (
        create_collision_checker,
        create_collision_object,
    )
    from commonroad_dc.feasibility.feasibility_checker import trajectory_feasibility
    from commonroad_dc.feasibility.vehicle_dynamics import VehicleDynamics, VehicleType

    g = goal_step(imp, result)
    last = len(result.t_s) - 1
    v = imp.spec.vehicle
    centre_states = [
        CustomState(
            time_step=int(round(result.t_s[k] / imp.spec.dt_s)),
            position=np.array(result.x[k][:2], float),
            orientation=float(result.x[k][2]),
        )
        for k in range(last + 1)
    ]
    steps = [st.time_step for st in centre_states]
    ego_traj = Trajectory(centre_states[0].time_step, centre_states)
    ego = create_collision_object(TrajectoryPrediction(ego_traj, Rectangle(v.length_m, v.width_m)))
    cc = create_collision_checker(imp.scenario)
    collision = None
    if cc.collide(ego):  # which state: the obstacles as they are at its time step
        collision = _first(len(steps), lambda k: cc.time_slice(steps[k]).collide(ego.obstacle_at_time(steps[k])))
    _, road = create_road_boundary_obstacle(imp.scenario, method="obb_rectangles")
    off_road = _first(len(steps), lambda k: road.collide(ego.obstacle_at_time(steps[k]))) if road.collide(ego) else None
    vtype = VehicleType[imp.vehicle_type]
    model = solution_model(imp, result)
    if model == "ST":  # feasible under the model it was driven on
        traj, dyn = st_solution_trajectory(imp, result, last), VehicleDynamics.ST(vtype)
    else:
        traj, dyn = solution_trajectory(imp, result, last), VehicleDynamics.KS(vtype)
    feasible, inputs = trajectory_feasibility(traj, dyn, imp.spec.dt_s)
    # the inputs reconstructed up to and including the step that fails: its target state's index
    infeasible = None if feasible else len(inputs.state_list)
    return CheckReport(
        collision is None,
        off_road is None,
        bool(feasible),
        g,
        last + 1,
        "ST" if model == "ST" else "KS",
        collision,
        off_road,
        infeasible,
    )


def _first(n: int, failed) -> int:
    """The first k < n with ``failed(k)``: the checker found the drive failing, so one does (if
    none is found state by state, the first state: counted as failing from the start, which
    fails the verdict up to the goal as well, as the checker's own verdict does)."""
    return next((k for k in range(n) if failed(k)), 0)


def with_vehicle(imp: CommonRoadImport, vehicle: str | None = None, plant: str | None = None) -> CommonRoadImport:
    """``imp`` driven with the CommonRoad ``vehicle`` (``ford_escort``, ``bmw_320i``,
    ``vw_vanagon``: the controller's parameters and limits, the solution's vehicle type and the
    checks') and, with ``plant`` (``ks``, ``st``, ``mb``), that CommonRoad model as the plant
    (:func:`~.commonroad_vehicles.apply_vehicle`; built by
    :func:`~.commonroad_vehicles.commonroad_plant`, the ``plant_factory`` of
    :func:`~mpcdrive.scenarios.build_experiment`); unchanged when both are None. ValueError for an
    unknown name."""
    if vehicle is None and plant is None:
        return imp
    from .commonroad_vehicles import apply_vehicle, solution_vehicle_type

    vehicle = vehicle or "ford_escort"
    spec = _validated(
        imp.spec.model_dump(mode="python", exclude_unset=True),
        imp.scenario,
        imp.planning_problem,
        imp.route,
        imp.centerline,
        build=lambda: apply_vehicle(imp.spec, vehicle, plant),
    )
    return replace(imp, spec=spec, vehicle_type=solution_vehicle_type(vehicle).name)
