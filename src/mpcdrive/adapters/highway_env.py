"""Drive highway-env's racetrack (``racetrack-v0``) with mpcdrive's LTV-MPC.

Optional extra ``highway`` (``pip install mpcdrive[highway]``: highway-env, gymnasium). Nothing
here imports highway-env at module import; the functions take a created environment.

What the adapter does:

* **Road -> path.** The centreline of the lane the ego vehicle is on is sampled from the
  environment's road network (``lane.position(longitudinal, 0)`` of each ``StraightLane`` /
  ``CircularLane``), following the successor lanes with the same lane id until the track closes,
  and fitted with a (lightly smoothed) :class:`~mpcdrive.paths.WaypointPath`. The racetrack's
  lane pieces overlap or leave small gaps where they join (up to about 1 m); the end of a piece
  that lies past the start line of the next one is dropped before the fit.
* **Vehicle -> model.** highway-env's kinematic ``Vehicle`` is a bicycle with the reference
  point at the centre, ``lf = lr = LENGTH / 2``, steering ``delta`` and acceleration held over
  the policy period and integrated with Euler steps at the simulation frequency:
  :class:`~mpcdrive.models.KinematicBicycle4` with those lengths (or
  :class:`~mpcdrive.models.KinematicBicycle3` at the current speed when the action has no
  longitudinal part).
* **Units.** ``ContinuousAction`` maps each action component linearly from [-1, 1] to its
  range: steering to ``steering_range`` [rad], acceleration to ``acceleration_range``
  [m/s^2]; :class:`ActionScaling` converts our radians and m/s^2 into that normalized action
  (order ``[acceleration, steering]`` when both are controlled) and the MPC's input bounds are
  exactly those ranges, so a command is never clipped by the environment.
* **Other vehicles -> moving obstacles.** Every other vehicle (and solid road object) is a
  ``LENGTH`` x ``WIDTH`` rectangle at its position and heading; each policy step the driver hands
  the controller their current poses (:meth:`LtvMpc.set_obstacles`, on the controller's clock),
  predicted over the horizon at constant speed along the lane each one steers to
  (:func:`lane_following_obstacle`; its offset from that lane's centre decays, as highway-env's
  lane keeping makes it) -- a straight-line prediction (:func:`vehicle_obstacle`,
  ``prediction="constant_velocity"``) runs off the racetrack's 15-25 m bends within the horizon
  and makes phantom obstacles of cars in the next lane. The avoidance is ``hard`` with car
  following (``follow_gap_s``): the ego keeps to its lane (the lane bound keeps its body inside),
  passes cars in the next lane, and behind a car in its own lane -- or one cutting in, judged
  where the ego meets it -- it slows down and follows at a time gap instead of overtaking.
  Vehicles beyond the influence distance (20 m) are ignored, the nearest three considered.

Example::

    import gymnasium as gym
    env = gym.make("racetrack-v0", config=racetrack_config(other_vehicles=10))
    env.reset(seed=0)
    drive = drive_env(env, HighwayEnvMpcDriver(env), steps=300)
    print(drive.result.e_y_m.max(), drive.on_road.all(), drive.crashed, drive.clearance_m.min())
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from ..control.lanes import LaneConfig, LaneDecision, LateralRamp, decide_lane
from ..control.mpc import LtvMpc, MpcConfig
from ..models.kinematic import KinematicBicycle3, KinematicBicycle4, KinematicParams
from ..ocp.avoidance import AvoidanceConfig
from ..ocp.problem import MpcProblem
from ..paths.straight import StraightPath
from ..paths.waypoints import WaypointPath
from ..scene.footprint import Footprint
from ..scene.geometry import shape_distance
from ..scene.obstacles import Obstacle
from ..scene.road import Lane, Road
from ..sim.closed_loop import contact_count
from ..types import ControlOutput, SimResult
from .highway_plant import (
    DEFAULT_ACCELERATION_RANGE_MPS2,
    DEFAULT_STEERING_RANGE_RAD,
    ActionScaling,
    _vehicle_state,
    lane_centerline,
    lane_following_obstacle,
    lane_sequence,
    vehicle_obstacle,
)

__all__ = [
    "ActionScaling",
    "DriverSettings",
    "HighwayDrive",
    "HighwayEnvMpcDriver",
    "drive_env",
    "lane_centerline",
    "lane_following_obstacle",
    "lane_sequence",
    "racetrack_config",
    "vehicle_obstacle",
]


def racetrack_config(
    *,
    longitudinal: bool = True,
    steering_range_rad: tuple[float, float] = DEFAULT_STEERING_RANGE_RAD,
    acceleration_range_mps2: tuple[float, float] = DEFAULT_ACCELERATION_RANGE_MPS2,
    policy_frequency_hz: int = 5,
    simulation_frequency_hz: int = 15,
    duration_s: float = 300.0,
    other_vehicles: int = 1,
) -> dict:
    """Configuration for ``gym.make("racetrack-v0", config=...)``: continuous steering (and
    acceleration when ``longitudinal``) and a cheap kinematics observation (the driver reads the
    vehicle states itself).

    ``simulation_frequency_hz`` must be a multiple of ``policy_frequency_hz`` (the environment
    repeats the action ``simulation / policy`` times). ``other_vehicles``: racetrack-v0's own
    meaning -- 0 is an empty track; n >= 1 places one car ahead in the ego's lane (6-9 m/s) and
    up to n - 1 more at random places (highway-env drops those within 20 m of another car);
    highway-env's default is 1."""
    for name, rng in (("steering_range_rad", steering_range_rad), ("acceleration_range_mps2", acceleration_range_mps2)):
        lo, hi = (float(v) for v in rng)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"{name} must be two finite numbers, low < high, got {rng}")
    if int(policy_frequency_hz) != policy_frequency_hz or policy_frequency_hz < 1:
        raise ValueError(f"policy_frequency_hz must be a positive integer, got {policy_frequency_hz}")
    if int(simulation_frequency_hz) != simulation_frequency_hz or simulation_frequency_hz % policy_frequency_hz:
        raise ValueError(
            f"simulation_frequency_hz must be a multiple of policy_frequency_hz "
            f"({policy_frequency_hz}), got {simulation_frequency_hz}"
        )
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be positive, got {duration_s}")
    if isinstance(other_vehicles, bool) or int(other_vehicles) != other_vehicles or other_vehicles < 0:
        raise ValueError(f"other_vehicles must be an integer >= 0, got {other_vehicles}")
    return {
        "observation": {"type": "Kinematics"},
        "action": {
            "type": "ContinuousAction",
            "longitudinal": bool(longitudinal),
            "lateral": True,
            "steering_range": [float(v) for v in steering_range_rad],
            "acceleration_range": [float(v) for v in acceleration_range_mps2],
        },
        "other_vehicles": int(other_vehicles),
        "policy_frequency": int(policy_frequency_hz),
        "simulation_frequency": int(simulation_frequency_hz),
        "duration": float(duration_s),
    }


