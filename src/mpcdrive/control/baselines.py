"""Geometric path-tracking baselines with the :class:`~mpcdrive.control.base.Controller` interface.

* :class:`PurePursuit` -- steer the rear axle along a circular arc to a look-ahead point on the
  path: ``delta = atan(2 L sin(alpha) / l_d)`` with look-ahead ``l_d = max(l_min, k_v v)``.
* :class:`Stanley` -- the Stanford "Stanley" law at the front axle:
  ``delta = delta_ff - e_psi - atan(k e_f / (k_soft + v))`` with ``e_f`` the front axle's lateral
  error, ``e_psi`` the heading error against the steady-state yaw and ``delta_ff`` the model's
  steady-state steering for the path curvature.

Both follow the reference speed (a :class:`~mpcdrive.paths.SpeedProfile` or constant) with a
proportional speed loop plus the profile's acceleration as feedforward, and respect the same
steering, steering-rate and acceleration limits as the MPC. They read the pose (x, y, yaw) and
the model's speed from any state layout. ``N = 0``: the "prediction" is the current state.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..models.base import VehicleModel
from ..paths.base import ReferencePath
from ..types import STATUS_OK, ControlOutput, WarmStart
from ..units import wrap_angle


@dataclass(frozen=True)
class BaselineLimits:
    """Actuator limits [rad, rad/s, m/s^2] shared with the MPC; rates apply per control period."""

    max_steer_rad: float
    max_steer_rate_rad_s: float = math.inf
    accel_min_mps2: float = -math.inf
    accel_max_mps2: float = math.inf

    def __post_init__(self):
        if not (self.max_steer_rad > 0 and self.max_steer_rate_rad_s > 0):
            raise ValueError("max_steer_rad and max_steer_rate_rad_s must be positive")
        if self.accel_min_mps2 > self.accel_max_mps2:
            raise ValueError("accel_min_mps2 exceeds accel_max_mps2")


class _GeometricTracker:
    name = "geometric"

    def __init__(
        self,
        model: VehicleModel,
        path: ReferencePath,
        dt_s: float,
        speed_ref,
        limits: BaselineLimits,
        *,
        wheelbase_m: float,
        lr_m: float,
        speed_gain_per_s: float = 2.0,
        projection_window_m: float = 2.0,
    ):
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s must be positive, got {dt_s}")
        if not callable(getattr(speed_ref, "speed", None)):
            raise ValueError("speed_ref must have a speed(s_m) method (SpeedProfile or ConstantSpeed)")
        if not (wheelbase_m > 0 and 0 < lr_m < wheelbase_m):
            raise ValueError(f"need 0 < lr_m < wheelbase_m, got {lr_m}, {wheelbase_m}")
        self.model, self.path, self.dt_s, self.speed_ref, self.limits = model, path, float(dt_s), speed_ref, limits
        self.L, self.lr = float(wheelbase_m), float(lr_m)
        self.k_v = float(speed_gain_per_s)
        self.window_m = projection_window_m
        self.nx, self.nu, self.N = model.nx, model.nu, 0
        self._accel = list(model.input_names).index("accel") if "accel" in model.input_names else None

    def initial_warm(self, x0) -> WarmStart:
        x0 = np.asarray(x0, float)
        s0, _ = self.path.project(x0[:2])
        return WarmStart(s_m=float(s0), u_prev=np.zeros(self.nu))

    def _steer(self, x: np.ndarray, s0: float, v: float) -> float:
        raise NotImplementedError

    def step(self, x, warm: WarmStart) -> ControlOutput:
        t0 = time.perf_counter()
        x = np.asarray(x, float)
        if x.shape != (self.nx,) or not np.all(np.isfinite(x)):
            raise ValueError(f"state must be {self.nx} finite numbers {self.model.state_names}, got {x}")
        s0, e_y = self.path.project(x[:2], warm.s_m, self.window_m)
        e_psi = wrap_angle(x[2] - float(self.path.heading(s0)))
        v = float(self.model.speed(x))
        lim = self.limits
        u = np.zeros(self.nu)
        rate = lim.max_steer_rate_rad_s * self.dt_s
        steer = self._steer(x, s0, v)
        steer = float(np.clip(steer, warm.u_prev[0] - rate, warm.u_prev[0] + rate))
        u[0] = float(np.clip(steer, -lim.max_steer_rad, lim.max_steer_rad))
        v_ref = float(self.speed_ref.speed(s0))
        if self._accel is not None:
            v_ahead = float(self.speed_ref.speed(s0 + max(v, 0.0) * self.dt_s))
            a_ff = (v_ahead - v_ref) / self.dt_s
            u[self._accel] = float(np.clip(a_ff + self.k_v * (v_ref - v), lim.accel_min_mps2, lim.accel_max_mps2))
        pose = np.array([[*self.path.position(s0), float(self.path.heading(s0))]])
        # the path point as the logged reference (no steady-state solve: it is for the log only)
        xr, _ = self.model.reference(pose, np.array([float(self.path.curvature(s0))]), np.array([v_ref]), False)
        return ControlOutput(
            u=u,
            status=STATUS_OK,
            fallback="",
            solve_time_s=time.perf_counter() - t0,
            s_m=float(s0),
            e_y_m=float(e_y),
            e_psi_rad=float(e_psi),
            X_pred=x[None, :].copy(),
            refs=xr,
            warm=WarmStart(s_m=float(s0), u_prev=u.copy()),
        )


class PurePursuit(_GeometricTracker):
    """Pure pursuit of a look-ahead point ``max(lookahead_min_m, lookahead_gain_s * v)`` ahead of
    the rear axle (other arguments: see :class:`_GeometricTracker` and the module docstring)."""

    name = "pure-pursuit"

    def __init__(self, *args, lookahead_gain_s: float = 0.35, lookahead_min_m: float = 0.6, **kw):
        super().__init__(*args, **kw)
        if not (lookahead_gain_s >= 0 and lookahead_min_m > 0):
            raise ValueError("lookahead_gain_s must be >= 0 and lookahead_min_m > 0")
        self.k_ld, self.ld_min = float(lookahead_gain_s), float(lookahead_min_m)

    def _steer(self, x, s0, v):
        c, s = math.cos(x[2]), math.sin(x[2])
        rear = x[:2] - self.lr * np.array([c, s])
        ld = max(self.ld_min, self.k_ld * abs(v))
        target = self.path.position(s0 - self.lr + ld)
        d = target - rear
        dist = math.hypot(*d)
        alpha = math.atan2(d[1], d[0]) - x[2]
        return math.atan2(2.0 * self.L * math.sin(alpha), dist)


class Stanley(_GeometricTracker):
    """Stanley steering at the front axle with gain ``gain`` [-] and softening speed
    ``softening_mps`` [m/s], plus the steady-state steering and slip of ``feedforward_model``
    (default: the model whose states it reads) for the path curvature."""

    name = "stanley"

    def __init__(
        self, *args, gain: float = 2.5, softening_mps: float = 1.0, feedforward_model: VehicleModel | None = None, **kw
    ):
        super().__init__(*args, **kw)
        if not (gain > 0 and softening_mps > 0):
            raise ValueError("gain and softening_mps must be positive")
        self.k, self.k_soft = float(gain), float(softening_mps)
        self.ff_model = self.model if feedforward_model is None else feedforward_model

    def _steer(self, x, s0, v):
        c, s = math.cos(x[2]), math.sin(x[2])
        lf = self.L - self.lr
        front = x[:2] + lf * np.array([c, s])
        sf, ef = self.path.project(front, s0 + lf, self.window_m)
        kappa = float(self.path.curvature(sf))
        ff, beta = self.ff_model.steady_state(np.array([kappa]), np.array([max(v, 0.0)]))
        # heading error against the steady-state yaw (path heading minus the body slip angle)
        e_psi = wrap_angle(x[2] - (float(self.path.heading(sf)) - float(np.ravel(beta)[0])))
        return float(np.ravel(ff)[0]) - e_psi - math.atan2(self.k * ef, self.k_soft + abs(v))
