"""Drive highway-env's racetrack (``racetrack-v0`` / ``racetrack-v1``) and ``highway-v0`` with
mpcdrive's LTV-MPC, through :func:`mpcdrive.sim.simulate`'s closed loop.

Optional extra ``highway`` (``pip install mpcdrive[highway]``: highway-env, gymnasium). Nothing
here imports highway-env at module import; the functions take a created environment.

The environment is the loop's plant (:class:`~mpcdrive.adapters.highway_plant.HighwayEnvPlant`:
the ego's state, a command as one policy step's action, the other vehicles as its traffic, the
episode's end); :class:`HighwayEnvMpcDriver` is the controller:

* **Path and model.** The path is the centreline of the ego's lane
  (:func:`~mpcdrive.adapters.highway_plant.lane_centerline`), the model the plant's (the
  environment's kinematic vehicle), and the MPC's input bounds are exactly the action's ranges,
  so a command is never clipped by the environment.
* **Other vehicles.** At each step the loop hands the controller the plant's traffic (their
  current poses and predictions, on the loop's clock: :meth:`LtvMpc.set_obstacles`). The
  avoidance is ``hard`` with car following (``follow_gap_s``): the ego keeps to its lane (the
  lane bound keeps its body inside), passes cars in the next lane, and behind a car in its own
  lane -- or one cutting in, judged where the ego meets it -- it slows down and follows at a time
  gap instead of overtaking. Vehicles beyond the influence distance (20 m) are ignored, the
  nearest three considered.
* **Lanes (highway-v0).** With ``settings.planner`` (:func:`highway_settings`) the controller is
  :class:`~mpcdrive.planning.driver.PlannedMpc`: the maneuver planner chooses the lane, the offset
  and the speed on highway-v0's straight parallel lanes, and the MPC keeps the body inside the
  lanes the maneuver uses and follows it (docs/highway.md), as on every other road with lanes.
* **Solver.** The default :class:`~mpcdrive.control.mpc.LtvMpc` (compiled step, condensed
  solver), as everywhere; a one-line notice names the reason where it does not cover a problem.

:func:`drive_env` runs an episode (:func:`~mpcdrive.sim.simulate` with the plant, the road the
run is judged on and the vehicle's footprint) and adds what the environment reported. Example::

    import gymnasium as gym
    env = gym.make("racetrack-v1", config=racetrack_config(other_vehicles=10))
    env.reset(seed=0)
    drive = drive_env(env, HighwayEnvMpcDriver(env), steps=300)
    print(drive.result.e_y_m.max(), drive.on_road.all(), drive.crashed, drive.clearance_m.min())
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from ..planning import Maneuver, PlannerConfig
from ..planning.driver import PlannedMpc
from ..control.mpc import LtvMpc, MpcConfig
from ..ocp.avoidance import AvoidanceConfig
from ..ocp.problem import MpcProblem
from ..paths.straight import StraightPath
from ..scene.footprint import Footprint
from ..scene.road import Lane, Road
from ..scene.world import Scene
from ..sim.closed_loop import simulate
from ..types import ControlOutput, SimResult, WarmStart
from .highway_plant import (
    DEFAULT_ACCELERATION_RANGE_MPS2,
    DEFAULT_STEERING_RANGE_RAD,
    ActionScaling,
    HighwayEnvPlant,
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
    "HighwayEnvPlant",
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
        raise ValueError("the maneuver planner on highway-env needs straight lanes (highway-v0)")
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
    planner: PlannerConfig | None = None

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
        if self.planner is not None and not isinstance(self.planner, PlannerConfig):
            raise ValueError(f"planner must be a PlannerConfig or None, got {type(self.planner).__name__}")


def highway_settings(v_ref_mps: float = 30.0, **overrides) -> DriverSettings:
    """:class:`DriverSettings` for highway-v0: ``v_ref_mps`` [m/s] (highway-env's speed limit
    and top of its speed reward is 30 m/s), vehicles considered within 60 m (the nearest 4),
    and the maneuver planner (:mod:`mpcdrive.planning`) wanting that speed. highway-v0 has no
    route: every lane goes where the ego goes, so a second out of the lane the ego started in
    costs nothing (``off_route_s_per_s = 0``); a lane change still costs its ``lane_change_s``."""
    base = dict(
        v_ref_mps=v_ref_mps,
        speed_limits_mps=(0.0, v_ref_mps + 5.0),
        avoidance=AvoidanceConfig("hard", margin_m=0.3, influence_m=60.0, max_obstacles=4, follow_gap_s=1.0),
        planner=PlannerConfig(off_route_s_per_s=0.0),
    )
    return DriverSettings(**{**base, **overrides})


class HighwayEnvMpcDriver:
    """LTV-MPC driver of a created (and reset) highway-env environment's ego vehicle: a
    controller (``initial_warm``, ``step``, ``set_obstacles``) for :func:`~mpcdrive.sim.simulate`
    with :attr:`plant` (the environment as the plant, its traffic predicted per ``settings``).

    Built once per episode (after ``env.reset``): path from the ego's lane, model from the
    vehicle's length, QP from the action ranges. At each step the loop hands it the plant's
    traffic (:meth:`set_obstacles`; ``others``, their order fixed, an obstacle's index its
    identity); :meth:`step` passes them to the MPC and solves (with ``settings.planner`` the
    :class:`~mpcdrive.planning.driver.PlannedMpc` plans the maneuver first). Its outputs'
    path coordinates are those on :attr:`path` (the route lane's centreline). The controller's period
    is the policy period ``1 / policy_frequency``. With steering only (no longitudinal action)
    the ego cannot slow down behind a slower car in its lane: it keeps its lane and speed, and
    the avoidance can only hold it off sideways. :attr:`considered` counts, per step, the
    obstacles the MPC considered (within the influence distance, at most ``max_obstacles``).
    """

    def __init__(self, env, settings: DriverSettings = DriverSettings()):
        u = env.unwrapped
        vehicle = getattr(u, "vehicle", None)
        if vehicle is None:
            raise ValueError("the environment has no ego vehicle: call env.reset() first")
        self.env = env
        self.settings = settings
        self.lane_index = tuple(vehicle.lane_index)
        # highway-v0's straight parallel lanes: the maneuver planner picks the lane to drive in
        self.road: Road | None = None
        if settings.planner is not None:
            self.road, self.path, lane_paths = straight_road(u.road.network, self.lane_index)
            self.lane_half_width_m = 0.5 * float(u.road.network.get_lane(self.lane_index).width)
        else:
            self.path, self.lane_half_width_m = lane_centerline(
                u.road.network,
                self.lane_index,
                ds_m=settings.centerline_ds_m,
                smoothing_m=settings.centerline_smoothing_m,
            )
            lane_paths = dict.fromkeys(lane_sequence(u.road.network, self.lane_index)[0], self.path)
        #: the environment as the closed loop's plant
        self.plant = HighwayEnvPlant(
            env,
            horizon=int(settings.horizon),
            prediction=settings.prediction,
            tau_lateral_s=settings.tau_lateral_s,
            centerline_ds_m=settings.centerline_ds_m,
            centerline_smoothing_m=settings.centerline_smoothing_m,
            lane_paths=lane_paths,
        )
        p = self.plant
        # the plant's vehicle, action and traffic
        self.model, self.footprint, self.scaling, self.dt_s = p.model, p.footprint, p.scaling, p.dt_s
        self.others = p.others
        st_lo, st_hi = self.scaling.steering_range_rad
        rate = settings.max_steer_rate_rad_s if settings.max_steer_rate_rad_s is not None else np.inf
        s = settings
        if self.scaling.longitudinal:
            a_lo, a_hi = self.scaling.acceleration_range_mps2
            u_min, u_max, du = [st_lo, a_lo], [st_hi, a_hi], [rate, np.inf]
            x_min = [-np.inf] * 3 + [s.speed_limits_mps[0]]
            x_max = [np.inf] * 3 + [s.speed_limits_mps[1]]
            v_ref, nq, nr = s.v_ref_mps, 4, 2
        else:
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
                f"vehicle ({self.footprint.width_m} m wide) with a margin of {s.lane_margin_m} m"
            )
        # the projection window must cover the distance driven per step, and more
        window = max(2.0, 3.0 * max(v_ref, float(vehicle.speed)) * self.dt_s)
        nx, nu = self.model.nx, self.model.nu
        problem = MpcProblem(
            nx=nx,
            nu=nu,
            N=int(s.horizon),
            dt_s=self.dt_s,
            Q=np.array(s.Q[:nx]),
            R=np.array(s.R[:nu]),
            Rc=np.array(s.Rc[:nu]),
            u_min=np.array(u_min),
            u_max=np.array(u_max),
            du_max_per_s=np.array(du),
            x_min=x_min,
            x_max=x_max,
            # the body inside the lane around the path, or, with lanes, the route lane to start in
            road=self.lane_road if self.road is None else self.road.band((self.road.route_lane,)),
        )
        #: obstacles the MPC considered per step
        self.considered: list[int] = []
        self._obstacles = p.traffic(0.0)
        mpc = LtvMpc(
            self.model,
            self.path,
            problem,
            MpcConfig(v_ref_mps=v_ref, projection_window_m=window),
            obstacles=self._obstacles,
            avoidance=s.avoidance,
            footprint=self.footprint,
        )
        #: the MPC (compiled), with ``settings.planner`` wrapped in a PlannedMpc on highway-v0's road
        self.controller = mpc if self.road is None or s.planner is None else PlannedMpc(mpc, self.road, s.planner)

    # -- the controller interface (sim.simulate) -----------------------------------------------
    @property
    def nx(self) -> int:
        return self.model.nx

    @property
    def nu(self) -> int:
        return self.model.nu

    @property
    def N(self) -> int:
        return int(self.settings.horizon)

    @property
    def safety_road(self) -> Road:
        """The road a run is judged on along :attr:`path`: highway-v0's whole road (every lane)
        with the maneuver planner, else the lane around the path."""
        return self.road if self.road is not None else self.lane_road

    @property
    def scene(self) -> Scene:
        """The world a drive is judged in (:func:`~mpcdrive.sim.simulate` reads it): the
        :attr:`safety_road` and the ego's body; the other vehicles are the plant's traffic."""
        return Scene(self.safety_road, (), self.footprint)

    @property
    def maneuver(self) -> Maneuver | None:
        """The maneuver planner's last maneuver (None without ``settings.planner``)."""
        return getattr(self.controller, "maneuver", None) if self.road is not None else None

    def initial_warm(self, x0) -> WarmStart:
        return self.controller.initial_warm(x0)

    def set_obstacles(self, obstacles) -> None:
        """The other vehicles (the plant's traffic) for the next :meth:`step`, on its clock."""
        self._obstacles = tuple(obstacles)

    def step(self, x, warm: WarmStart) -> ControlOutput:
        """One control step from the measured state ``x`` with the last obstacles given (with
        ``settings.planner`` the maneuver first: :attr:`maneuver`)."""
        x = np.asarray(x, float)
        if self._obstacles:
            self.controller.set_obstacles(self._obstacles)
        out = self.controller.step(x, warm)
        avoidance = self.controller.avoidance
        self.considered.append(0 if avoidance is None else len(avoidance.relevant(warm.t_s, x[:2])))
        return out


@dataclass(frozen=True)
class HighwayDrive:
    """An episode driven by :class:`HighwayEnvMpcDriver` (:func:`drive_env`).

    result : :func:`~mpcdrive.sim.simulate`'s log (states as read from the environment, the
    controller's commands, the safety accounting: collisions with the other vehicles, the body's
    excess outside :attr:`HighwayEnvMpcDriver.safety_road`, failed solves, fallbacks); on_road :
    (K,) the environment's ``vehicle.on_road`` after each step; crashed : the vehicle crashed;
    terminated / truncated : how the episode ended (both False when ``steps`` ran out first);
    rewards : (K,) per-step rewards; footprint : the vehicle body; clearance_m : (K,) signed
    distance [m] between the body and the nearest other vehicle (or road object) at each logged
    state (inf without any); considered : (K,) number of obstacles the controller considered at
    each step (within the avoidance's influence distance, at most ``max_obstacles``).
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
    """Run up to ``steps`` policy steps (fewer if the episode ends) of ``driver`` on its plant
    (``env``) through :func:`~mpcdrive.sim.simulate`, judged on ``driver.scene`` (its
    ``safety_road``). One run
    per driver: the loop's clock and the warm start begin at 0 (after ``env.reset``, build a new
    driver)."""
    if isinstance(steps, bool) or int(steps) != steps or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps}")
    plant = driver.plant
    if plant.env is not env:
        raise ValueError("the driver was built for another environment")
    first, first_considered = len(plant.records), len(driver.considered)
    result = simulate(
        driver,
        plant,
        driver.path,
        plant.state(),
        driver.dt_s,
        int(steps),
        stop_at_path_end=False,
        meta={
            "id": "highway-env-racetrack" if driver.road is None else "highway-env-highway",
            "description": "highway-env driven by LTV-MPC",
            "max_steer_rad": float(driver.scaling.steering_range_rad[1]),
            "lane_index": list(driver.lane_index),
            "other_vehicles": len(driver.others),
        },
    )
    records = plant.records[first:]
    on_road = np.array([r.on_road for r in records], dtype=bool)
    result = replace(result, meta={**result.meta, "on_road_steps": int(on_road.sum())})
    last = records[-1] if records else None
    return HighwayDrive(
        result,
        on_road,
        bool(env.unwrapped.vehicle.crashed),
        last is not None and last.terminated,
        last is not None and last.truncated,
        np.array([r.reward for r in records]),
        driver.footprint,
        np.full(result.steps, np.inf) if result.clearance_m is None else result.clearance_m,
        np.array(driver.considered[first_considered:], dtype=int),
    )