def highway_config(
    *, duration_s: float = 40.0, policy_frequency_hz: int = 5, simulation_frequency_hz: int = 15, **env_config
) -> dict:
    """Configuration for ``gym.make("highway-v0", config=...)``: the continuous steering and
    acceleration of :func:`racetrack_config`, highway-env's own traffic (4 lanes, 50 IDM/MOBIL
    vehicles, density 1) unless ``env_config`` says otherwise (e.g. ``vehicles_count``)."""
    cfg = racetrack_config(
        policy_frequency_hz=policy_frequency_hz, simulation_frequency_hz=simulation_frequency_hz, duration_s=duration_s
    )
    del cfg["other_vehicles"]  # racetrack-v0 only
    return {**cfg, **env_config}


# --------------------------------------------------------------------------- road -> path
def straight_road(network, lane_index) -> tuple[Road, StraightPath, dict]:
    """highway-v0's road: the lanes of the edge holding ``lane_index`` (straight and parallel,
    as ``RoadNetwork.straight_road_network`` makes them) as a :class:`~mpcdrive.scene.road.Road`
    along the centreline of ``lane_index`` (its route lane), that centreline as a path, and a
    path per lane index (for the other vehicles' predictions)."""
    fr, to, _ = lane_index
    lanes = network.graph[fr][to]
    route = network.get_lane(lane_index)
    if not all(type(ln).__name__ == "StraightLane" for ln in lanes):
        raise ValueError("the lane decision layer needs straight lanes (highway-v0)")
    path = StraightPath(route.start, route.end)
    out = []
    for j, ln in enumerate(lanes):
        d = np.asarray(ln.end, float) - np.asarray(ln.start, float)
        if abs(float(np.cross(d / np.hypot(*d), path.t))) > 1e-6:
            raise ValueError(f"lane {j} of edge {fr!r} -> {to!r} is not parallel to the route lane")
        c, w = float(path.n @ (np.asarray(ln.start, float) - path.start)), 0.5 * float(ln.width)
        out.append(Lane(str(j), np.full(2, c), np.full(2, c + w), np.full(2, c - w)))
    s = np.array([0.0, path.length_m])
    road = Road(
        s, max(ln.left_m[0] for ln in out), min(ln.right_m[0] for ln in out), 0.0, tuple(out), int(lane_index[2])
    )
    paths = {(fr, to, j): StraightPath(ln.start, ln.end) for j, ln in enumerate(lanes)}
    return road, path, paths


