"""CommonRoad scenarios: import a scenario file as a :class:`ScenarioSpec`, export the driven
trajectory as a CommonRoad solution, and check it with the CommonRoad drivability checker.

Optional extra ``commonroad`` (commonroad-io, commonroad-drivability-checker); imported lazily.

Import:

* **Route.** The lanelet holding the initial position (closest heading), then a breadth-first
  search over successor and same-direction adjacent lanelets to a goal lanelet (the goal's
  lanelets, else those holding the goal shape's centre). A time-only goal follows the straightest
  successors for the distance the car covers by the goal time. The route centreline is the
  lanelets' centre polylines joined, extended 30 m past its end straight ahead.
* **Road.** The lane bound is the narrowest route lanelet width (the controller keeps the body
  inside it).
* **Obstacles.** Static and dynamic obstacles with rectangle / circle / polygon shapes; a dynamic
  obstacle's recorded trajectory is its known prediction (:class:`TrajectoryMotion`).
* **Vehicle.** ``kinematic4`` (speed state) with the CommonRoad Ford Escort preset's wheelbase,
  length and width, steering and steering-rate limits; ``dt`` = the scenario's time step;
  reference speed = the goal velocity range's middle, else the initial speed; ``hard`` avoidance.

The car's reference point (the state's x, y) is its centre of gravity, as in CommonRoad's KS
states (its checker moves them to the rear axle itself).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..models.presets import PRESETS
from ..scenarios.schema import ScenarioSpec

PRESET = "commonroad_ford_escort"
_EXTEND_M = 30.0
_EXTRAPOLATE_S = 10.0  # recorded obstacle trajectories are extended this long at their last velocity
_V_SWITCH_MPS = 7.319  # CommonRoad Ford Escort: speed above which the acceleration limit falls as 1/v


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
    """A CommonRoad file read and mapped: ``spec`` runs with :func:`build_experiment`."""

    file: Path
    scenario: object  # commonroad Scenario
    planning_problem: object  # commonroad PlanningProblem
    spec: ScenarioSpec
    route: tuple[int, ...]
    centerline: np.ndarray  # (M, 2) [m]

    def write_outputs(self, result, out_dir: Path) -> dict:
        """Write ``solution.xml`` (up to the goal, else the whole drive) and return the
        ``commonroad`` metrics: route, goal step and the drivability checker's verdicts."""
        report = check_drive(self, result)
        path = write_solution(self, result, Path(out_dir), report.goal_step)
        return {"commonroad": {"file": self.file.name, "route_lanelets": list(self.route),
                               "goal_reached": report.goal_step is not None, "goal_step": report.goal_step,
                               "collision_free": report.collision_free, "road_compliant": report.road_compliant,
                               "ks_feasible": report.feasible, "states_checked": report.steps_checked,
                               "solution": path.name}}


