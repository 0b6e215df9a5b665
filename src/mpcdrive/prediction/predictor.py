"""Predict other cars from what is observable now: constant speed along the lane, with an
uncertainty that grows with the prediction time.

An :class:`Observation` is what a sensor gives of a car at one time: pose, speed along its
heading, body. :func:`observe` takes it from any :class:`~mpcdrive.scene.obstacles.Obstacle`
without looking ahead: the pose at the time, the velocity a constant-velocity motion states, or
for a recorded trajectory the mean velocity over the last control period (over the recording's
first step at its very start, the recorded start velocity).

:class:`LanePredictor` turns an observation into the obstacles the controller avoids: the car
moves at its current speed along the lane it is matched to (:class:`~.lanes.LaneMap`: the lane's
curve and its successors), its offset from the lane's centre decaying with ``tau_lateral_s``; a
car on no lane goes straight on. The body is inflated by what the car may do differently: ahead
``speed_sigma_mps t + accel_sigma_mps2 t^2 / 2``, behind the same but no more than the distance it
covers (it does not back up), sideways ``lateral_rate_mps t``, each capped. Since an obstacle has
one shape, the prediction is a few obstacles, one per time band (``bands_s``), each present only
over its band and inflated as at the band's end: the controller keeps a larger distance from the
car the farther ahead it looks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..scene.obstacles import Circle, ConstantVelocity, Obstacle, Polygon, TrajectoryMotion
from .lanes import LaneMap

#: a band's start lies this long after the previous band's end [s]: at a horizon step exactly on
#: a band's edge only the earlier band is present
BAND_GAP_S = 1e-6


@dataclass(frozen=True)
class Observation:
    """A car as observed at time ``t_s`` [s]: pose ``(x m, y m, yaw rad)``, speed ``v_mps``
    along its heading [m/s], its shape, name and lifetime (as the obstacle's: a predictor does
    not use its end, which lies in the future)."""

    t_s: float
    pose: tuple[float, float, float]
    v_mps: float
    shape: Circle | Polygon
    name: str = ""
    t_start_s: float = -math.inf
    t_end_s: float = math.inf


def observe(ob: Obstacle, t_s: float, period_s: float) -> Observation | None:
    """What a sensor sees of ``ob`` at ``t_s`` [s] (None when it is not there): its pose now and
    its velocity from the past only (the stated velocity of a constant-velocity motion; for a
    recorded trajectory the displacement over the last ``period_s`` [s], or over the
    recording's first step at its start), as speed along its heading."""
    if not bool(ob.present(t_s)):
        return None
    m = ob.motion
    if isinstance(m, TrajectoryMotion):
        t0, t1 = t_s - period_s, t_s
        first = float(m.t_s[0])
        if len(m.t_s) >= 2 and t0 < first - 1e-9:
            t0, t1 = first, float(m.t_s[1])
        P = ob.poses_at(np.array([t_s, t0, t1]))  # one interpolation for the three times
        x, y, yaw = (float(c) for c in P[0])
        vx, vy = ((P[2, 0] - P[1, 0]) / (t1 - t0), (P[2, 1] - P[1, 1]) / (t1 - t0)) if t1 > t0 else (0.0, 0.0)
    else:
        x, y, yaw = ob.pose_at(t_s)
        vx, vy = (m.vx_mps, m.vy_mps) if isinstance(m, ConstantVelocity) else (0.0, 0.0)
    v = vx * math.cos(yaw) + vy * math.sin(yaw)
    return Observation(float(t_s), (x, y, yaw), float(v), ob.shape, ob.name, ob.t_start_s, ob.t_end_s)


@dataclass(frozen=True)
class PredictionConfig:
    """Settings of :class:`LanePredictor` (SI units).

    horizon_s / dt_s : how far ahead and how finely the motion is predicted [s];
    bands_s : the ends of the time bands [s] (increasing; the last is the horizon's end), one
    obstacle each; speed_sigma_mps / accel_sigma_mps2 : the longitudinal uncertainty's growth
    [m/s, m/s^2], capped at longitudinal_cap_m [m]; lateral_rate_mps / lateral_cap_m : the
    lateral one [m/s, m]; tau_lateral_s : time constant [s] of the offset from the lane centre
    (the car steers back to it); max_heading_deg / reach_m : what matches a car to a lane
    (:meth:`~.lanes.LaneMap.match`); min_speed_mps : below it a car counts as standing (it
    stays where it is, its body growing ahead only); range_m : the sensors' range [m]: a car
    farther from the ego is not seen (not predicted).
    """

    horizon_s: float = 8.0
    dt_s: float = 0.1
    bands_s: tuple[float, ...] = (1.0, 3.0, 8.0)
    speed_sigma_mps: float = 0.5
    accel_sigma_mps2: float = 0.5
    longitudinal_cap_m: float = 4.0
    lateral_rate_mps: float = 0.2
    lateral_cap_m: float = 0.5
    tau_lateral_s: float = 2.0
    max_heading_deg: float = 45.0
    reach_m: float = 1.0
    min_speed_mps: float = 0.1
    range_m: float = 150.0

    def __post_init__(self):
        for name in ("horizon_s", "dt_s", "tau_lateral_s", "max_heading_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"prediction {name} must be positive, got {v}")
        for name in (
            "speed_sigma_mps",
            "accel_sigma_mps2",
            "longitudinal_cap_m",
            "lateral_rate_mps",
            "lateral_cap_m",
            "reach_m",
            "min_speed_mps",
            "range_m",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"prediction {name} must be >= 0, got {v}")
        b = tuple(float(v) for v in self.bands_s)
        if not b or any(v <= 0 for v in b) or any(y <= x for x, y in zip(b, b[1:])):
            raise ValueError(f"prediction bands_s must be increasing positive times, got {self.bands_s}")
        if abs(b[-1] - self.horizon_s) > 1e-9:
            raise ValueError(f"the last of bands_s ({b[-1]:g} s) must be horizon_s ({self.horizon_s:g} s)")
        object.__setattr__(self, "bands_s", b)

    def inflation_m(self, tau_s: float, v_mps: float) -> tuple[float, float, float]:
        """(ahead, behind, sideways) [m] by which the body is grown at ``tau_s`` [s] ahead for a
        car at ``v_mps`` [m/s]."""
        lon = min(self.speed_sigma_mps * tau_s + 0.5 * self.accel_sigma_mps2 * tau_s**2, self.longitudinal_cap_m)
        return lon, min(lon, max(v_mps, 0.0) * tau_s), min(self.lateral_rate_mps * tau_s, self.lateral_cap_m)


def inflated(shape: Circle | Polygon, ahead_m: float, behind_m: float, side_m: float) -> Circle | Polygon:
    """``shape`` grown by ``ahead_m`` forward, ``behind_m`` backward and ``side_m`` to each side
    [m] (a polygon becomes its grown bounding box; a circle grows by the largest of the three)."""
    if isinstance(shape, Circle):
        return Circle(shape.radius_m + max(ahead_m, behind_m, side_m))
    p = shape.points
    x0, x1 = float(p[:, 0].min()) - behind_m, float(p[:, 0].max()) + ahead_m
    y0, y1 = float(p[:, 1].min()) - side_m, float(p[:, 1].max()) + side_m
    return Polygon(np.array([[x1, y1], [x0, y1], [x0, y0], [x1, y0]]))


class LanePredictor:
    """Constant speed along the lane (:class:`~.lanes.LaneMap`), uncertainty growing with time
    (:class:`PredictionConfig`)."""

    def __init__(self, lanes: LaneMap | None, config: PredictionConfig = PredictionConfig()):
        self.lanes = lanes
        self.config = config
        n = int(round(config.horizon_s / config.dt_s))
        self.taus_s = np.linspace(0.0, n * config.dt_s, n + 1)
        self._decay = np.exp(-self.taus_s / config.tau_lateral_s)  # of the offset from the lane centre
        self._shapes: dict[tuple, Circle | Polygon] = {}  # inflated bodies, by body and growth

    def _inflated(self, shape: Circle | Polygon, tau_s: float, v_mps: float) -> Circle | Polygon:
        """:func:`inflated` at ``tau_s`` for a car at ``v_mps``, the growth behind rounded up
        to 0.1 m (kept: a car's bodies repeat from step to step)."""
        ahead, behind, side = self.config.inflation_m(tau_s, v_mps)
        behind = min(math.ceil(behind * 10.0 - 1e-9) / 10.0, ahead)
        body = shape.radius_m if isinstance(shape, Circle) else shape.points.tobytes()
        key = (body, ahead, behind, side)
        out = self._shapes.get(key)
        if out is None:
            out = self._shapes[key] = inflated(shape, ahead, behind, side)
        return out

    @property
    def bands(self) -> int:
        """Obstacles per predicted car."""
        return len(self.config.bands_s)

    def path(self, obs: Observation) -> tuple[np.ndarray, np.ndarray]:
        """The predicted positions (K, 2) [m] and headings (K,) [rad] at ``taus_s`` after the
        observation."""
        cfg = self.config
        x, y, yaw = obs.pose
        v = obs.v_mps if obs.v_mps >= cfg.min_speed_mps else 0.0
        taus = self.taus_s
        lanes = self.lanes
        m = None
        if lanes is not None:
            m = lanes.match(x, y, yaw, max_heading_rad=math.radians(cfg.max_heading_deg), reach_m=cfg.reach_m)
        if lanes is None or m is None:  # on no lane: straight on
            d = np.array([math.cos(yaw), math.sin(yaw)])
            return np.array([x, y]) + (v * taus)[:, None] * d, np.full(len(taus), yaw)
        xy_c, h = lanes.follow(m.lane, m.s_m + v * taus)
        decay = self._decay
        normal = np.column_stack([-np.sin(h), np.cos(h)])
        P = xy_c + (m.e_y_m * decay)[:, None] * normal
        P += (np.array([x, y]) - P[0]) * decay[:, None]  # starts exactly at the car
        yaws = h + m.e_psi_rad * decay  # continuous: the lane's headings are
        return P, yaws + (yaw - yaws[0])

    def predict(self, obs: Observation) -> tuple[Obstacle, ...]:
        """The obstacles predicting ``obs``: one per band, on the controller's clock (``pose_at(t)``
        the predicted pose at ``t`` [s]), each present over its band only (the first from
        now on) and inflated as at the band's end; past the horizon the last pose holds."""
        cfg = self.config
        P, yaws = self.path(obs)
        t0 = obs.t_s
        x, y, yaw = obs.pose
        motion = TrajectoryMotion(t0 + self.taus_s, P[:, 0] - x, P[:, 1] - y, yaws - yaw)
        out = []
        start = -math.inf
        for k, end in enumerate(cfg.bands_s):
            # the car's future lifetime is not observable: each band holds from its start to its end
            shape = self._inflated(obs.shape, end, obs.v_mps)
            out.append(Obstacle(shape, obs.pose, motion, f"{obs.name}~{k}", start, t0 + end))
            start = t0 + end + BAND_GAP_S
        return tuple(out)