def ramp_path(path, ramp: LateralRamp, s_m: float, ds_m: float = 2.0) -> WaypointPath:
    """The controller's path: ``path`` shifted sideways by the decision layer's lateral
    reference ``ramp`` [m], from 20 m behind ``s_m`` [m] to 50 m past the ramp's end (beyond,
    the path goes on straight along its end tangent: the target lane's centre on highway-v0)."""
    s = np.arange(s_m - 20.0, max(ramp.s1_m, s_m) + 50.0, ds_m)
    h = np.asarray(path.heading(s), float)
    n = np.column_stack([-np.sin(h), np.cos(h)])
    return WaypointPath(np.asarray(path.position(s), float) + ramp.offset(s)[:, None] * n, ds_m=0.5)


def lane_problem(
    nx: int, nu: int, N: int, dt_s: float, Q, R, Rc, u_min, u_max, du_max_per_s, x_min, x_max, road: Road
) -> MpcProblem:
    """The driver's MPC problem (every one this module builds): weights, input / rate / state
    bounds, and the body kept inside the lane ``road`` around the path."""
    return MpcProblem(
        nx=nx,
        nu=nu,
        N=N,
        dt_s=dt_s,
        Q=np.array(Q),
        R=np.array(R),
        Rc=np.array(Rc),
        u_min=np.array(u_min),
        u_max=np.array(u_max),
        du_max_per_s=np.array(du_max_per_s),
        x_min=x_min,
        x_max=x_max,
        road=road,
    )


