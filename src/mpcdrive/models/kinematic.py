"""Kinematic bicycle model (the paper's eqs. 1-8), 3 and 4 states.

Slip angle at the centre of gravity: ``beta = atan(lr / (lf + lr) * tan(delta))``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class KinematicParams:
    """Geometry of the kinematic bicycle.

    lf_m : distance centre of gravity -> front axle [m]; lr_m : centre of gravity -> rear axle [m].
    Defaults are the paper's 1:10 F1TENTH-class car (wheelbase 0.33 m).
    """

    lf_m: float = 0.17
    lr_m: float = 0.16

    def __post_init__(self):
        if not (np.isfinite(self.lf_m) and np.isfinite(self.lr_m)) or self.lf_m <= 0 or self.lr_m <= 0:
            raise ValueError(f"lf_m and lr_m must be positive finite numbers, got {self.lf_m}, {self.lr_m}")

    @property
    def wheelbase_m(self) -> float:
        return self.lf_m + self.lr_m

    @property
    def lq(self) -> float:
        """lr / (lf + lr), the paper's ``l_q``."""
        return self.lr_m / (self.lf_m + self.lr_m)


def rear_axle_heading(xy: np.ndarray, yaw0_rad: float, lr_m: float) -> np.ndarray:
    """(K,) heading [rad] of the point ``lr_m`` behind a path of centre-of-gravity positions
    ``xy`` (K, 2) that moves the way it points, starting at ``yaw0_rad``: a kinematic bicycle's
    rear axle (which rolls without slip) dragged along by its centre of gravity, the tractrix
    ``dtheta/ds = sin(chi - theta) / lr`` with ``chi`` the direction the centre of gravity travels.

    Each step takes the chord between two positions as the travel (``chi`` its direction, ``s``
    its length), where the tractrix solves in closed form: ``tan((chi - theta) / 2)`` shrinks by
    ``exp(-s / lr)``: the chord's error is second order (on a kinematic car, where it is the
    yaw: 1e-4 rad with 10 ms steps in a test's turns; 0.005 rad at most on CommonRoad's KS drives
    of the development files, 0.1-0.2 s steps). The heading
    turns only as the car travels: standing, it holds. On a car whose tyres slip it is the yaw
    plus the rear axle's slip angle, the rear axle lagging behind a sudden change as it does (what
    a kinematic state of that drive holds as its orientation)."""
    p = np.asarray(xy, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 1:
        raise ValueError(f"positions must be (K >= 1, 2), got shape {p.shape}")
    if not (np.isfinite(lr_m) and lr_m > 0):
        raise ValueError(f"lr_m must be a positive length in m, got {lr_m!r}")
    step = np.diff(p, axis=0)
    chi = np.arctan2(step[:, 1], step[:, 0])
    shrink = np.exp(-np.hypot(step[:, 0], step[:, 1]) / lr_m)
    out = np.empty(len(p))
    out[0] = theta = float(yaw0_rad)
    for k in range(len(step)):
        lag = (chi[k] - theta + np.pi) % (2.0 * np.pi) - np.pi
        theta += lag - 2.0 * np.arctan(np.tan(0.5 * lag) * shrink[k])  # unwrapped, as the yaw is
        out[k + 1] = theta
    return out


def path_steering(
    xy: np.ndarray, heading_rad: np.ndarray, wheelbase_m: float, min_travel_m: float = 0.05
) -> np.ndarray:
    """(K,) steering angle [rad] of a kinematic bicycle whose rear axle turns with ``heading_rad``
    (K,) along the positions ``xy`` (K, 2): ``atan(L dtheta / ds)``, the heading's change over
    the distance travelled in the steps either side of each state (one step at the ends); NaN
    where the car travels less than ``min_travel_m`` [m] in them (standing, the path says nothing
    of the wheels)."""
    p = np.asarray(xy, dtype=float)
    th = np.asarray(heading_rad, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2 or th.shape != (len(p),) or len(p) < 2:
        raise ValueError(f"positions must be (K >= 2, 2) and headings (K,), got {p.shape} and {th.shape}")
    if not (np.isfinite(wheelbase_m) and wheelbase_m > 0):
        raise ValueError(f"wheelbase_m must be a positive length in m, got {wheelbase_m!r}")
    step = np.hypot(*np.diff(p, axis=0).T)
    lo = np.maximum(np.arange(len(p)) - 1, 0)
    hi = np.minimum(np.arange(len(p)) + 1, len(p) - 1)
    travel = np.concatenate(([0.0], np.cumsum(step)))
    ds = travel[hi] - travel[lo]
    out = np.full(len(p), np.nan)
    ok = ds >= min_travel_m
    out[ok] = np.arctan(wheelbase_m * (th[hi] - th[lo])[ok] / ds[ok])
    return out


def steady_state_equations(kappa, lq, lr_m, ns):
    """Steady-state (steering [rad], slip angle beta [rad]) on curvature kappa [1/m] with math
    functions from ``ns`` (numpy, or numba when compiled): the single definition used by
    :func:`steady_state_for_curvature` and the compiled controller."""
    beta = ns.arcsin(ns.minimum(ns.maximum(lr_m * kappa, -0.999), 0.999))
    return ns.arctan(ns.tan(beta) / lq), beta


def steady_state_for_curvature(kappa, params: KinematicParams) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state (steering [rad], slip angle beta [rad]) that keeps the centre of gravity of
    the kinematic bicycle on a path of curvature kappa [1/m].

    The centre of gravity moves along ``yaw + beta``; from ``yaw_rate = v/lr sin(beta) = v kappa``:
    ``beta = asin(lr kappa)``, ``delta = atan(tan(beta) / lq)``; |lr kappa| is clipped below 1.
    """
    return steady_state_equations(np.asarray(kappa, float), params.lq, params.lr_m, np)


def _kinematic_reference(pose, kappa, params: KinematicParams, feedforward: bool, nu: int):
    """Pose references (yaw = heading - steady-state slip with ``feedforward``) and inputs
    (steady-state steering with ``feedforward``, zero otherwise) for path points."""
    pose = np.asarray(pose, float)
    kappa = np.asarray(kappa, float)
    xref = pose.copy()
    uref = np.zeros(kappa.shape + (nu,))
    if feedforward:
        steer, beta = steady_state_for_curvature(kappa, params)
        xref[..., 2] -= beta
        uref[..., 0] = steer
    return xref, uref


def _components(a: np.ndarray):
    """State / input components of a single vector or a batch, as views."""
    return a.T if a.ndim <= 2 else np.moveaxis(a, -1, 0)


def slip_terms(delta, lq, ns):
    """(beta, sin beta, cos beta): slip angle beta [rad] at the centre of gravity for steering
    delta [rad], |delta| < pi/2 (eq. 8: tan beta = lq tan delta), with its sine and cosine
    (shared by the equations below; sin and cos from tan beta, no further trigonometry)."""
    w = lq * ns.tan(delta)
    r = 1.0 / ns.sqrt(1.0 + w * w)
    return ns.arctan(w), w * r, r


def slip_angle_derivative(delta, lq, ns):
    """d beta / d delta = lq (1 + tan^2 delta) / (1 + lq^2 tan^2 delta) (eq. 11, divided through
    by cos^2 delta), |delta| < pi/2."""
    t = ns.tan(delta)
    return lq * (1.0 + t * t) / (1.0 + lq * lq * t * t)


def kinematic_rhs_at_slip(yaw, v, slip, lr_m, ns):
    """x', y', yaw' (eqs. 1-4) given ``slip = slip_terms(delta, ...)``."""
    beta, sin_beta, _ = slip
    return v * ns.cos(yaw + beta), v * ns.sin(yaw + beta), v / lr_m * sin_beta


def kinematic_partials_at_slip(yaw, v, slip, dbeta, lr_m, ns):
    """The non-zero partial derivatives of :func:`kinematic_rhs_at_slip` (eqs. 9-12), chained
    through beta(delta): ``(dx'/dyaw, dy'/dyaw, dx'/dv, dy'/dv, dyaw'/dv, dx'/ddelta,
    dy'/ddelta, dyaw'/ddelta)``; dbeta = d beta / d delta."""
    beta, sin_beta, cos_beta = slip
    sa, ca = ns.sin(yaw + beta), ns.cos(yaw + beta)
    return (-v * sa, v * ca, ca, sa, sin_beta / lr_m, -v * sa * dbeta, v * ca * dbeta, v / lr_m * cos_beta * dbeta)


def kinematic_rhs(yaw, v, delta, lq, lr_m, ns):
    """x', y', yaw' of the kinematic bicycle (eqs. 1-4, 8) with math functions from ``ns``
    (numpy, CasADi, or numba: these functions are also compiled as they stand by the fast path).

    yaw [rad], v [m/s], delta [rad]; lq = lr / (lf + lr); lr_m [m]."""
    return kinematic_rhs_at_slip(yaw, v, slip_terms(delta, lq, ns), lr_m, ns)


def kinematic_jacobian_entries(yaw, v, delta, lq, lr_m, ns):
    """:func:`kinematic_partials_at_slip` at steering delta [rad]."""
    return kinematic_partials_at_slip(yaw, v, slip_terms(delta, lq, ns), slip_angle_derivative(delta, lq, ns), lr_m, ns)


class _FromComponents:
    """``f`` of a model from its single definition ``f_components`` (numpy batches)."""

    def f(self, x, u):
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        return np.stack(self.f_components(_components(x), _components(u)), axis=-1)


class KinematicBicycle3(_FromComponents):
    """Kinematic bicycle at constant speed.

    x : (3,) [x m, y m, yaw rad]; u : (1,) [delta rad] front steering angle.
    """

    nx = 3
    nu = 1
    state_names = ("x", "y", "yaw")
    input_names = ("steer",)

    def __init__(self, v_mps: float = 1.0, params: KinematicParams = KinematicParams()):
        if not np.isfinite(v_mps):
            raise ValueError(f"v_mps must be finite, got {v_mps}")
        self.v_mps = float(v_mps)
        self.params = params

    def f_components(self, x, u, ns=np):
        """The equations, on sequences of state / input components and the math namespace ``ns``
        (numpy, or a symbolic one such as CasADi's): the single definition behind :meth:`f`."""
        return kinematic_rhs(x[2], self.v_mps, u[0], self.params.lq, self.params.lr_m, ns)

    def jacobians(self, x, u):
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        v = self.v_mps
        j = kinematic_jacobian_entries(x[..., 2], v, u[..., 0], self.params.lq, self.params.lr_m, np)
        shape = x.shape[:-1]
        A = np.zeros(shape + (3, 3))
        A[..., 0, 2] = j[0]
        A[..., 1, 2] = j[1]
        B = np.zeros(shape + (3, 1))
        B[..., 0, 0] = j[5]
        B[..., 1, 0] = j[6]
        B[..., 2, 0] = j[7]
        return A, B

    def speed(self, x):
        x = np.asarray(x, float)
        return np.full(x.shape[:-1], self.v_mps)

    def steady_state(self, kappa, v_mps=None):
        """(steering [rad], slip angle [rad]) on curvature kappa [1/m]; speed-independent here."""
        return steady_state_for_curvature(kappa, self.params)

    def reference(self, pose, kappa, v_mps=None, feedforward: bool = True):
        """Reference states (K, 3) and inputs (K, 1) for path points ``pose`` (K, 3) [x m, y m,
        heading rad] of curvature ``kappa`` (K,) [1/m] (the speed is the model's own)."""
        return _kinematic_reference(pose, kappa, self.params, feedforward, 1)


class KinematicBicycle4(_FromComponents):
    """Kinematic bicycle with speed as a state.

    x : (4,) [x m, y m, yaw rad, v m/s]; u : (2,) [delta rad, a m/s^2].
    """

    nx = 4
    nu = 2
    state_names = ("x", "y", "yaw", "v")
    input_names = ("steer", "accel")

    def __init__(self, params: KinematicParams = KinematicParams()):
        self.params = params

    def f_components(self, x, u, ns=np):
        """The equations on state / input components (see KinematicBicycle3.f_components)."""
        return (*kinematic_rhs(x[2], x[3], u[0], self.params.lq, self.params.lr_m, ns), u[1])

    def jacobians(self, x, u):
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        j = kinematic_jacobian_entries(x[..., 2], x[..., 3], u[..., 0], self.params.lq, self.params.lr_m, np)
        shape = x.shape[:-1]
        A = np.zeros(shape + (4, 4))
        A[..., 0, 2] = j[0]
        A[..., 1, 2] = j[1]
        A[..., 0, 3] = j[2]
        A[..., 1, 3] = j[3]
        A[..., 2, 3] = j[4]
        B = np.zeros(shape + (4, 2))
        B[..., 0, 0] = j[5]
        B[..., 1, 0] = j[6]
        B[..., 2, 0] = j[7]
        B[..., 3, 1] = 1.0
        return A, B

    def speed(self, x):
        return np.asarray(x, float)[..., 3]

    def steady_state(self, kappa, v_mps=None):
        """(steering [rad], slip angle [rad]) on curvature kappa [1/m]; speed-independent here."""
        return steady_state_for_curvature(kappa, self.params)

    def reference(self, pose, kappa, v_mps, feedforward: bool = True):
        """Reference states (K, 4) and inputs (K, 2) for path points ``pose`` (K, 3) [x m, y m,
        heading rad] of curvature ``kappa`` (K,) [1/m] driven at ``v_mps`` (K,) [m/s]."""
        xp, uref = _kinematic_reference(pose, kappa, self.params, feedforward, 2)
        xref = np.empty(xp.shape[:-1] + (4,))
        xref[..., :3] = xp
        xref[..., 3] = v_mps
        return xref, uref
