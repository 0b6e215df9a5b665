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


def steady_state_for_curvature(kappa, params: KinematicParams) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state (steering [rad], slip angle beta [rad]) that keeps the centre of gravity of
    the kinematic bicycle on a path of curvature kappa [1/m].

    The centre of gravity moves along ``yaw + beta``; from ``yaw_rate = v/lr sin(beta) = v kappa``:
    ``beta = asin(lr kappa)``, ``delta = atan(tan(beta) / lq)``; |lr kappa| is clipped below 1.
    """
    beta = np.arcsin(np.clip(params.lr_m * np.asarray(kappa, float), -0.999, 0.999))
    return np.arctan(np.tan(beta) / params.lq), beta


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


def _kinematic_rhs(yaw, v, delta, params: KinematicParams, ns):
    """x', y', yaw' of the kinematic bicycle (eqs. 1-4, 8) with math functions from ``ns``."""
    beta = ns.arctan(params.lq * ns.tan(delta))
    return v * ns.cos(yaw + beta), v * ns.sin(yaw + beta), v / params.lr_m * ns.sin(beta)


def _beta_and_derivative(delta: np.ndarray, lq: float) -> tuple[np.ndarray, np.ndarray]:
    """beta(delta) and d beta / d delta = lq / (cos^2 delta + lq^2 sin^2 delta) (eq. 11)."""
    beta = np.arctan(lq * np.tan(delta))
    s, c = np.sin(delta), np.cos(delta)
    dbeta = lq / (c * c + lq * lq * s * s)
    return beta, dbeta


class KinematicBicycle3:
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
        return _kinematic_rhs(x[2], self.v_mps, u[0], self.params, ns)

    def f(self, x, u):
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        return np.stack(self.f_components(_components(x), _components(u)), axis=-1)

    def jacobians(self, x, u):
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        beta, dbeta = _beta_and_derivative(u[..., 0], self.params.lq)
        v = self.v_mps
        ang = x[..., 2] + beta
        sa, ca = np.sin(ang), np.cos(ang)
        shape = x.shape[:-1]
        A = np.zeros(shape + (3, 3))
        A[..., 0, 2] = -v * sa
        A[..., 1, 2] = v * ca
        B = np.zeros(shape + (3, 1))
        B[..., 0, 0] = -v * sa * dbeta
        B[..., 1, 0] = v * ca * dbeta
        B[..., 2, 0] = v / self.params.lr_m * np.cos(beta) * dbeta
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


class KinematicBicycle4:
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
        return (*_kinematic_rhs(x[2], x[3], u[0], self.params, ns), u[1])

    def f(self, x, u):
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        return np.stack(self.f_components(_components(x), _components(u)), axis=-1)

    def jacobians(self, x, u):
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        beta, dbeta = _beta_and_derivative(u[..., 0], self.params.lq)
        v = x[..., 3]
        ang = x[..., 2] + beta
        sa, ca = np.sin(ang), np.cos(ang)
        shape = x.shape[:-1]
        A = np.zeros(shape + (4, 4))
        A[..., 0, 2] = -v * sa
        A[..., 0, 3] = ca
        A[..., 1, 2] = v * ca
        A[..., 1, 3] = sa
        A[..., 2, 3] = np.sin(beta) / self.params.lr_m
        B = np.zeros(shape + (4, 2))
        B[..., 0, 0] = -v * sa * dbeta
        B[..., 1, 0] = v * ca * dbeta
        B[..., 2, 0] = v / self.params.lr_m * np.cos(beta) * dbeta
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