# --------------------------------------------------------------------------- driver
@dataclass(frozen=True)
class DriverSettings:
    """Tuning of the racetrack MPC (SI units, radians).

    horizon : N steps of the policy period; v_ref_mps : reference speed [m/s] (with
    longitudinal control; otherwise the vehicle keeps its speed); Q : state weights
    (x, y, yaw[, v]); R : input weights (steer[, accel]); Rc : input-change weights;
    max_steer_rate_rad_s : steering rate bound [rad/s] (None: unbounded);
    speed_limits_mps : (low, high) speed bounds [m/s]; lane_margin_m : distance kept between
    the vehicle's side and the lane edge by the soft lane bound [m];
    centerline_ds_m / centerline_smoothing_m : see :func:`lane_centerline`;
    avoidance : how other vehicles enter the MPC (an
    :class:`~mpcdrive.ocp.avoidance.AvoidanceConfig`; the default: hard half-planes with 0.3 m
    clearance, vehicles within 20 m, the nearest 3, car following at a 1 s time gap);
    prediction : ``lane`` (constant speed along the lane each vehicle steers to, its offset from
    the lane centre decaying with time constant ``tau_lateral_s`` [s]) or ``constant_velocity``
    (a straight line; it leaves the road in the bends).
    """

    horizon: int = 15
    v_ref_mps: float = 10.0
    Q: tuple[float, ...] = (1.0, 1.0, 2.0, 0.5)
    R: tuple[float, ...] = (1.0, 0.05)
    Rc: tuple[float, ...] = (20.0, 0.05)
    max_steer_rate_rad_s: float | None = 1.0
    speed_limits_mps: tuple[float, float] = (0.0, 20.0)
    lane_margin_m: float = 0.0
    centerline_ds_m: float = 1.0
    centerline_smoothing_m: float = 0.02
    avoidance: AvoidanceConfig = AvoidanceConfig(
        "hard", margin_m=0.3, influence_m=20.0, max_obstacles=3, follow_gap_s=1.0
    )
    prediction: Literal["lane", "constant_velocity"] = "lane"
    tau_lateral_s: float = 1.0
    lanes: LaneConfig | None = None

    def __post_init__(self):
        if int(self.horizon) != self.horizon or self.horizon < 1:
            raise ValueError(f"horizon must be a positive integer, got {self.horizon}")
        if not (math.isfinite(self.v_ref_mps) and self.v_ref_mps > 0):
            raise ValueError(f"v_ref_mps must be positive, got {self.v_ref_mps}")
        if self.max_steer_rate_rad_s is not None and not self.max_steer_rate_rad_s > 0:
            raise ValueError(f"max_steer_rate_rad_s must be positive, got {self.max_steer_rate_rad_s}")
        if not (math.isfinite(self.lane_margin_m) and self.lane_margin_m >= 0):
            raise ValueError(f"lane_margin_m must be >= 0, got {self.lane_margin_m}")
        if not isinstance(self.avoidance, AvoidanceConfig):
            raise ValueError(f"avoidance must be an AvoidanceConfig, got {type(self.avoidance).__name__}")
        if self.prediction not in ("lane", "constant_velocity"):
            raise ValueError(f"prediction must be 'lane' or 'constant_velocity', got {self.prediction!r}")
        if not self.tau_lateral_s > 0:
            raise ValueError(f"tau_lateral_s must be positive, got {self.tau_lateral_s}")
        if self.lanes is not None and not isinstance(self.lanes, LaneConfig):
            raise ValueError(f"lanes must be a LaneConfig or None, got {type(self.lanes).__name__}")


def highway_settings(v_ref_mps: float = 30.0, **overrides) -> DriverSettings:
    """:class:`DriverSettings` for highway-v0: ``v_ref_mps`` [m/s] (highway-env's speed limit
    and top of its speed reward is 30 m/s), vehicles considered within 60 m (the nearest 4),
    and the lane decision layer (:mod:`mpcdrive.control.lanes`) wanting that speed."""
    base = dict(
        v_ref_mps=v_ref_mps,
        speed_limits_mps=(0.0, v_ref_mps + 5.0),
        avoidance=AvoidanceConfig("hard", margin_m=0.3, influence_m=60.0, max_obstacles=4, follow_gap_s=1.0),
        lanes=LaneConfig(desired_speed_mps=v_ref_mps, standstill_m=6.0, rear_time_gap_s=0.6),
    )
    return DriverSettings(**{**base, **overrides})


