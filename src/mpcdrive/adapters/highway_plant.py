"""highway-env as the plant of mpcdrive's closed loop (:func:`mpcdrive.sim.simulate`).

Optional extra ``highway`` (``pip install mpcdrive[highway]``: highway-env, gymnasium). Nothing
here imports highway-env at module import; the functions take a created environment.

:class:`HighwayEnvPlant` is a created and reset environment seen by the loop as a plant: the
ego's state is read from the environment, a command is its action for one policy step, the
other vehicles are the plant's traffic (obstacles with their predictions, every step) and the
environment's termination ends the run. What it maps:

* **Road -> path.** The centreline of a lane is sampled from the environment's road network
  (``lane.position(longitudinal, 0)`` of each ``StraightLane`` / ``CircularLane``), following
  the successor lanes with the same lane id until the track closes, and fitted with a (lightly
  smoothed) :class:`~mpcdrive.paths.WaypointPath` (:func:`lane_centerline`). The racetrack's
  lane pieces overlap or leave small gaps where they join (up to about 1 m); the end of a piece
  that lies past the start line of the next one is dropped before the fit. A straight lane
  without successors (highway-v0's) is its own centreline, a
  :class:`~mpcdrive.paths.StraightPath`.
* **Vehicle -> model.** highway-env's kinematic ``Vehicle`` is a bicycle with the reference
  point at the centre, ``lf = lr = LENGTH / 2``, steering ``delta`` and acceleration held over
  the policy period and integrated with Euler steps at the simulation frequency:
  :class:`~mpcdrive.models.KinematicBicycle4` with those lengths (or
  :class:`~mpcdrive.models.KinematicBicycle3` at the current speed when the action has no
  longitudinal part).
* **Units.** ``ContinuousAction`` maps each action component linearly from [-1, 1] to its
  range: steering to ``steering_range`` [rad], acceleration to ``acceleration_range``
  [m/s^2]; :class:`ActionScaling` converts our radians and m/s^2 into that normalized action
  (order ``[acceleration, steering]`` when both are controlled).
* **Other vehicles -> moving obstacles.** Every other vehicle (and solid road object) is a
  ``LENGTH`` x ``WIDTH`` rectangle at its position and heading, predicted over the horizon at
  constant speed along the lane each one steers to (:func:`lane_following_obstacle`; its offset
  from that lane's centre decays, as highway-env's lane keeping makes it) or in a straight line
  (:func:`vehicle_obstacle`, ``prediction="constant_velocity"``; it runs off the racetrack's
  15-25 m bends within the horizon and makes phantom obstacles of cars in the next lane).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..models.kinematic import KinematicBicycle3, KinematicBicycle4, KinematicParams
from ..paths.base import ReferencePath
from ..paths.straight import StraightPath
from ..paths.waypoints import WaypointPath
from ..scene.footprint import Footprint
from ..scene.obstacles import ConstantVelocity, Obstacle, TrajectoryMotion, rectangle
from ..sim.closed_loop import ENDED_COLLISION

__all__ = [
    "ActionScaling",
    "EnvStep",
    "HighwayEnvPlant",
    "lane_centerline",
    "lane_following_obstacle",
    "lane_sequence",
    "vehicle_obstacle",
]

#: highway-env's ContinuousAction defaults (used when the env config names no range)
DEFAULT_STEERING_RANGE_RAD = (-math.pi / 4, math.pi / 4)
DEFAULT_ACCELERATION_RANGE_MPS2 = (-5.0, 5.0)


# --------------------------------------------------------------------------- road -> path
def lane_sequence(network, start_index) -> tuple[list, bool]:
    """Lane indices ``(from, to, id)`` followed from ``start_index`` through the road network,
    keeping the lane id where the next road has it (else the nearest lane of the next road);
    returns (indices, closed): closed when the sequence comes back to the start."""
    graph = network.graph
    try:
        network.get_lane(start_index)
    except (KeyError, IndexError, TypeError):
        raise ValueError(f"lane index {start_index!r} is not in the road network") from None
    seq, cur = [tuple(start_index)], tuple(start_index)
    n_lanes = sum(len(lanes) for to in graph.values() for lanes in to.values())
    for _ in range(n_lanes):
        _, to, lane_id = cur
        nexts = graph.get(to, {})
        if not nexts:
            return seq, False
        end = network.get_lane(cur).position(network.get_lane(cur).length, 0.0)
        best = None
        for nxt_to, lanes in nexts.items():
            ids = [lane_id] if lane_id < len(lanes) else range(len(lanes))
            for j in ids:
                d = float(np.hypot(*(np.asarray(lanes[j].position(0.0, 0.0)) - end)))
                if best is None or d < best[0]:
                    best = (d, (to, nxt_to, j))
        cur = best[1]
        if cur == seq[0]:
            return seq, True
        if cur in seq:
            raise ValueError(
                f"the lanes from {start_index!r} run into a loop that does not return to the start (at {cur!r})"
            )
        seq.append(cur)
    raise ValueError(f"could not follow the lanes from {start_index!r}")


def lane_centerline(network, lane_index, *, ds_m: float = 1.0, smoothing_m: float = 0.02) -> tuple[WaypointPath, float]:
    """The centreline of the lane ``lane_index`` and its successors as a path, and the lane
    half width [m] (the narrowest along the way).

    ds_m : sampling step along each lane [m]; smoothing_m : allowed RMS distance [m] between
    the fitted spline and the samples (0 interpolates; the default irons out the few-decimetre
    steps where the racetrack's pieces join without moving the line noticeably).
    """
    if not (math.isfinite(ds_m) and ds_m > 0):
        raise ValueError(f"ds_m must be positive, got {ds_m}")
    if not (math.isfinite(smoothing_m) and smoothing_m >= 0):
        raise ValueError(f"smoothing_m must be >= 0, got {smoothing_m}")
    seq, closed = lane_sequence(network, lane_index)
    lanes = [network.get_lane(ix) for ix in seq]
    pts, widths = [], []
    for n, lane in enumerate(lanes):
        length = float(lane.length)
        s = np.arange(0.0, length, ds_m)
        if not closed and n == len(lanes) - 1:
            s = np.r_[s, length]
        P = np.array([lane.position(si, 0.0) for si in s], dtype=float).reshape(-1, 2)
        widths += [float(lane.width_at(si)) for si in (0.0, 0.5 * length, length)]
        if closed or n + 1 < len(lanes):
            nxt = lanes[(n + 1) % len(lanes)]
            start = np.asarray(nxt.position(0.0, 0.0), dtype=float)
            h = float(nxt.heading_at(0.0))
            along = (P - start) @ np.array([math.cos(h), math.sin(h)])
            # near the end only: points at or past the next piece's start line overlap it
            near_end = s > length - min(5.0, 0.5 * length)
            P = P[~(near_end & (along > -0.25 * ds_m))]
        pts.append(P)
    P = np.vstack(pts)
    path = WaypointPath(P, closed=closed, smoothing=len(P) * smoothing_m**2)
    return path, 0.5 * min(widths)


# --------------------------------------------------------------------------- actions
@dataclass(frozen=True)
class ActionScaling:
    """highway-env's ContinuousAction mapping between [-1, 1] and physical inputs.

    steering_range_rad : (low, high) [rad]; acceleration_range_mps2 : (low, high) [m/s^2], or
    None when the action has no longitudinal part (then the action is ``[steering]``, else
    ``[acceleration, steering]``).
    """

    steering_range_rad: tuple[float, float] = DEFAULT_STEERING_RANGE_RAD
    acceleration_range_mps2: tuple[float, float] | None = DEFAULT_ACCELERATION_RANGE_MPS2

    def __post_init__(self):
        for name in ("steering_range_rad", "acceleration_range_mps2"):
            rng = getattr(self, name)
            if rng is None and name == "acceleration_range_mps2":
                continue
            lo, hi = (float(v) for v in rng)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(f"{name} must be two finite numbers, low < high, got {rng}")
            object.__setattr__(self, name, (lo, hi))

    @classmethod
    def from_env(cls, env) -> ActionScaling:
        """The scaling of a created environment's ContinuousAction (lateral control required)."""
        at = env.unwrapped.action_type
        if type(at).__name__ != "ContinuousAction":
            raise ValueError(f"action.type must be ContinuousAction, got {type(at).__name__}")
        if not at.lateral:
            raise ValueError("action.lateral must be true: the driver steers")
        return cls(tuple(at.steering_range), tuple(at.acceleration_range) if at.longitudinal else None)

    @property
    def longitudinal(self) -> bool:
        return self.acceleration_range_mps2 is not None

    @staticmethod
    def _to_unit(value: float, rng: tuple[float, float]) -> float:
        lo, hi = rng
        return float(np.clip(2.0 * (value - lo) / (hi - lo) - 1.0, -1.0, 1.0))

    @staticmethod
    def _from_unit(a: float, rng: tuple[float, float]) -> float:
        lo, hi = rng
        return float(lo + (float(np.clip(a, -1.0, 1.0)) + 1.0) * 0.5 * (hi - lo))

    def to_action(self, steer_rad: float, accel_mps2: float = 0.0) -> np.ndarray:
        """Normalized action (float32, in [-1, 1]) for steering [rad] and acceleration [m/s^2]."""
        if not (math.isfinite(steer_rad) and math.isfinite(accel_mps2)):
            raise ValueError(f"steer_rad and accel_mps2 must be finite, got {steer_rad}, {accel_mps2}")
        st = self._to_unit(steer_rad, self.steering_range_rad)
        if self.acceleration_range_mps2 is None:
            return np.array([st], dtype=np.float32)
        return np.array([self._to_unit(accel_mps2, self.acceleration_range_mps2), st], dtype=np.float32)

    def from_action(self, action) -> tuple[float, float]:
        """(steering [rad], acceleration [m/s^2]) that the environment applies for ``action``."""
        a = np.asarray(action, dtype=float).reshape(-1)
        n = 2 if self.longitudinal else 1
        if a.shape != (n,):
            raise ValueError(f"action must have {n} component(s), got shape {a.shape}")
        if not self.longitudinal:
            return self._from_unit(a[0], self.steering_range_rad), 0.0
        return (self._from_unit(a[1], self.steering_range_rad), self._from_unit(a[0], self.acceleration_range_mps2))


# --------------------------------------------------------------------------- other vehicles
def vehicle_obstacle(vehicle, t_s: float = 0.0, name: str = "") -> Obstacle:
    """A highway-env vehicle (or road object) as a moving obstacle: its ``LENGTH`` x ``WIDTH``
    rectangle [m] centred at its ``position`` [m] with its ``heading`` [rad], moving at its
    current velocity ``speed (cos heading, sin heading)`` [m/s].

    t_s : the time [s] on the controller's clock at which the vehicle is where it is now (the
    ``warm.t_s`` of the step that uses the obstacle), so ``pose_at(t_s)`` is its current pose
    and ``pose_at(t_s + k dt)`` the constant-velocity prediction ``k`` steps ahead."""
    if not math.isfinite(t_s):
        raise ValueError(f"t_s must be finite, got {t_s}")
    x, y = (float(v) for v in vehicle.position)
    heading, speed = float(vehicle.heading), float(getattr(vehicle, "speed", 0.0))
    vx, vy = speed * math.cos(heading), speed * math.sin(heading)
    return Obstacle(
        rectangle(float(vehicle.LENGTH), float(vehicle.WIDTH)),
        (x - vx * t_s, y - vy * t_s, heading),
        ConstantVelocity(vx, vy),
        name,
    )


def lane_following_obstacle(
    vehicle,
    path,
    times_s,
    t_s: float = 0.0,
    *,
    s_guess: float | None = None,
    tau_lateral_s: float = 1.0,
    name: str = "",
) -> Obstacle:
    """A highway-env vehicle as an obstacle that follows its lane: the ``LENGTH`` x ``WIDTH``
    rectangle [m] starts at the vehicle's pose and moves along ``path`` (the lane's centreline,
    a :class:`~mpcdrive.paths.ReferencePath`) at its current speed [m/s], its lateral offset [m] and
    heading offset [rad] from the lane decaying with time constant ``tau_lateral_s`` [s] (the
    vehicle steers back to the lane centre; ``math.inf`` keeps the offsets).

    times_s : (K,) prediction times [s] from now (increasing, starting at 0; the pose is held
    after the last); t_s : the controller's clock [s] now (see :func:`vehicle_obstacle`);
    s_guess : arc length [m] near which to project the vehicle (None: the whole path)."""
    times = np.asarray(times_s, dtype=float)
    if times.ndim != 1 or len(times) < 1 or times[0] != 0.0 or np.any(np.diff(times) <= 0):
        raise ValueError("times_s must be increasing prediction times starting at 0")
    if not math.isfinite(t_s):
        raise ValueError(f"t_s must be finite, got {t_s}")
    if not tau_lateral_s > 0:
        raise ValueError(f"tau_lateral_s must be positive, got {tau_lateral_s}")
    xy = np.array([float(v) for v in vehicle.position])
    heading, speed = float(vehicle.heading), float(getattr(vehicle, "speed", 0.0))
    window = 10.0 + float(vehicle.LENGTH)
    s0, e0 = path.project(xy, s_guess, window) if s_guess is not None else path.project(xy)
    s = s0 + max(speed, 0.0) * times
    if not path.closed:
        s = np.minimum(s, path.length_m)
    h = np.asarray(path.heading(s), dtype=float)
    dpsi = (heading - float(path.heading(s0)) + math.pi) % (2.0 * math.pi) - math.pi
    decay = np.exp(-times / tau_lateral_s)
    normal = np.column_stack([-np.sin(h), np.cos(h)])
    P = np.asarray(path.position(s), dtype=float) + (e0 * decay)[:, None] * normal
    # the prediction starts exactly at the vehicle's pose
    P += (xy - P[0]) * decay[:, None]
    yaw = np.unwrap(h + dpsi * decay)
    yaw += heading - yaw[0]
    motion = TrajectoryMotion(t_s + times, P[:, 0] - xy[0], P[:, 1] - xy[1], yaw - heading)
    return Obstacle(rectangle(float(vehicle.LENGTH), float(vehicle.WIDTH)), (xy[0], xy[1], heading), motion, name)


def _vehicle_state(vehicle, nx: int) -> np.ndarray:
    x = [float(vehicle.position[0]), float(vehicle.position[1]), float(vehicle.heading)]
    if nx == 4:
        x.append(float(vehicle.speed))
    return np.array(x)


# --------------------------------------------------------------------------- the plant
@dataclass(frozen=True)
class EnvStep:
    """What the environment reported after one ``env.step``: its ``reward``, ``terminated``
    and ``truncated``; the ego's ``crashed``, ``on_road`` (on a lane), ``speed_mps`` [m/s] and
    ``lane_index``."""

    reward: float
    terminated: bool
    truncated: bool
    crashed: bool
    on_road: bool
    speed_mps: float
    lane_index: tuple


class HighwayEnvPlant:
    """A created and reset highway-env environment as the plant of :func:`mpcdrive.sim.simulate`
    (an ``ObservedPlant`` with traffic that can end the episode: ``TrafficPlant``,
    ``EpisodicPlant`` of :mod:`mpcdrive.sim.closed_loop`).

    The environment holds the state: the plant state is the ego's observed state [x m, y m,
    yaw rad(, v m/s)] (:attr:`model`'s layout) as read after the last step, and :meth:`step`
    must be given that state. A command ``u`` (steering [rad](, acceleration [m/s^2])) is the
    action of one policy step (``dt_s = 1 / policy_frequency``), scaled by :attr:`scaling`; what
    the environment reports after it is appended to :attr:`records` and ``observer(env)`` (when
    given) is called. :meth:`traffic` gives the other vehicles (and solid road objects:
    :attr:`others`, their order fixed) as obstacles at the loop's time, with the prediction
    ``prediction`` over ``horizon`` policy steps (``lane``: along the lane each one steers to, its
    offset decaying with ``tau_lateral_s`` [s]; ``constant_velocity``: a straight line; lane
    centrelines built with ``centerline_ds_m`` / ``centerline_smoothing_m``, see
    :func:`lane_centerline`, except those given in ``lane_paths``, a path per lane index, e.g.
    the controller's own). :meth:`ended` ends the run when the environment terminates
    (``collision`` when the ego crashed, else ``terminated``) or truncates (``truncated``).
    """

    def __init__(
        self,
        env,
        *,
        horizon: int = 15,
        prediction: Literal["lane", "constant_velocity"] = "lane",
        tau_lateral_s: float = 1.0,
        centerline_ds_m: float = 1.0,
        centerline_smoothing_m: float = 0.02,
        lane_paths: dict | None = None,
        observer: Callable | None = None,
    ):
        u = env.unwrapped
        vehicle = getattr(u, "vehicle", None)
        if vehicle is None:
            raise ValueError("the environment has no ego vehicle: call env.reset() first")
        cfg = u.config
        if cfg["action"].get("dynamical", False):
            raise ValueError(
                "action.dynamical must be false: the plant models highway-env's "
                "kinematic Vehicle, not the dynamical BicycleVehicle"
            )
        if isinstance(horizon, bool) or int(horizon) != horizon or horizon < 1:
            raise ValueError(f"horizon must be a positive integer, got {horizon}")
        if prediction not in ("lane", "constant_velocity"):
            raise ValueError(f"prediction must be 'lane' or 'constant_velocity', got {prediction!r}")
        if not tau_lateral_s > 0:
            raise ValueError(f"tau_lateral_s must be positive, got {tau_lateral_s}")
        self.env = env
        self.scaling = ActionScaling.from_env(env)
        self.dt_s = 1.0 / float(cfg["policy_frequency"])
        #: the ego's lane when the plant was made
        self.lane_index = tuple(vehicle.lane_index)
        # everything the ego can collide with, in a fixed order (index = obstacle identity)
        self.others = tuple(
            o
            for o in [*u.road.vehicles, *getattr(u.road, "objects", [])]
            if o is not vehicle and getattr(o, "collidable", True) and getattr(o, "solid", True)
        )
        length_m, width_m = float(vehicle.LENGTH), float(vehicle.WIDTH)
        self.footprint = Footprint(length_m, width_m)
        params = KinematicParams(0.5 * length_m, 0.5 * length_m)
        self.model: KinematicBicycle3 | KinematicBicycle4
        if self.scaling.longitudinal:
            self.model = KinematicBicycle4(params)
        else:
            self.model = KinematicBicycle3(float(vehicle.speed), params)
        self.prediction, self.tau_lateral_s = prediction, float(tau_lateral_s)
        self._centerline = {"ds_m": centerline_ds_m, "smoothing_m": centerline_smoothing_m}
        self._times_s = self.dt_s * np.arange(int(horizon) + 1)
        self._lane_paths: dict = {tuple(ix): p for ix, p in (lane_paths or {}).items()}
        self.observer = observer
        #: what the environment reported after each step
        self.records: list[EnvStep] = []

    # -- the ego ------------------------------------------------------------------------------
    def state(self) -> np.ndarray:
        """(nx,) the ego's state [x m, y m, yaw rad(, v m/s)] read from the environment."""
        return _vehicle_state(self.env.unwrapped.vehicle, self.model.nx)

    def initial_state(self, x0) -> np.ndarray:
        """The plant state: the ego where the environment has it, which ``x0`` must be."""
        x = self.state()
        if np.shape(x0) != x.shape or not np.allclose(np.asarray(x0, float), x, rtol=0.0, atol=1e-9):
            raise ValueError(f"x0 must be the ego's state in the environment (plant.state()) {x.tolist()}, got {x0!r}")
        return x

    def observe(self, xp) -> np.ndarray:
        return np.asarray(xp, float)

    def step(self, xp, u, dt_s: float) -> np.ndarray:
        """One ``env.step`` with the command ``u`` from the plant state ``xp`` (the last one this
        plant gave); the ego's state after it. A command that is not finite is not applied: the
        state is NaN (the loop ends the run as diverged)."""
        if not math.isclose(dt_s, self.dt_s, rel_tol=1e-9):
            raise ValueError(f"dt_s must be the policy period {self.dt_s:g} s (1 / policy_frequency), got {dt_s!r}")
        if not np.array_equal(np.asarray(xp, float), self.state()):
            raise ValueError("xp must be the environment's current ego state (the plant's last state)")
        u = np.asarray(u, float).reshape(-1)
        if not np.all(np.isfinite(u)):
            return np.full(self.model.nx, np.nan)
        accel = float(u[1]) if self.model.nu > 1 else 0.0
        _, reward, terminated, truncated, _ = self.env.step(self.scaling.to_action(float(u[0]), accel))
        ego = self.env.unwrapped.vehicle
        self.records.append(
            EnvStep(
                float(reward),
                bool(terminated),
                bool(truncated),
                bool(ego.crashed),
                bool(ego.on_road),
                float(ego.speed),
                tuple(ego.lane_index),
            )
        )
        if self.observer is not None:
            self.observer(self.env)
        return self.state()

    def ended(self, xp=None) -> str | None:
        """Why the episode is over after the last step (None while it goes on)."""
        if not self.records:
            return None
        r = self.records[-1]
        if r.crashed:
            return ENDED_COLLISION
        if r.terminated:
            return "terminated"
        return "truncated" if r.truncated else None

    # -- the traffic --------------------------------------------------------------------------
    def lane_path(self, lane_index) -> ReferencePath:
        """Centreline path of the lanes followed from ``lane_index`` (built once per sequence;
        a straight lane without successors is a :class:`StraightPath`)."""
        lane_index = tuple(lane_index)
        if lane_index not in self._lane_paths:
            network = self.env.unwrapped.road.network
            lane = network.get_lane(lane_index)
            if type(lane).__name__ == "StraightLane" and not network.graph.get(lane_index[1]):
                self._lane_paths[lane_index] = StraightPath(lane.start, lane.end)
            else:
                seq, _ = lane_sequence(network, lane_index)
                path, _ = lane_centerline(network, lane_index, **self._centerline)
                for ix in seq:
                    self._lane_paths.setdefault(ix, path)
        return self._lane_paths[lane_index]

    def traffic(self, t_s: float) -> tuple[Obstacle, ...]:
        """The other vehicles (and solid road objects) where they are now, as obstacles on the
        loop's clock at ``t_s`` [s]: moving along their lane (:func:`lane_following_obstacle`,
        towards the lane they steer to) or, with ``prediction="constant_velocity"`` and for
        objects off the lanes, in a straight line (:func:`vehicle_obstacle`)."""
        out = []
        for j, o in enumerate(self.others):
            name = f"{type(o).__name__}-{j}"
            lane = getattr(o, "target_lane_index", None) or getattr(o, "lane_index", None)
            if self.prediction == "lane" and lane is not None and float(getattr(o, "speed", 0.0)) != 0.0:
                out.append(
                    lane_following_obstacle(
                        o, self.lane_path(lane), self._times_s, t_s, tau_lateral_s=self.tau_lateral_s, name=name
                    )
                )
            else:
                out.append(vehicle_obstacle(o, t_s, name))
        return tuple(out)