def _angle_diff(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


def _lanelet_heading_at(lanelet, p: np.ndarray) -> float:
    cv = lanelet.center_vertices
    i = int(np.argmin(np.hypot(*(cv - p).T)))
    i = min(i, len(cv) - 2)
    d = cv[i + 1] - cv[i]
    return math.atan2(d[1], d[0])


def _neighbours(net, lid: int) -> list[int]:
    ll = net.find_lanelet_by_id(lid)
    out = list(ll.successor)
    if ll.adj_left is not None and ll.adj_left_same_direction:
        out.append(ll.adj_left)
    if ll.adj_right is not None and ll.adj_right_same_direction:
        out.append(ll.adj_right)
    return out


def _goal_lanelets(net, pp) -> set[int]:
    goal = pp.goal
    ids: set[int] = set()
    if goal.lanelets_of_goal_position:
        for v in goal.lanelets_of_goal_position.values():
            ids.update(v)
        return ids
    for st in goal.state_list:
        pos = getattr(st, "position", None)
        if pos is not None:
            for lst in net.find_lanelet_by_position([np.asarray(pos.center, float)]):
                ids.update(lst)
    return ids


def find_route(net, start: int, goals: set[int]) -> list[int] | None:
    """Shortest lanelet sequence (breadth-first over successors and same-direction neighbours)."""
    prev = {start: None}
    queue = deque([start])
    while queue:
        lid = queue.popleft()
        if lid in goals:
            route = [lid]
            while prev[route[-1]] is not None:
                route.append(prev[route[-1]])
            return route[::-1]
        for n in _neighbours(net, lid):
            if n not in prev:
                prev[n] = lid
                queue.append(n)
    return None


def _straightest_route(net, start: int, length_m: float) -> list[int]:
    route = [start]
    total = net.find_lanelet_by_id(start).distance[-1]
    while total < length_m:
        ll = net.find_lanelet_by_id(route[-1])
        succ = [s for s in ll.successor if s not in route]
        if not succ:
            break
        end_dir = ll.center_vertices[-1] - ll.center_vertices[-2]
        h = math.atan2(end_dir[1], end_dir[0])

        def turn(s, h=h):
            cv = net.find_lanelet_by_id(s).center_vertices
            d = cv[-1] - cv[0]
            return _angle_diff(math.atan2(d[1], d[0]), h)

        route.append(min(succ, key=turn))
        total += net.find_lanelet_by_id(route[-1]).distance[-1]
    return route


def route_centerline(net, route: list[int], start_xy: np.ndarray) -> np.ndarray:
    """Centre polyline (M, 2) [m] of a route, from the point nearest the start, extended straight."""
    pts: list[np.ndarray] = []
    for k, lid in enumerate(route):
        cv = np.asarray(net.find_lanelet_by_id(lid).center_vertices, float)
        if k > 0 and lid not in net.find_lanelet_by_id(route[k - 1]).successor:
            # lane change to a neighbour: continue on it from the point abreast of where we are
            j = int(np.argmin(np.hypot(*(cv - pts[-1][-1]).T)))
            cv = cv[min(j + 1, len(cv) - 1):]
        pts.append(cv)
    line = np.vstack(pts)
    # resample at about 1 m (lanelet polylines can have vertices tens of metres apart)
    seg = np.hypot(*np.diff(line, axis=0).T)
    keep = np.concatenate([[True], seg > 1e-6])
    line = line[keep]
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(line, axis=0).T))]
    s_new = np.linspace(0.0, s[-1], max(2, int(math.ceil(s[-1])) + 1))
    line = np.column_stack([np.interp(s_new, s, line[:, 0]), np.interp(s_new, s, line[:, 1])])
    j = int(np.argmin(np.hypot(*(line - start_xy).T)))
    line = line[max(j - 2, 0):]
    d = line[-1] - line[-2]
    d = d / np.hypot(*d)
    return np.vstack([line, line[-1] + _EXTEND_M * d])


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
    yaw = float(getattr(st, "orientation", 0.0) or 0.0)
    entry.update(position=(float(st.position[0]), float(st.position[1])), yaw_deg=math.degrees(yaw))
    pred = getattr(o, "prediction", None)
    if pred is not None and getattr(pred, "trajectory", None) is not None:
        states = [st] + list(pred.trajectory.state_list)
        yaws = list(np.unwrap([float(s.orientation) for s in states]))
        t = [s.time_step * dt for s in states]
        pts = [(float(s.position[0]), float(s.position[1])) for s in states]
        if len(states) >= 2:
            # past the end of the recording the obstacle keeps its last velocity (not a sudden stop)
            vx, vy = ((pts[-1][0] - pts[-2][0]) / (t[-1] - t[-2]), (pts[-1][1] - pts[-2][1]) / (t[-1] - t[-2]))
            t.append(t[-1] + _EXTRAPOLATE_S)
            pts.append((pts[-1][0] + vx * _EXTRAPOLATE_S, pts[-1][1] + vy * _EXTRAPOLATE_S))
            yaws.append(yaws[-1])
        entry["trajectory"] = {"t_s": t, "points": pts, "yaw_deg": [math.degrees(y) for y in yaws]}
    return entry


def _interval_mid(v) -> float | None:
    if v is None:
        return None
    if hasattr(v, "start"):
        return 0.5 * (float(v.start) + float(v.end))
    return float(v)


def _read_file(reader, file: Path):
    """(scenario, planning problems) of a ``.xml`` file, or of a gzip-compressed ``.xml.gz``."""
    if not file.name.endswith(".gz"):
        return reader(str(file)).open()
    import gzip
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        plain = Path(tmp) / file.name.removesuffix(".gz")
        plain.write_bytes(gzip.decompress(file.read_bytes()))
        return reader(str(plain)).open()