class HighwayEnvMpcDriver:
    """LTV-MPC driver of a created (and reset) highway-env environment's ego vehicle.

    Built once per episode (after ``env.reset``): path from the ego's lane, model from the
    vehicle's length, QP from the action ranges, and the list of the other vehicles (and solid
    road objects: ``others``, their order fixed, an obstacle's index its identity). :meth:`act`
    reads the vehicle state (position [m], heading [rad], speed [m/s]) and the other vehicles'
    poses, hands those to the controller as obstacles and returns the normalized action and the
    controller's output. The controller's period is the policy period ``1 / policy_frequency``.
    With steering only (no longitudinal action) the ego cannot slow down behind a slower car in
    its lane: it keeps its lane and speed, and the avoidance can only hold it off sideways.
    """

    def __init__(self, env, settings: DriverSettings = DriverSettings()):
        u = env.unwrapped
        vehicle = getattr(u, "vehicle", None)
        if vehicle is None:
            raise ValueError("the environment has no ego vehicle: call env.reset() first")
        cfg = u.config
        if cfg["action"].get("dynamical", False):
            raise ValueError(
                "action.dynamical must be false: the driver models highway-env's "
                "kinematic Vehicle, not the dynamical BicycleVehicle"
            )
        # everything the ego can collide with, in a fixed order (index = obstacle identity)
        self.others = tuple(
            o
            for o in [*u.road.vehicles, *getattr(u.road, "objects", [])]
            if o is not vehicle and getattr(o, "collidable", True) and getattr(o, "solid", True)
        )
        self.env = env
        self.settings = settings
        self.scaling = ActionScaling.from_env(env)
        self.dt_s = 1.0 / float(cfg["policy_frequency"])
        self.lane_index = tuple(vehicle.lane_index)
        # highway-v0's straight parallel lanes: a decision layer picks the lane to drive in
        self.road: Road | None = None
        self.decision: LaneDecision | None = None
        self._lane_paths: dict = {}
        if settings.lanes is not None:
            self.road, self.path, self._lane_paths = straight_road(u.road.network, self.lane_index)
            self.lane_half_width_m = 0.5 * float(u.road.network.get_lane(self.lane_index).width)
        else:
            self.path, self.lane_half_width_m = lane_centerline(
                u.road.network,
                self.lane_index,
                ds_m=settings.centerline_ds_m,
                smoothing_m=settings.centerline_smoothing_m,
            )
            self._lane_paths = dict.fromkeys(lane_sequence(u.road.network, self.lane_index)[0], self.path)
        self._times_s = self.dt_s * np.arange(int(settings.horizon) + 1)
        length_m, width_m = float(vehicle.LENGTH), float(vehicle.WIDTH)
        self.footprint = Footprint(length_m, width_m)
        params = KinematicParams(0.5 * length_m, 0.5 * length_m)
        st_lo, st_hi = self.scaling.steering_range_rad
        rate = settings.max_steer_rate_rad_s if settings.max_steer_rate_rad_s is not None else np.inf
        s = settings
        if self.scaling.longitudinal:
            self.model = KinematicBicycle4(params)
            a_lo, a_hi = self.scaling.acceleration_range_mps2
            u_min, u_max, du = [st_lo, a_lo], [st_hi, a_hi], [rate, np.inf]
            x_min = [-np.inf] * 3 + [s.speed_limits_mps[0]]
            x_max = [np.inf] * 3 + [s.speed_limits_mps[1]]
            v_ref, nq, nr = s.v_ref_mps, 4, 2
        else:
            self.model = KinematicBicycle3(float(vehicle.speed), params)
            u_min, u_max, du = [st_lo], [st_hi], [rate]
            x_min = x_max = None
            v_ref, nq, nr = float(vehicle.speed), 3, 1
        if len(s.Q) < nq or len(s.R) < nr or len(s.Rc) < nr:
            raise ValueError(f"settings need Q with {nq} and R, Rc with {nr} entries")
        #: the lane around the path as the road the controller keeps the body inside (scene.road)
        self.lane_road = Road.constant(2.0 * self.lane_half_width_m, s.lane_margin_m)
        if self.lane_road.narrowest_fit_m(self.footprint) <= 0:
            raise ValueError(
                f"lane half width {self.lane_half_width_m} m leaves no room for the "
                f"vehicle ({width_m} m wide) with a margin of {s.lane_margin_m} m"
            )
        self._bounds = (u_min, u_max, du, x_min, x_max)
        # the projection window must cover the distance driven per step, and more
        window = max(2.0, 3.0 * max(v_ref, float(vehicle.speed)) * self.dt_s)
        self._mpc_config = MpcConfig(v_ref_mps=v_ref, projection_window_m=window)
        obstacles = self.obstacles(0.0)
        self.controller = self._controller(self.path, obstacles)
        self.warm = self.controller.initial_warm(self.state())
        if self.road is not None:
            self._follow_lanes(obstacles)

    def _controller(self, path, obstacles) -> LtvMpc:
        """The LTV-MPC along ``path`` (the body kept inside the lane around it) avoiding ``obstacles``."""
        s, (nx, nu) = self.settings, (self.model.nx, self.model.nu)
        u_min, u_max, du, x_min, x_max = self._bounds
        problem = lane_problem(
            nx,
            nu,
            int(s.horizon),
            self.dt_s,
            s.Q[:nx],
            s.R[:nu],
            s.Rc[:nu],
            u_min,
            u_max,
            du,
            x_min,
            x_max,
            self.lane_road,
        )
        return LtvMpc(
            self.model,
            path,
            problem,
            self._mpc_config,
            obstacles=obstacles,
            avoidance=s.avoidance,
            footprint=self.footprint,
        )

    def _follow_lanes(self, obstacles) -> None:
        """Ask the decision layer for the lane; on a new lateral reference, retarget the
        controller: a fresh one along the route lane's centreline shifted by the reference
        (:func:`ramp_path`), its warm start carried over (the plan is in world coordinates)."""
        assert self.road is not None and self.settings.lanes is not None
        x = self.state()
        s_m, e_y = self.path.project(x[:2])
        d = decide_lane(
            self.road,
            self.path,
            s_m,
            e_y,
            float(self.env.unwrapped.vehicle.speed),
            obstacles,
            self.warm.t_s,
            self.decision,
            self.settings.lanes,
        )
        if self.decision is None or d.ramp is not self.decision.ramp:
            ctrl = self._controller(ramp_path(self.path, d.ramp, s_m), obstacles)
            self.warm = replace(self.warm, s_m=ctrl.initial_warm(x).s_m, sides=())
            self.controller = ctrl
        self.decision = d

    def state(self) -> np.ndarray:
        """(nx,) ego state [x m, y m, yaw rad(, v m/s)] read from the environment."""
        return _vehicle_state(self.env.unwrapped.vehicle, self.model.nx)

    def lane_path(self, lane_index):
        """Centreline path of the lanes followed from ``lane_index`` (built once per sequence)."""
        lane_index = tuple(lane_index)
        if lane_index not in self._lane_paths:
            seq, _ = lane_sequence(self.env.unwrapped.road.network, lane_index)
            path, _ = lane_centerline(
                self.env.unwrapped.road.network,
                lane_index,
                ds_m=self.settings.centerline_ds_m,
                smoothing_m=self.settings.centerline_smoothing_m,
            )
            for ix in seq:
                self._lane_paths.setdefault(ix, path)
        return self._lane_paths[lane_index]

    def obstacles(self, t_s: float) -> tuple[Obstacle, ...]:
        """The other vehicles (and solid road objects) where they are now, as obstacles on the
        controller's clock at ``t_s`` [s]: moving along their lane (:func:`lane_following_obstacle`,
        towards the lane they steer to) or, with ``prediction="constant_velocity"`` and for
        objects off the lanes, in a straight line (:func:`vehicle_obstacle`)."""
        s = self.settings
        out = []
        for j, o in enumerate(self.others):
            name = f"{type(o).__name__}-{j}"
            lane = getattr(o, "target_lane_index", None) or getattr(o, "lane_index", None)
            if s.prediction == "lane" and lane is not None and float(getattr(o, "speed", 0.0)) != 0.0:
                out.append(
                    lane_following_obstacle(
                        o, self.lane_path(lane), self._times_s, t_s, tau_lateral_s=s.tau_lateral_s, name=name
                    )
                )
            else:
                out.append(vehicle_obstacle(o, t_s, name))
        return tuple(out)

    def act(self) -> tuple[np.ndarray, ControlOutput]:
        """One control step: (normalized action for ``env.step``, controller output); with
        ``settings.lanes``, the lane decision first (:attr:`decision`)."""
        if self.others:
            obstacles = self.obstacles(self.warm.t_s)
            if self.road is not None:
                self._follow_lanes(obstacles)
            self.controller.set_obstacles(obstacles)
        out = self.controller.step(self.state(), self.warm)
        self.warm = out.warm
        steer = float(out.u[0])
        accel = float(out.u[1]) if self.model.nu > 1 else 0.0
        return self.scaling.to_action(steer, accel), out


