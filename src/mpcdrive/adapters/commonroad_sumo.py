"""CommonRoad scenarios among SUMO traffic: the scenario's vehicles driven by SUMO, reacting to
the ego, which mpcdrive's closed loop drives and pushes into SUMO every step at its real state.

Optional extra ``sumo`` (``pip install 'mpcdrive[sumo]'``: eclipse-sumo's simulator and tools,
libsumo, commonroad-sumo's map and route conversion); imported lazily.

* **Files.** commonroad-sumo converts the lanelet network into a SUMO net and the recorded
  vehicles into SUMO routes (:func:`build_sumo_files`, in a temporary folder, never kept): each
  recorded trajectory is matched to the net's edges within ``map_matching_m`` (12 m: at
  commonroad-sumo's 5 m, 16 of US-101's 35 vehicles find no route, among them the car behind
  the ego; at 12 m 30 do). The routes are then corrected: SUMO's ``departPos`` is the front
  bumper, not the centre the converter gives it (half a car length too far back), and each
  vehicle gets its recorded length and width (a vehicle type of its own). A vehicle without a
  route stays what it was, a recorded obstacle; so do the static obstacles, which SUMO does not
  simulate.
* **Tools.** netconvert and duarouter are found without ``SUMO_HOME``: it is set from the
  eclipse-sumo package when unset. SUMO runs in-process (libsumo), never as a GUI binary.
* **Co-simulation** (:class:`SumoSession`). SUMO's clock runs one step ahead of the loop's (the
  first step inserts the ego: SUMO time ``t + dt`` is the loop's ``t``). The ego is a SUMO
  vehicle with id :data:`EGO_ID` (no CommonRoad id, no generated id), on its own route (the
  reference path matched to the net lane by lane and direction, :func:`route_edges`), placed at its pose with ``moveToXY`` staying on that
  route (``keepRoute=1``: at a junction on the lane of its route, not the nearest junction lane,
  where a car behind would stop seeing it as its leader), its speed set with every check off
  (speed mode 0: SUMO's limits would have its drivers react to an ego that accelerates and
  brakes otherwise than it does). The recorded vehicles depart at their recorded times, lanes,
  positions and speeds, free to drive faster than they started (commonroad-sumo's own start
  pins each at its recorded start speed until released).
* **Timing.** SUMO's drivers plan a step from where the others were placed at the end of the
  step before; a pose pushed with ``moveToXY`` is taken at the end of the step it is pushed
  for. :meth:`SumoTrafficPlant.step` therefore pushes the ego's state after the loop's step and
  then steps SUMO: its drivers move from ``t`` to ``t + dt`` seeing the ego as it was at
  ``t``, as they see each other (pushing the state at ``t`` instead, as commonroad-sumo's
  interactive simulation does, has them see the ego one step late).
* **Duration.** The loop decides when the drive ends (commonroad-sumo's own loop stops as soon
  as the goal is met: after 3.3 s on a time-only goal); a co-simulated drive lasts at least
  :data:`DURATION_S`.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..scene.obstacles import ConstantVelocity, Obstacle, Static, rectangle

#: the ego's SUMO id: never a CommonRoad obstacle id (digits) nor an id SUMO generates
EGO_ID = "mpcdrive-ego"
#: distance within which a recorded trajectory is matched to the net's edges [m]
MAP_MATCHING_M = 12.0
#: a co-simulated drive lasts at least this long [s] (the traffic goes on past the goal)
DURATION_S = 20.0
#: SUMO speed mode with every check off: the speed set is the speed driven
SPEED_MODE_NO_CHECKS = 0
#: SUMO's moveToXY keeping the vehicle on its route; anywhere in the net
KEEP_ROUTE, ANYWHERE = 1, 2
INSTALL_HINT = "pip install 'mpcdrive[sumo]'"

_active: list[object] = []  # libsumo is one simulation per process: the session that holds it


def available() -> bool:
    """True when the ``sumo`` extra (eclipse-sumo, libsumo, commonroad-sumo) is installed."""
    try:
        _libsumo()
        import commonroad_sumo  # noqa: F401
    except ImportError:
        return False
    return True


def sumo_home() -> str:
    """``SUMO_HOME``, set from the eclipse-sumo package when unset (commonroad-sumo finds
    netconvert and duarouter on the ``PATH`` or there)."""
    if not os.environ.get("SUMO_HOME"):
        import sumo

        os.environ["SUMO_HOME"] = str(sumo.SUMO_HOME)
    return os.environ["SUMO_HOME"]


def _libsumo():
    """libsumo, imported without its start-up message on stdout (a pyarrow version note)."""
    sumo_home()
    with contextlib.redirect_stdout(io.StringIO()):
        import libsumo
    return libsumo


@dataclass(frozen=True)
class SumoSettings:
    """How SUMO simulates: ``map_matching_m`` [m] (see the module), ``seed`` (SUMO's random
    numbers: speed deviations, lane changes; fixed, so a drive repeats exactly),
    ``lateral_resolution_m`` [m] (the sublane model: lane changes move sideways gradually;
    None: SUMO's lane changes, one step each), ``duration_s`` [s] the shortest drive."""

    map_matching_m: float = MAP_MATCHING_M
    seed: int = 0
    lateral_resolution_m: float | None = 1.0
    duration_s: float = DURATION_S

    def __post_init__(self):
        if not (math.isfinite(self.map_matching_m) and self.map_matching_m > 0):
            raise ValueError(f"map_matching_m must be positive, got {self.map_matching_m}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {self.seed!r}")


@dataclass(frozen=True)
class SumoVehicle:
    """A recorded vehicle SUMO drives: CommonRoad ``id``, ``name`` (as the import names it),
    body ``length_m`` x ``width_m`` [m], scheduled departure ``depart_s`` [s] and its recorded
    start pose ``(x m, y m, yaw rad)``."""

    id: int
    name: str
    length_m: float
    width_m: float
    depart_s: float
    start_pose: tuple[float, float, float]


@dataclass(frozen=True)
class SumoFiles:
    """A scenario's SUMO project in ``folder``: ``config`` (the ``.sumo.cfg``), ``net``,
    ``routes``; the ``vehicles`` SUMO drives and the dynamic obstacles it could not route
    (``unrouted``: their ids, kept as recorded obstacles)."""

    folder: Path
    config: Path
    net: Path
    routes: Path
    vehicles: tuple[SumoVehicle, ...]
    unrouted: tuple[int, ...]


def _obstacle_name(o) -> str:
    return f"{o.obstacle_type.value}-{o.obstacle_id}"


def exact_states(scenario):
    """A copy of ``scenario`` whose obstacle states are exact: a position given as a shape (an
    uncertain position) becomes its centre, an interval its middle, as the import reads them
    (commonroad-sumo's route matching takes every position for a point)."""
    import copy

    from .commonroad_route import point, scalar

    sc = copy.deepcopy(scenario)
    for o in sc.dynamic_obstacles:
        states = [o.initial_state]
        if o.prediction is not None and getattr(o.prediction, "trajectory", None) is not None:
            states += list(o.prediction.trajectory.state_list)
        for st in states:
            st.position = point(st.position)
            for name in ("orientation", "velocity"):
                v = getattr(st, name, None)
                if v is not None:
                    setattr(st, name, scalar(v))
    return sc


def build_sumo_files(scenario, folder: Path, settings: SumoSettings = SumoSettings()) -> SumoFiles:
    """Convert ``scenario``'s lanelet network and recorded vehicles into a SUMO project in
    ``folder`` (see the module: map matching, routes corrected to the recorded starts and
    bodies; uncertain states read exactly, :func:`exact_states`); ValueError naming what
    failed."""
    sumo_home()
    _libsumo()
    from commonroad.geometry.shape import Rectangle
    from commonroad_sumo.cr2sumo import (
        CR2SumoMapConverter,
        ResimulationTrafficGeneratorConfig,
        UnsafeResimulationTrafficGenerator,
    )
    from commonroad_sumo.sumolib.sumo_project import SumoFileType

    folder = Path(folder)
    scenario = exact_states(scenario)
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            project = CR2SumoMapConverter(scenario).create_sumo_files(output_folder=folder)
    except Exception as e:  # the converter raises anything from KeyError to networkx errors
        raise ValueError(f"SUMO cannot convert the lanelet network ({type(e).__name__}: {e})".splitlines()[0]) from None
    if project is None:
        raise ValueError("SUMO cannot convert the lanelet network (netconvert failed)")
    config = ResimulationTrafficGeneratorConfig(
        map_matching_delta=settings.map_matching_m,
        extend_routes_downstream_junction=True,
        extend_routes_upstream_junction=True,
        extend_routes=True,
    )
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            UnsafeResimulationTrafficGenerator(config).generate_traffic(scenario, project)
    except Exception as e:
        raise ValueError(f"SUMO cannot route the recorded vehicles ({type(e).__name__}: {e})".splitlines()[0]) from None
    routes = Path(project.get_file_path(SumoFileType.VEHICLE_ROUTES))
    dt = float(scenario.dt)
    tree = ET.parse(routes)
    root = tree.getroot()
    net = Path(project.get_file_path(SumoFileType.NET))
    edge_length = _edge_lengths(net)
    vehicles = []
    for i, veh in enumerate(list(root.iter("vehicle"))):
        o = scenario.obstacle_by_id(int(veh.get("id")))
        if o is None or not isinstance(o.obstacle_shape, Rectangle):
            root.remove(veh)
            continue
        length, width = float(o.obstacle_shape.length), float(o.obstacle_shape.width)
        vtype = ET.Element(
            "vType",
            id=f"cr-{o.obstacle_id}",
            vClass=veh.get("type", "passenger"),
            length=f"{length:.4f}",
            width=f"{width:.4f}",
        )
        root.insert(i, vtype)
        veh.set("type", vtype.get("id"))
        # SUMO places a vehicle by its front bumper; the converter gave the centre
        route = veh.find("route")
        first = route.get("edges").split()[0] if route is not None else None
        pos = float(veh.get("departPos", "0")) + 0.5 * length
        if first in edge_length:
            pos = min(pos, edge_length[first] - 0.01)
        veh.set("departPos", f"{pos:.3f}")
        st = o.initial_state
        vehicles.append(
            SumoVehicle(
                int(o.obstacle_id),
                _obstacle_name(o),
                length,
                width,
                float(st.time_step) * dt,
                (float(st.position[0]), float(st.position[1]), float(st.orientation)),
            )
        )
    tree.write(routes)
    routed = {v.id for v in vehicles}
    unrouted = tuple(int(o.obstacle_id) for o in scenario.dynamic_obstacles if int(o.obstacle_id) not in routed)
    cfg = Path(project.get_file_path(SumoFileType.CONFIG))
    return SumoFiles(folder, cfg, net, routes, tuple(vehicles), unrouted)


def _edge_lengths(net: Path) -> dict[str, float]:
    """Length [m] of each edge's first lane in a SUMO net file."""
    out = {}
    for edge in ET.parse(net).getroot().iter("edge"):
        lane = edge.find("lane")
        if lane is not None and edge.get("function") != "internal":
            out[edge.get("id")] = float(lane.get("length"))
    return out


def route_edges(net: Path, points: np.ndarray, radius_m: float = MAP_MATCHING_M, step_m: float = 2.0) -> list[str]:
    """The SUMO edges along a line of ``points`` (M, 2) [m] in driving order (the ego's
    reference path), connected; empty when the line lies on no edge.

    Every ``step_m`` [m] along the line the nearest lane within ``radius_m`` [m] that runs the
    line's way (within 45 deg) gives the edge; consecutive edges that do not connect are joined
    by the net's shortest path. (commonroad-sumo's map matcher measures to an edge's middle line
    and ignores direction: on FRA_Anglet it starts the ego's route on the lane of the opposite
    direction, where SUMO's drivers behind it do not see it.)"""
    import sumolib
    from sumolib.geomhelper import polygonOffsetAndDistanceToPoint, rotationAtShapeOffset

    sn = sumolib.net.readNet(str(net), withInternal=False)
    pts = np.asarray(points, float)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    s = np.r_[0.0, np.cumsum(seg)]
    if s[-1] <= 0:
        return []
    at = np.arange(0.0, s[-1], step_m)
    xs, ys = np.interp(at, s, pts[:, 0]), np.interp(at, s, pts[:, 1])
    ahead = np.minimum(at + 1.0, s[-1])
    hs = np.arctan2(np.interp(ahead, s, pts[:, 1]) - ys, np.interp(ahead, s, pts[:, 0]) - xs)
    seq: list = []
    for x, y, h in zip(xs, ys, hs):
        best = None
        for edge, _ in sn.getNeighboringEdges(float(x), float(y), r=radius_m, includeJunctions=False):
            for lane in edge.getLanes():
                shape = lane.getShape()
                off, d = polygonOffsetAndDistanceToPoint((float(x), float(y)), shape)
                if d < 0:
                    continue
                rot = rotationAtShapeOffset(shape, off)
                if rot is None or abs((rot - h + math.pi) % (2.0 * math.pi) - math.pi) > math.radians(45.0):
                    continue
                if best is None or d < best[0]:
                    best = (d, edge)
        if best is not None and (not seq or seq[-1] is not best[1]):
            if best[1] in seq:  # back on an edge already passed: matching noise
                continue
            seq.append(best[1])
    route: list = []
    for e in seq:
        if route and e not in route[-1].getOutgoing():
            path, _ = sn.getShortestPath(route[-1], e)
            if path is None:
                # the net does not connect the path's edges (DEU_Salzwedel's left turn): no route
                # SUMO could hold the ego to; it is placed anywhere
                return []
            route += list(path[1:-1])
        route.append(e)
    if route:  # a start inside a junction: the route begins on the edge leading into it
        start = (float(xs[min(1, len(xs) - 1)]), float(ys[min(1, len(ys) - 1)]))

        def dist(edge) -> float:
            return min(polygonOffsetAndDistanceToPoint(start, ln.getShape())[1] % 1e9 for ln in edge.getLanes())

        into = [e for e in route[0].getIncoming() if e.getFunction() != "internal"]
        if into and dist(route[0]) > 2.0:
            before = min(into, key=dist)
            if dist(before) < dist(route[0]):
                route.insert(0, before)
        # the path may end in a junction or short of an edge SUMO needs: the route goes on one
        # edge, the one leaving the last one the path's way (SUMO holds a car at its route's end)
        out = [e for e in route[-1].getOutgoing() if e.getFunction() != "internal" and e not in route]
        if out:

            def turn(edge) -> float:
                rot = rotationAtShapeOffset(edge.getLanes()[0].getShape(), 0.0)
                return math.inf if rot is None else abs((rot - float(hs[-1]) + math.pi) % (2.0 * math.pi) - math.pi)

            route.append(min(out, key=turn))
    return [e.getID() for e in route]


@dataclass
class VehicleState:
    """A SUMO vehicle's state: centre ``x_m``, ``y_m`` [m], ``yaw_rad`` [rad], ``v_mps`` [m/s]."""

    x_m: float
    y_m: float
    yaw_rad: float
    v_mps: float


def _front(x: float, y: float, yaw: float, length: float) -> tuple[float, float]:
    return x + 0.5 * length * math.cos(yaw), y + 0.5 * length * math.sin(yaw)


class SumoSession:
    """One SUMO simulation (libsumo, in-process: one at a time per process) of ``files`` at the
    step ``dt_s`` [s]. :meth:`start` inserts the ego (remote-controlled, or with ``driver=True``
    a SUMO driver on its route) at its pose; :meth:`push_ego` places it for the next
    :meth:`step`; :meth:`states` reads the vehicles. ``step_times_s`` logs each step's wall
    time (SUMO's own work and the exchange with it)."""

    def __init__(self, files: SumoFiles, dt_s: float, settings: SumoSettings = SumoSettings()):
        self.files, self.dt_s, self.settings = files, float(dt_s), settings
        self.ego_route: list[str] = []
        self.step_times_s: list[float] = []
        #: steps at which the ego was too far from its route to be kept on it (placed anywhere)
        self.off_route_steps = 0
        self._ls = None
        self._ego_length = 0.0

    # -- life ----------------------------------------------------------------------------------
    def start(self, ego_pose, ego_speed_mps: float, ego_shape: tuple[float, float], route: list[str], *, driver=False):
        """Start SUMO and insert the ego at ``ego_pose`` (x m, y m, yaw rad; its centre) with
        ``ego_speed_mps`` [m/s], body ``ego_shape`` (length m, width m), on the edges
        ``route`` (empty: anywhere); its first step runs here (SUMO time ``dt``, the loop's 0)."""
        if _active:
            raise RuntimeError("a SUMO simulation is already running in this process (libsumo runs one at a time)")
        ls = _libsumo()
        cmd = [
            "sumo",
            "-c", str(self.files.config),
            "--step-length", f"{self.dt_s:.6g}",
            "--seed", str(self.settings.seed),
            "--no-step-log", "true",
            "--no-warnings", "true",
            "--collision.action", "none",
            "--time-to-teleport", "-1",
        ]  # fmt: skip
        if self.settings.lateral_resolution_m:
            cmd += ["--lateral-resolution", f"{self.settings.lateral_resolution_m:g}", "--lanechange.duration", "0"]
        ls.start(cmd)
        _active.append(self)
        self._ls = ls
        V = ls.vehicle
        length, width = ego_shape
        self._ego_length = float(length)
        ls.vehicletype.copy("DEFAULT_VEHTYPE", "mpcdrive-ego-type")
        ls.vehicletype.setLength("mpcdrive-ego-type", float(length))
        ls.vehicletype.setWidth("mpcdrive-ego-type", float(width))
        self.ego_route = list(route)
        if route:
            try:
                route = list(ls.simulation.findRoute(route[0], route[-1]).edges) or route
            except ls.TraCIException:
                pass
            self.ego_route = route
            ls.route.add("mpcdrive-ego-route", route)
        else:  # no route: a route of the edge nearest to the start, placed anywhere
            x, y, _ = ego_pose
            ls.route.add("mpcdrive-ego-route", [ls.simulation.convertRoad(float(x), float(y))[0]])
        V.add(EGO_ID, "mpcdrive-ego-route", typeID="mpcdrive-ego-type", departSpeed=f"{max(ego_speed_mps, 0.0):.4f}")
        self._place(ego_pose, ego_speed_mps)
        if driver:
            V.setSpeed(EGO_ID, max(ego_speed_mps, 0.0))  # the first step at its speed, then SUMO drives
        self.step()
        if driver:
            V.setSpeed(EGO_ID, -1.0)
        return self

    def close(self) -> None:
        if self._ls is not None:
            with contextlib.suppress(Exception):
                self._ls.close()
            self._ls = None
        if self in _active:
            _active.remove(self)

    # -- the ego -------------------------------------------------------------------------------
    def _place(self, pose, v_mps: float) -> None:
        V = self._ls.vehicle
        x, y, yaw = (float(c) for c in pose)
        fx, fy = _front(x, y, yaw, self._ego_length)
        angle = 90.0 - math.degrees(yaw)  # SUMO: degrees clockwise from north
        try:
            V.moveToXY(EGO_ID, "", -1, fx, fy, angle, keepRoute=KEEP_ROUTE if self.ego_route else ANYWHERE)
        except self._ls.TraCIException:  # farther than 100 m from its route: placed anywhere
            V.moveToXY(EGO_ID, "", -1, fx, fy, angle, keepRoute=ANYWHERE)
            self.off_route_steps += 1
        V.setSpeedMode(EGO_ID, SPEED_MODE_NO_CHECKS)
        V.setSpeed(EGO_ID, max(float(v_mps), 0.0))

    def push_ego(self, pose, v_mps: float) -> None:
        """Place the ego at ``pose`` (x m, y m, yaw rad; centre) with speed ``v_mps`` [m/s] at
        the end of the next :meth:`step`."""
        self._place(pose, v_mps)

    def ego_state(self) -> VehicleState | None:
        return self._state(EGO_ID, self._ego_length)

    def ego_lane(self) -> str:
        """The SUMO lane the ego is on now."""
        return self._ls.vehicle.getLaneID(EGO_ID)

    # -- stepping and reading ------------------------------------------------------------------
    def step(self) -> None:
        t0 = time.perf_counter()
        self._ls.simulationStep()
        self.step_times_s.append(time.perf_counter() - t0)

    @property
    def time_s(self) -> float:
        """The loop's time [s] of SUMO's current state (SUMO's clock less one step)."""
        return float(self._ls.simulation.getTime()) - self.dt_s

    def present(self) -> set[str]:
        return set(self._ls.vehicle.getIDList())

    def _state(self, vid: str, length: float) -> VehicleState | None:
        V = self._ls.vehicle
        try:
            fx, fy = V.getPosition(vid)
            yaw = math.radians(90.0 - V.getAngle(vid))
            v = V.getSpeed(vid)
        except self._ls.TraCIException:
            return None
        yaw = (yaw + math.pi) % (2.0 * math.pi) - math.pi
        return VehicleState(fx - 0.5 * length * math.cos(yaw), fy - 0.5 * length * math.sin(yaw), yaw, v)

    def states(self) -> dict[int, VehicleState]:
        """The recorded vehicles in the simulation now, by CommonRoad id (centre poses)."""
        here = self.present()
        out = {}
        for veh in self.files.vehicles:
            if str(veh.id) in here:
                s = self._state(str(veh.id), veh.length_m)
                if s is not None:
                    out[veh.id] = s
        return out


@dataclass
class TrafficLog:
    """What the SUMO vehicles did: per vehicle its states by loop step (``{id: {k: state}}``)."""

    dt_s: float
    states: dict[int, dict[int, VehicleState]] = field(default_factory=dict)

    def record(self, k: int, states: dict[int, VehicleState]) -> None:
        for vid, s in states.items():
            self.states.setdefault(vid, {})[k] = s


class SumoTrafficPlant:
    """The ego's plant (``inner``: a :class:`~mpcdrive.sim.Plant` or an ``ObservedPlant`` such
    as a CommonRoad vehicle model) among SUMO traffic: an ``ObservedPlant`` and ``TrafficPlant``
    of :func:`mpcdrive.sim.simulate`.

    The loop moves the ego (``inner``); each :meth:`step` pushes the ego's new state into SUMO
    and steps SUMO (see the module for the timing), and :meth:`traffic` gives the recorded
    vehicles as SUMO has them: rectangles of their bodies at their poses, moving straight on at
    their velocity (the controller predicts them itself), present from when they enter SUMO
    until they leave it. ``ego_shape`` (length m, width m) is the ego's body, ``centerline``
    (M, 2) [m] its reference path (matched to its SUMO route). :meth:`close` ends SUMO (the
    run's caller does, once the loop is over)."""

    def __init__(self, inner, files: SumoFiles, *, dt_s: float, ego_shape, centerline, settings=SumoSettings()):
        from ..sim.closed_loop import Plant

        self.inner = inner
        self._plain = isinstance(inner, Plant)
        if self._plain and inner.actuator is not None:
            raise ValueError("a steering actuator on the ego's plant is not supported among SUMO traffic")
        self.model = inner.model
        self.files = files
        self.dt_s = float(dt_s)
        self.ego_shape = (float(ego_shape[0]), float(ego_shape[1]))
        self.settings = settings
        self.session = SumoSession(files, dt_s, settings)
        self.route = route_edges(files.net, centerline, settings.map_matching_m)
        self.log = TrafficLog(self.dt_s)
        #: wall time [s] of each step's exchange with SUMO: the ego pushed, SUMO's step, the
        #: vehicles read
        self.cosim_times_s: list[float] = []
        self._k = 0
        self._now: dict[int, VehicleState] = {}
        self._seen: dict[int, tuple[float, float]] = {}  # id -> (first, last) time present [s]
        self._last: dict[int, VehicleState] = {}

    # -- ObservedPlant -------------------------------------------------------------------------
    def initial_state(self, x0) -> np.ndarray:
        xp = np.asarray(x0, float) if self._plain else np.asarray(self.inner.initial_state(x0), float)
        x = self.observe(xp)
        self.session.start((x[0], x[1], x[2]), float(self.model.speed(x)), self.ego_shape, self.route)
        self._read(0)
        return xp

    def observe(self, xp) -> np.ndarray:
        return np.asarray(xp, float) if self._plain else np.asarray(self.inner.observe(xp), float)

    def step(self, xp, u, dt_s: float) -> np.ndarray:
        if not math.isclose(dt_s, self.dt_s, rel_tol=1e-9):
            raise ValueError(f"dt_s must be SUMO's step {self.dt_s:g} s, got {dt_s!r}")
        xp1 = np.asarray(self.inner.step(xp, u, dt_s), float)
        if not np.all(np.isfinite(xp1)):
            return xp1
        x1 = self.observe(xp1)
        t0 = time.perf_counter()
        self.session.push_ego((x1[0], x1[1], x1[2]), float(self.model.speed(x1)))
        self.session.step()
        self._k += 1
        self._read(self._k)
        self.cosim_times_s.append(time.perf_counter() - t0)
        return xp1

    def close(self) -> None:
        self.session.close()

    # -- TrafficPlant --------------------------------------------------------------------------
    def _read(self, k: int) -> None:
        t = k * self.dt_s
        self._now = self.session.states()
        self.log.record(k, self._now)
        for vid, s in self._now.items():
            first, _ = self._seen.get(vid, (t, t))
            self._seen[vid] = (first, t)
            self._last[vid] = s

    def traffic(self, t_s: float) -> tuple[Obstacle, ...]:
        """The recorded vehicles at the loop's time ``t_s`` [s] (which must be the plant's), in
        the order of ``files.vehicles``."""
        t = self._k * self.dt_s
        if not math.isclose(t_s, t, rel_tol=1e-9, abs_tol=1e-9):
            raise ValueError(f"the SUMO traffic is at t = {t:g} s, asked for {t_s:g} s")
        out = []
        for veh in self.files.vehicles:
            shape = rectangle(veh.length_m, veh.width_m)
            s = self._now.get(veh.id)
            if s is not None:
                vx, vy = s.v_mps * math.cos(s.yaw_rad), s.v_mps * math.sin(s.yaw_rad)
                pose = (s.x_m - vx * t, s.y_m - vy * t, s.yaw_rad)
                first = self._seen[veh.id][0]
                out.append(Obstacle(shape, pose, ConstantVelocity(vx, vy), veh.name, first, math.inf))
            elif veh.id in self._seen:  # it has left SUMO (arrived at its route's end)
                last = self._last[veh.id]
                first, gone = self._seen[veh.id]
                out.append(Obstacle(shape, (last.x_m, last.y_m, last.yaw_rad), Static(), veh.name, first, gone))
            else:  # not yet departed
                start = max(veh.depart_s, t + self.dt_s)
                out.append(Obstacle(shape, veh.start_pose, Static(), veh.name, start, math.inf))
        return tuple(out)

    def sumo_step_ms(self) -> dict:
        """``{p50, p99, max, steps}`` of SUMO's step times [ms] over the drive (wall time; the
        first step inserts the ego)."""
        return _ms(self.session.step_times_s)

    def cosim_step_ms(self) -> dict:
        """``{p50, p99, max, steps}`` [ms] of what SUMO adds to each loop step (wall time): the
        ego pushed, SUMO's step, the vehicles read."""
        return _ms(self.cosim_times_s)


def _ms(times_s) -> dict:
    """``{p50, p99, max, steps}`` [ms] of wall times [s]."""
    st = np.asarray(times_s, float) * 1e3
    if not st.size:
        return {"p50": None, "p99": None, "max": None, "steps": 0}
    return {
        "p50": float(np.percentile(st, 50)),
        "p99": float(np.percentile(st, 99)),
        "max": float(st.max()),
        "steps": int(st.size),
    }


def tempdir() -> tempfile.TemporaryDirectory:
    """A temporary folder for a scenario's SUMO files (removed when the object is cleaned up)."""
    return tempfile.TemporaryDirectory(prefix="mpcdrive-sumo-")