def load_commonroad(file: str | Path) -> CommonRoadImport:
    """Read a CommonRoad scenario file and map it (first planning problem); ValueError on a file
    we cannot read or map."""
    from commonroad.common.file_reader import CommonRoadFileReader

    file = Path(file)
    try:
        scenario, pps = _read_file(CommonRoadFileReader, file)
    except Exception as e:  # the reader raises anything from lxml errors to KeyError
        raise ValueError(f"not a readable CommonRoad scenario ({type(e).__name__}: {e})".splitlines()[0]) from None
    if not pps.planning_problem_dict:
        raise ValueError("no planning problem")
    pp = next(iter(pps.planning_problem_dict.values()))
    net = scenario.lanelet_network
    dt = float(scenario.dt)
    init = pp.initial_state
    p0 = np.asarray(init.position, float)
    yaw0 = float(init.orientation)
    v0 = float(init.velocity)
    cands = [lid for lst in net.find_lanelet_by_position([p0]) for lid in lst]
    if not cands:
        raise ValueError("initial position is on no lanelet")
    start = min(cands, key=lambda lid: _angle_diff(_lanelet_heading_at(net.find_lanelet_by_id(lid), p0), yaw0))
    goal_state = pp.goal.state_list[0]
    # simulate through the last goal time step (inclusive)
    t_end = (float(goal_state.time_step.end) + 1) * dt if hasattr(goal_state.time_step, "end") else 60.0
    goals = _goal_lanelets(net, pp)
    v_goal = _interval_mid(getattr(goal_state, "velocity", None))
    v_ref = v_goal if v_goal is not None else v0
    if goals:
        route = find_route(net, start, goals)
        if route is None:
            raise ValueError(f"no route from lanelet {start} to the goal lanelets {sorted(goals)}")
    else:
        route = _straightest_route(net, start, max(v_ref, 1.0) * t_end + 20.0)
    line = route_centerline(net, route, p0)
    widths = []
    for lid in route:
        ll = net.find_lanelet_by_id(lid)
        widths.append(float(np.min(np.hypot(*(ll.left_vertices - ll.right_vertices).T))))
    pre = PRESETS[PRESET]
    # CommonRoad's longitudinal limit: a_max, reduced to a_max v_switch / v above v_switch
    v_max = max(v_ref, v0) + 2.0
    a_lim = 0.9 * pre.max_accel_mps2 * min(1.0, _V_SWITCH_MPS / v_max)
    obstacles = [_obstacle_entry(o, dt) for o in scenario.obstacles]
    spec = ScenarioSpec.model_validate({
        "id": str(scenario.scenario_id),
        "description": f"CommonRoad {scenario.scenario_id}: route {route}, {len(obstacles)} obstacles",
        "dt_s": dt,
        "duration_s": t_end,
        "vehicle": {"model": "kinematic4", "preset": PRESET, "speed_mps": v_ref, "footprint_discs": 3},
        "path": {"type": "waypoints", "points": [tuple(map(float, p)) for p in line], "ds_m": 0.2},
        "road": {"lane_width_m": min(widths), "margin_m": 0.1},
        "initial_state": {"x_m": float(p0[0]), "y_m": float(p0[1]), "yaw_deg": math.degrees(yaw0), "v_mps": v0},
        "obstacles": obstacles,
        "avoidance": {"formulation": "hard", "margin_m": 0.3, "max_obstacles": 4,
                      "influence_m": max(20.0, max(v_ref, v0) * 30 * dt + 10.0)},
        "controller": {
            "horizon": 30,
            "Q": [1.0, 1.0, 2.0, 1.0],
            "R": [10.0, 0.1],
            "Rc": [100.0, 1.0],
            "max_steer_deg": math.degrees(pre.max_steer_rad),
            "max_steer_rate_deg_s": math.degrees(pre.max_steer_rate_rad_s) * 0.95,
            "accel_limits_mps2": (-a_lim, a_lim),
            "speed_limits_mps": (0.0, v_max),
            "reference_speed_mps": v_ref,
            "horizon_step_m": 0.5,
        },
    })
    return CommonRoadImport(file, scenario, pp, spec, tuple(route), line)


def goal_step(imp: CommonRoadImport, result) -> int | None:
    """First step index whose state is in the goal region (position, time, orientation,
    velocity as the goal gives them), or None."""
    from commonroad.scenario.state import CustomState

    for k in range(len(result.t_s)):
        x = result.x[k]
        st = CustomState(position=np.array([x[0], x[1]]), orientation=float(x[2]), velocity=float(x[3]),
                         time_step=int(round(result.t_s[k] / imp.spec.dt_s)))
        if imp.planning_problem.goal.is_reached(st):
            return k
    return None