@dataclass(frozen=True)
class HighwayDrive:
    """An episode driven by :class:`HighwayEnvMpcDriver`.

    result : the log as a :class:`SimResult` (states as read from the environment, inputs as
    applied after the action's scaling); on_road : (K,) the environment's ``vehicle.on_road``
    after each step; crashed : the vehicle crashed; terminated / truncated : how the episode
    ended (both False when ``steps`` ran out first); rewards : (K,) per-step rewards;
    footprint : the vehicle body; clearance_m : (K,) signed distance [m] between the body and
    the nearest other vehicle (or road object) at each logged state (inf without any);
    considered : (K,) number of obstacles the controller considered at each step (within the
    avoidance's influence distance, at most ``max_obstacles``).
    """

    result: SimResult
    on_road: np.ndarray
    crashed: bool
    terminated: bool
    truncated: bool
    rewards: np.ndarray
    footprint: Footprint
    clearance_m: np.ndarray
    considered: np.ndarray


def drive_env(env, driver: HighwayEnvMpcDriver, steps: int) -> HighwayDrive:
    """Run up to ``steps`` policy steps (fewer if the episode ends) and log them."""
    if int(steps) != steps or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps}")
    u = env.unwrapped
    model, path = driver.model, driver.path
    N, nx = driver.controller.N, model.nx
    T, X, U, S, EY, EPSI, XP, RF, ST = [], [], [], [], [], [], [], [], []
    status, fallback, on_road, rewards, clearance, considered = [], [], [], [], [], []
    terminated = truncated = False
    for k in range(int(steps)):
        x = driver.state()
        t_s = driver.warm.t_s
        body = driver.footprint.polygon(*x[:3])
        clearance.append(
            min((shape_distance(body, vehicle_obstacle(o).at(0.0)) for o in driver.others), default=np.inf)
        )
        action, out = driver.act()
        avoidance = driver.controller.avoidance
        considered.append(0 if avoidance is None else len(avoidance.relevant(t_s, x[:2])))
        steer, accel = driver.scaling.from_action(action)
        T.append(k * driver.dt_s)
        X.append(x)
        U.append([steer, accel][: model.nu])
        S.append(out.s_m)
        EY.append(out.e_y_m)
        EPSI.append(out.e_psi_rad)
        XP.append(out.X_pred)
        RF.append(out.refs)
        ST.append(out.solve_time_s)
        status.append(out.status)
        fallback.append(out.fallback)
        _, reward, terminated, truncated, _ = env.step(action)
        rewards.append(float(reward))
        on_road.append(bool(u.vehicle.on_road))
        if terminated or truncated:
            break
    Xa = np.array(X)
    Ua = np.array(U, dtype=float).reshape(len(X), model.nu)
    clearance = np.array(clearance)
    meta = {}
    if driver.others:
        meta = {"min_obstacle_clearance_m": float(clearance.min()), "collisions": contact_count(clearance)}
    result = SimResult(
        t_s=np.array(T),
        x=Xa,
        u=Ua,
        x_final=driver.state(),
        s_m=np.array(S),
        e_y_m=np.array(EY),
        e_psi_rad=np.array(EPSI),
        yaw_rad=Xa[:, 2].copy(),
        v_mps=np.asarray(model.speed(Xa), dtype=float).copy() if nx == 4 else np.full(len(Xa), float(model.v_mps)),
        steer_rad=Ua[:, 0].copy(),
        accel_mps2=Ua[:, 1].copy() if model.nu > 1 else np.zeros(len(Xa)),
        X_pred=np.array(XP).reshape(len(X), N + 1, nx),
        refs=np.array(RF).reshape(len(X), N + 1, nx),
        status=tuple(status),
        fallback=tuple(fallback),
        solve_time_s=np.array(ST),
        path_xy=path.polyline(),
        dt_s=driver.dt_s,
        state_names=tuple(model.state_names),
        input_names=tuple(model.input_names),
        road_profile=driver.lane_road.profile(path.length_m),
        lane_excess_m=driver.lane_road.body_excess_m(
            np.array(S), np.array(EY), np.asarray(path.curvature(np.array(S))), np.array(EPSI), driver.footprint
        ),
        goal_reached=None,
        meta={
            "id": "highway-env-racetrack",
            "description": "highway-env racetrack driven by LTV-MPC",
            "max_steer_rad": float(driver.scaling.steering_range_rad[1]),
            "lane_index": list(driver.lane_index),
            "on_road_steps": int(sum(on_road)),
            "other_vehicles": len(driver.others),
            **meta,
        },
    )
    return HighwayDrive(
        result,
        np.array(on_road, dtype=bool),
        bool(u.vehicle.crashed),
        bool(terminated),
        bool(truncated),
        np.array(rewards),
        driver.footprint,
        clearance,
        np.array(considered, dtype=int),
    )