def solution_trajectory(imp: CommonRoadImport, result, last_step: int | None = None):
    """The driven trajectory as a CommonRoad KS trajectory from step 0 to ``last_step``
    (default: all).

    Positions are the centre of gravity (CommonRoad's KS states are given there; its model moves
    the rear axle, ``lr`` behind), the velocity is the rear axle's, ``v cos(beta)`` with the slip
    angle ``beta = atan(lr / L tan(delta))``, and the steering angle of state k is the mean of the
    commands held before and after it (KS steers with a bounded rate, our plant holds each command
    for a step: the ramp through the means covers the same mean steering per step)."""
    from commonroad.scenario.state import KSState
    from commonroad.scenario.trajectory import Trajectory

    v = imp.spec.vehicle
    lr, wheelbase = v.lr_m, v.lf_m + v.lr_m
    n = len(result.t_s) if last_step is None else last_step + 1
    steer = np.asarray(result.steer_rad, float)
    states = []
    for k in range(n):
        x = result.x[k]
        before = steer[k - 1] if k > 0 else steer[0]
        beta = math.atan(lr / wheelbase * math.tan(steer[k]))
        states.append(KSState(time_step=int(round(result.t_s[k] / imp.spec.dt_s)),
                              position=np.array([x[0], x[1]], float),
                              steering_angle=float(0.5 * (before + steer[k])),
                              velocity=float(x[3] * math.cos(beta)), orientation=float(x[2])))
    return Trajectory(states[0].time_step, states)


def write_solution(imp: CommonRoadImport, result, out_dir: Path, last_step: int | None = None) -> Path:
    """Write ``solution.xml`` (CommonRoad solution: KS model, Ford Escort) into ``out_dir``."""
    from commonroad.common.solution import (CommonRoadSolutionWriter, CostFunction, PlanningProblemSolution,
                                            Solution, VehicleModel, VehicleType)

    traj = solution_trajectory(imp, result, last_step)
    pps = PlanningProblemSolution(planning_problem_id=imp.planning_problem.planning_problem_id,
                                  vehicle_type=VehicleType.FORD_ESCORT, vehicle_model=VehicleModel.KS,
                                  cost_function=CostFunction.SM1, trajectory=traj)
    sol = Solution(imp.scenario.scenario_id, [pps])
    CommonRoadSolutionWriter(sol).write_to_file(output_path=str(out_dir), filename="solution.xml", overwrite=True)
    return Path(out_dir) / "solution.xml"


@dataclass(frozen=True)
class CheckReport:
    """The drivability checker's verdicts on a driven trajectory."""

    collision_free: bool
    road_compliant: bool
    feasible: bool
    goal_step: int | None
    steps_checked: int

    def line(self) -> str:
        goal = "not reached" if self.goal_step is None else f"reached at step {self.goal_step}"
        return (f"collision-free {self.collision_free}, road-compliant {self.road_compliant}, "
                f"KS-feasible {self.feasible}, goal {goal}, {self.steps_checked} states")


def check_drive(imp: CommonRoadImport, result) -> CheckReport:
    """Check the driven trajectory (up to the goal, else all of it) with the drivability checker:
    collisions with the scenario's obstacles, road boundary, and KS feasibility (Ford Escort)."""
    from commonroad.geometry.shape import Rectangle
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.state import CustomState
    from commonroad.scenario.trajectory import Trajectory
    from commonroad_dc.boundary.boundary import create_road_boundary_obstacle
    from commonroad_dc.collision.collision_detection.pycrcc_collision_dispatch import (create_collision_checker,
                                                                                       create_collision_object)
    from commonroad_dc.feasibility.feasibility_checker import trajectory_feasibility
    from commonroad_dc.feasibility.vehicle_dynamics import VehicleDynamics, VehicleType

    g = goal_step(imp, result)
    last = g if g is not None else len(result.t_s) - 1
    v = imp.spec.vehicle
    centre_states = [CustomState(time_step=int(round(result.t_s[k] / imp.spec.dt_s)),
                                 position=np.array(result.x[k][:2], float), orientation=float(result.x[k][2]))
                     for k in range(last + 1)]
    ego_traj = Trajectory(centre_states[0].time_step, centre_states)
    ego = create_collision_object(TrajectoryPrediction(ego_traj, Rectangle(v.length_m, v.width_m)))
    cc = create_collision_checker(imp.scenario)
    collision_free = not cc.collide(ego)
    _, road = create_road_boundary_obstacle(imp.scenario, method="obb_rectangles")
    road_ok = not road.collide(ego)
    ks = solution_trajectory(imp, result, last)
    feasible, _ = trajectory_feasibility(ks, VehicleDynamics.KS(VehicleType.FORD_ESCORT), imp.spec.dt_s)
    return CheckReport(bool(collision_free), bool(road_ok), bool(feasible), g, last + 1)
