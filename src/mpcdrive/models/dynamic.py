"""Dynamic bicycle model (the paper's eqs. 20-49) with linear or Pacejka tires.

State ``x : (6,) [x m, y m, yaw rad, vx m/s, vy m/s, r rad/s]``: position of the centre of gravity
in the world frame, yaw, longitudinal and lateral velocity in the body frame, yaw rate.
Input ``u : (2,) [delta rad, a m/s^2]``: front steering angle and longitudinal (drive/brake)
acceleration command ``Fx / m``.

Body-frame equations (single track, zero bank angle)::

    vx' = a - Fyf sin(delta) / m + r vy
    vy' = (Fyf cos(delta) + Fyr) / m - r vx
    r'  = (lf Fyf cos(delta) - lr Fyr) / Iz
    x'  = vx cos(yaw) - vy sin(yaw);  y' = vx sin(yaw) + vy cos(yaw);  yaw' = r

Axle loads with longitudinal load transfer: ``Fzf = m (g lr - a h) / L``, ``Fzr = m (g lf + a h) / L``.

Tires (``tire="linear"``, the paper's form with its eq. 33 sign corrected)::

    alpha_f = delta - (vy + lf r) / vx,   alpha_r = -(vy - lr r) / vx
    Fy = mu C_S Fz alpha                  (cornering stiffness C_alpha = mu C_S Fz)

``tire="pacejka"`` (magic formula, slip angles with arctan)::

    alpha_f = delta - atan((vy + lf r) / vx),   alpha_r = -atan((vy - lr r) / vx)
    Fy = mu Fz sin(C atan(B alpha - E (B alpha - atan(B alpha)))),   B = C_S / C

so that both tire models have the same cornering stiffness at zero slip (``B C D = mu C_S Fz``).

Low speed: the slip angles divide by ``vx``, so as ``vx -> 0`` the model blends smoothly (a
smoothstep weight ``w`` from ``v_blend_low_mps`` to ``v_blend_high_mps``) into the kinematic
bicycle written in the same states: the pose moves with the kinematic velocities
``vy_k = vx lq tan(delta)``, ``r_k = vx tan(delta) / L`` and ``vy``, ``r`` relax towards them with
time constant ``kinematic_relax_s``. Below ``v_blend_low_mps`` the model *is* the kinematic bicycle
(no division by ``vx``); there is no NaN at zero or negative speed.

The equations and their analytic partial derivatives are the module functions
:func:`dynamic_rhs` and :func:`dynamic_rhs_and_partials` of a parameter sequence
(:func:`dynamic_parameters`) and a math namespace: :class:`DynamicBicycle` evaluates them on numpy
batches (or CasADi symbols), and the compiled controller compiles them as they stand.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .kinematic import _components

TireModel = Literal["linear", "pacejka"]


@dataclass(frozen=True)
class DynamicParams:
    """Parameters of the dynamic bicycle (SI units).

    lf_m, lr_m : centre of gravity -> front / rear axle [m]; mass_kg [kg]; yaw_inertia_kgm2 [kg m^2];
    friction : tire-road friction coefficient mu [-]; cs_front_per_rad, cs_rear_per_rad : cornering
    stiffness coefficients C_S [1/rad] (cornering stiffness per unit normal load and unit friction,
    the convention of the CommonRoad and F1TENTH single-track models); h_cg_m : height of the centre
    of gravity [m] (longitudinal load transfer; 0 disables it); pacejka_c, pacejka_e : magic-formula
    shape and curvature factors [-]; v_blend_low_mps, v_blend_high_mps : speeds [m/s] between which the
    model blends from kinematic to dynamic; kinematic_relax_s : time constant [s] with which vy and r
    follow their kinematic values at low speed; g_mps2 : gravity [m/s^2].

    Defaults: the F1TENTH gym's 1:10 car (m = 3.74 kg, Iz = 0.04712 kg m^2, lf = 0.15875 m,
    lr = 0.17145 m, mu = 1.0489, C_Sf = 4.718, C_Sr = 5.4562, h = 0.074 m) with the magic-formula
    shape factors of the CommonRoad tire set (C = 1.3507, E = -0.0074722).
    """

    lf_m: float = 0.15875
    lr_m: float = 0.17145
    mass_kg: float = 3.74
    yaw_inertia_kgm2: float = 0.04712
    friction: float = 1.0489
    cs_front_per_rad: float = 4.718
    cs_rear_per_rad: float = 5.4562
    h_cg_m: float = 0.074
    pacejka_c: float = 1.3507
    pacejka_e: float = -0.0074722
    v_blend_low_mps: float = 0.5
    v_blend_high_mps: float = 1.0
    kinematic_relax_s: float = 0.05
    g_mps2: float = 9.81

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not np.isfinite(v):
                raise ValueError(f"{f.name} must be finite, got {v}")
        for name in (
            "lf_m",
            "lr_m",
            "mass_kg",
            "yaw_inertia_kgm2",
            "friction",
            "cs_front_per_rad",
            "cs_rear_per_rad",
            "kinematic_relax_s",
            "g_mps2",
            "v_blend_high_mps",
        ):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if self.h_cg_m < 0:
            raise ValueError(f"h_cg_m must be >= 0, got {self.h_cg_m}")
        if not 0 < self.v_blend_low_mps < self.v_blend_high_mps:
            raise ValueError(
                f"need 0 < v_blend_low_mps < v_blend_high_mps, got {self.v_blend_low_mps}, {self.v_blend_high_mps}"
            )
        if not 0 < self.pacejka_c < 2:
            raise ValueError(f"pacejka_c must lie in (0, 2), got {self.pacejka_c}")
        if self.pacejka_e >= 1:
            raise ValueError(f"pacejka_e must be below 1, got {self.pacejka_e}")

    @property
    def wheelbase_m(self) -> float:
        return self.lf_m + self.lr_m

    @property
    def lq(self) -> float:
        """lr / (lf + lr)."""
        return self.lr_m / (self.lf_m + self.lr_m)

    @property
    def normal_load_front_n(self) -> float:
        """Static front axle load m g lr / L [N]."""
        return self.mass_kg * self.g_mps2 * self.lr_m / self.wheelbase_m

    @property
    def normal_load_rear_n(self) -> float:
        """Static rear axle load m g lf / L [N]."""
        return self.mass_kg * self.g_mps2 * self.lf_m / self.wheelbase_m

    @property
    def cornering_stiffness_front_n_per_rad(self) -> float:
        """Static front axle cornering stiffness C_alpha,f = mu C_Sf Fzf [N/rad]."""
        return self.friction * self.cs_front_per_rad * self.normal_load_front_n

    @property
    def cornering_stiffness_rear_n_per_rad(self) -> float:
        """Static rear axle cornering stiffness C_alpha,r = mu C_Sr Fzr [N/rad]."""
        return self.friction * self.cs_rear_per_rad * self.normal_load_rear_n

    @property
    def understeer_gradient_rad_per_mps2(self) -> float:
        """K_us = m / L (lr / C_alpha,f - lf / C_alpha,r) [rad / (m/s^2)]: steady-state steering
        ``delta = L kappa + K_us a_y`` of the linear-tire model (positive: understeer)."""
        p = self
        return (
            p.mass_kg
            / p.wheelbase_m
            * (p.lr_m / p.cornering_stiffness_front_n_per_rad - p.lf_m / p.cornering_stiffness_rear_n_per_rad)
        )

    def scaled(self, **factors: float) -> DynamicParams:
        """A copy with fields multiplied by factors, e.g. ``scaled(mass_kg=1.2)`` (+20 % mass)."""
        unknown = [k for k in factors if k not in {f.name for f in dataclasses.fields(self)}]
        if unknown:
            raise ValueError(f"unknown parameter(s) {', '.join(unknown)}")
        return dataclasses.replace(self, **{k: getattr(self, k) * float(v) for k, v in factors.items()})


# ------------------------------------------------------------------------------ tire curves
def _pacejka(alpha, B, C, E, ns):
    """Normalized magic formula sin(C atan(B a - E (B a - atan(B a)))) [-] of slip alpha [rad]."""
    z = B * alpha
    return ns.sin(C * ns.arctan(z - E * (z - ns.arctan(z))))


def _pacejka_and_slope(alpha, B, C, E, ns):
    """(normalized force, its derivative wrt alpha) with math namespace ``ns``."""
    z = B * alpha
    psi = z - E * (z - ns.arctan(z))
    dpsi = 1.0 - E * (1.0 - 1.0 / (1.0 + z * z))
    ang = C * ns.arctan(psi)
    return ns.sin(ang), ns.cos(ang) * C / (1.0 + psi * psi) * dpsi * B


def _pacejka_inverse(y, B, C, E):
    """Slip alpha [rad] with normalized force y in (-1, 1) on the rising branch of the curve."""
    psi = np.tan(np.arcsin(y) / C)
    if E == 0:
        return psi / B
    z = psi
    # Newton on z - E (z - atan z) = psi (monotone for E < 1); quadratic convergence from z = psi,
    # whose error is O(E): three steps reach machine precision for |E| < 0.1
    for i in range(30):
        g = z - E * (z - np.arctan(z)) - psi
        dg = 1.0 - E * (1.0 - 1.0 / (1.0 + z * z))
        step = g / dg
        z = z - step
        if i >= 2 and (abs(E) < 0.1 or np.max(np.abs(step), initial=0.0) < 1e-13):
            break
    return z / B


class _ScalarMath:
    """The math namespace of :meth:`DynamicBicycle.f_components` for plain floats (a single state
    evaluates ~20x faster with ``math`` than with numpy's per-call overhead)."""

    sin, cos, tan, arctan = (
        staticmethod(math.sin),
        staticmethod(math.cos),
        staticmethod(math.tan),
        staticmethod(math.atan),
    )
    fmax, fmin = staticmethod(max), staticmethod(min)


def _smoothstep(vx, lo, hi, ns):
    t = ns.fmin(ns.fmax((vx - lo) / (hi - lo), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


# ------------------------------------------------------------------------------ the equations
# The equations are module functions of a parameter sequence P (see dynamic_parameters) and a
# math namespace ns, so that numpy batches, CasADi and the compiled controller (numba, with numpy
# as ns) run the same definition.
#: secant iteration of the steady cornering state (``steady_state_full``, and models.compiled's
#: copy): it stops when every point's acceleration residual |G(a) - a| is below
#: STEADY_ACCEL_TOL_MPS2 [m/s^2], or after STEADY_SECANT_ITERATIONS. Near the grip limit of the
#: Pacejka tire it can run out of iterations with a large residual: there the result is where the
#: iteration stopped, not a fixed point.
STEADY_ACCEL_TOL_MPS2 = 1e-8
STEADY_SECANT_ITERATIONS = 12

_P_LF, _P_LR, _P_M, _P_IZ, _P_MU, _P_CSF, _P_CSR, _P_H, _P_C, _P_E, _P_VLO, _P_VHI, _P_TAU, _P_G, _P_PACEJKA = range(15)

#: (row, column) of the entries of df/dx and df/du that :func:`dynamic_rhs_and_partials` returns
#: (all others are zero)
DYNAMIC_A_ENTRIES = (
    (0, 2),
    (0, 3),
    (0, 4),
    (1, 2),
    (1, 3),
    (1, 4),
    (2, 3),
    (2, 5),
    (3, 3),
    (3, 4),
    (3, 5),
    (4, 3),
    (4, 4),
    (4, 5),
    (5, 3),
    (5, 4),
    (5, 5),
)
DYNAMIC_B_ENTRIES = ((0, 0), (1, 0), (2, 0), (3, 0), (3, 1), (4, 0), (4, 1), (5, 0), (5, 1))


def dynamic_parameters(params: DynamicParams, tire: TireModel) -> tuple[float, ...]:
    """The parameter sequence P of the equation functions: the fields of ``params`` in the order
    of the ``_P_*`` indices and 1.0 for Pacejka tires (0.0 linear)."""
    p = params
    return (
        p.lf_m,
        p.lr_m,
        p.mass_kg,
        p.yaw_inertia_kgm2,
        p.friction,
        p.cs_front_per_rad,
        p.cs_rear_per_rad,
        p.h_cg_m,
        p.pacejka_c,
        p.pacejka_e,
        p.v_blend_low_mps,
        p.v_blend_high_mps,
        p.kinematic_relax_s,
        p.g_mps2,
        1.0 if tire == "pacejka" else 0.0,
    )


def slip_speed_floor(P):
    """The speed [m/s] ``vx`` is floored at in the slip angles (below ``v_blend_low`` the dynamic
    part has no weight)."""
    return 0.5 * P[_P_VLO]


def axle_tire(alpha, front, P, ns):
    """(Fy / Fz, d(Fy / Fz) / d alpha) of the front (``front`` true) or rear axle at slip alpha [rad]."""
    cs = P[_P_CSF] if front else P[_P_CSR]
    if P[_P_PACEJKA] != 0.0:
        y, dy = _pacejka_and_slope(alpha, cs / P[_P_C], P[_P_C], P[_P_E], ns)
        return P[_P_MU] * y, P[_P_MU] * dy
    k = P[_P_MU] * cs
    return k * alpha, k


def dynamic_rhs(yaw, vx, vy, r, delta, a, P, ns):
    """The six state derivatives (module docstring) at states yaw [rad], vx, vy [m/s], r [rad/s]
    and inputs delta [rad], a [m/s^2]; parameters P (:func:`dynamic_parameters`), math namespace
    ``ns`` (numpy, CasADi, or numpy in compiled code)."""
    lf, lr, m = P[_P_LF], P[_P_LR], P[_P_M]
    L = lf + lr
    # dynamic part
    vxs = ns.fmax(vx, slip_speed_floor(P))
    Fzf = m * (P[_P_G] * lr - a * P[_P_H]) / L
    Fzr = m * (P[_P_G] * lf + a * P[_P_H]) / L
    if P[_P_PACEJKA] != 0.0:
        af = delta - ns.arctan((vy + lf * r) / vxs)
        ar = -ns.arctan((vy - lr * r) / vxs)
        Fyf = P[_P_MU] * Fzf * _pacejka(af, P[_P_CSF] / P[_P_C], P[_P_C], P[_P_E], ns)
        Fyr = P[_P_MU] * Fzr * _pacejka(ar, P[_P_CSR] / P[_P_C], P[_P_C], P[_P_E], ns)
    else:
        af = delta - (vy + lf * r) / vxs
        ar = -(vy - lr * r) / vxs
        Fyf = P[_P_MU] * P[_P_CSF] * Fzf * af
        Fyr = P[_P_MU] * P[_P_CSR] * Fzr * ar
    sd, cd = ns.sin(delta), ns.cos(delta)
    dvx_d = a - Fyf * sd / m + r * vy
    dvy_d = (Fyf * cd + Fyr) / m - r * vx
    dr_d = (lf * Fyf * cd - lr * Fyr) / P[_P_IZ]
    # kinematic part in the same states
    td = ns.tan(delta)
    lq = lr / L
    vy_k = vx * lq * td
    r_k = vx * td / L
    tau = P[_P_TAU]
    dvy_k = a * lq * td + (vy_k - vy) / tau
    dr_k = a * td / L + (r_k - r) / tau
    # blend
    w = _smoothstep(vx, P[_P_VLO], P[_P_VHI], ns)
    vy_p = w * vy + (1.0 - w) * vy_k
    r_p = w * r + (1.0 - w) * r_k
    c, s = ns.cos(yaw), ns.sin(yaw)
    return (
        vx * c - vy_p * s,
        vx * s + vy_p * c,
        r_p,
        w * dvx_d + (1.0 - w) * a,
        w * dvy_d + (1.0 - w) * dvy_k,
        w * dr_d + (1.0 - w) * dr_k,
    )


def dynamic_rhs_and_partials(yaw, vx, vy, r, delta, a, P, ns):
    """(f, A entries, B entries): the derivatives of :func:`dynamic_rhs` and their analytic
    partial derivatives, df/dx at :data:`DYNAMIC_A_ENTRIES` and df/du at
    :data:`DYNAMIC_B_ENTRIES` (exact wherever f is differentiable: the floor of vx at
    :func:`slip_speed_floor` and the blend corners are kinks). ``ns`` is numpy (arrays or, in
    compiled code, scalars)."""
    lf, lr, m, Iz = P[_P_LF], P[_P_LR], P[_P_M], P[_P_IZ]
    L = lf + lr
    v_eps = slip_speed_floor(P)
    # slip-angle arguments q = (vy +- l r) / vxs and their derivatives
    vxs = ns.fmax(vx, v_eps)
    dvxs = (vx > v_eps) * 1.0
    qf = (vy + lf * r) / vxs
    qr = (vy - lr * r) / vxs
    if P[_P_PACEJKA] != 0.0:
        gf, dgf = ns.arctan(qf), 1.0 / (1.0 + qf * qf)
        gr, dgr = ns.arctan(qr), 1.0 / (1.0 + qr * qr)
    else:
        gf, dgf = qf, 1.0
        gr, dgr = qr, 1.0
    af = delta - gf
    ar = -gr
    # d alpha / d (vx, vy, r)
    af_vx = dgf * qf / vxs * dvxs
    af_vy = -dgf / vxs
    af_r = -dgf * lf / vxs
    ar_vx = dgr * qr / vxs * dvxs
    ar_vy = -dgr / vxs
    ar_r = dgr * lr / vxs
    Fzf = m * (P[_P_G] * lr - a * P[_P_H]) / L
    Fzr = m * (P[_P_G] * lf + a * P[_P_H]) / L
    Fzf_a = -m * P[_P_H] / L
    Fzr_a = m * P[_P_H] / L
    nf, dnf = axle_tire(af, True, P, ns)
    nr, dnr = axle_tire(ar, False, P, ns)
    Fyf, Fyr = Fzf * nf, Fzr * nr
    kf, kr = Fzf * dnf, Fzr * dnr  # dFy / d alpha
    Fyf_vx, Fyf_vy, Fyf_r, Fyf_d, Fyf_a = kf * af_vx, kf * af_vy, kf * af_r, kf, Fzf_a * nf
    Fyr_vx, Fyr_vy, Fyr_r, Fyr_a = kr * ar_vx, kr * ar_vy, kr * ar_r, Fzr_a * nr
    sd, cd = ns.sin(delta), ns.cos(delta)
    # dynamic derivatives and their partials (vx, vy, r, delta, a)
    dvx_d = a - Fyf * sd / m + r * vy
    dvy_d = (Fyf * cd + Fyr) / m - r * vx
    dr_d = (lf * Fyf * cd - lr * Fyr) / Iz
    Dvx = (
        -sd / m * Fyf_vx,
        -sd / m * Fyf_vy + r,
        -sd / m * Fyf_r + vy,
        -(Fyf_d * sd + Fyf * cd) / m,
        1.0 - sd / m * Fyf_a,
    )
    Dvy = (
        (cd * Fyf_vx + Fyr_vx) / m - r,
        (cd * Fyf_vy + Fyr_vy) / m,
        (cd * Fyf_r + Fyr_r) / m - vx,
        (cd * Fyf_d - sd * Fyf) / m,
        (cd * Fyf_a + Fyr_a) / m,
    )
    Dr = (
        (lf * cd * Fyf_vx - lr * Fyr_vx) / Iz,
        (lf * cd * Fyf_vy - lr * Fyr_vy) / Iz,
        (lf * cd * Fyf_r - lr * Fyr_r) / Iz,
        lf * (cd * Fyf_d - sd * Fyf) / Iz,
        (lf * cd * Fyf_a - lr * Fyr_a) / Iz,
    )
    # kinematic part
    td = ns.tan(delta)
    sec2 = 1.0 + td * td
    lq, tau = lr / L, P[_P_TAU]
    vy_k = vx * lq * td
    r_k = vx * td / L
    dvy_k = a * lq * td + (vy_k - vy) / tau
    dr_k = a * td / L + (r_k - r) / tau
    Kvy = (lq * td / tau, -1.0 / tau, 0.0, (a + vx / tau) * lq * sec2, lq * td)
    Kr = (td / (L * tau), 0.0, -1.0 / tau, (a + vx / tau) * sec2 / L, td / L)
    # blend weight w (the smoothstep) and its derivative (zero outside the blend, where t is 0 or 1)
    lo, hi = P[_P_VLO], P[_P_VHI]
    t = ns.fmin(ns.fmax((vx - lo) / (hi - lo), 0.0), 1.0)
    w = t * t * (3.0 - 2.0 * t)
    dw = 6.0 * t * (1.0 - t) / (hi - lo)
    W = 1.0 - w
    # blended partials (vx, vy, r, delta, a); the kinematic vx' = a has the partials (0, 0, 0, 0, 1)
    Bvx = (w * Dvx[0] + dw * (dvx_d - a), w * Dvx[1], w * Dvx[2], w * Dvx[3], w * Dvx[4] + W)
    Bvy = (
        w * Dvy[0] + W * Kvy[0] + dw * (dvy_d - dvy_k),
        w * Dvy[1] + W * Kvy[1],
        w * Dvy[2] + W * Kvy[2],
        w * Dvy[3] + W * Kvy[3],
        w * Dvy[4] + W * Kvy[4],
    )
    Br = (
        w * Dr[0] + W * Kr[0] + dw * (dr_d - dr_k),
        w * Dr[1] + W * Kr[1],
        w * Dr[2] + W * Kr[2],
        w * Dr[3] + W * Kr[3],
        w * Dr[4] + W * Kr[4],
    )
    # pose velocities
    vy_p = w * vy + W * vy_k
    vyp_vx = dw * (vy - vy_k) + W * lq * td
    vyp_d = W * vx * lq * sec2
    rp_vx = dw * (r - r_k) + W * td / L
    rp_d = W * vx * sec2 / L
    c, s = ns.cos(yaw), ns.sin(yaw)
    f = (
        vx * c - vy_p * s,
        vx * s + vy_p * c,
        w * r + W * r_k,
        w * dvx_d + W * a,
        w * dvy_d + W * dvy_k,
        w * dr_d + W * dr_k,
    )
    A = (
        -vx * s - vy_p * c,
        c - s * vyp_vx,
        -s * w,
        vx * c - vy_p * s,
        s + c * vyp_vx,
        c * w,
        rp_vx,
        w,
        Bvx[0],
        Bvx[1],
        Bvx[2],
        Bvy[0],
        Bvy[1],
        Bvy[2],
        Br[0],
        Br[1],
        Br[2],
    )
    B = (-s * vyp_d, c * vyp_d, rp_d, Bvx[3], Bvx[4], Bvy[3], Bvy[4], Br[3], Br[4])
    return f, A, B


class DynamicBicycle:
    """Dynamic bicycle with ``tire`` ``"linear"`` (the paper's) or ``"pacejka"`` tires.

    x : (6,) [x m, y m, yaw rad, vx m/s, vy m/s, r rad/s]; u : (2,) [delta rad, a m/s^2].
    See the module docstring for the equations.
    """

    nx = 6
    nu = 2
    state_names = ("x", "y", "yaw", "vx", "vy", "r")
    input_names = ("steer", "accel")

    def __init__(self, params: DynamicParams = DynamicParams(), tire: TireModel = "pacejka"):
        if tire not in ("linear", "pacejka"):
            raise ValueError(f"tire must be 'linear' or 'pacejka', got {tire!r}")
        self.params = params
        self.tire = tire
        p = params
        #: the parameter sequence of the equation functions (:func:`dynamic_parameters`)
        self._P = dynamic_parameters(params, tire)
        self._Bf = p.cs_front_per_rad / p.pacejka_c
        self._Br = p.cs_rear_per_rad / p.pacejka_c
        self._v_eps = slip_speed_floor(self._P)

    def __repr__(self) -> str:
        return f"DynamicBicycle(tire={self.tire!r}, params={self.params!r})"

    # -- the single definition of the equations -------------------------------------------------
    def f_components(self, x, u, ns=np):
        """The equations on sequences of state / input components with math namespace ``ns``
        (numpy or CasADi); returns the six derivatives. Serves :meth:`f` and symbolic backends."""
        return dynamic_rhs(x[2], x[3], x[4], x[5], u[0], u[1], self._P, ns)

    def f(self, x, u):
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        if x.ndim == 1 and u.ndim == 1:  # a single state: plain floats are much faster
            return np.array(self.f_components(x.tolist(), u.tolist(), _ScalarMath))
        return np.stack(self.f_components(_components(x), _components(u)), axis=-1)

    # -- analytic Jacobians ---------------------------------------------------------------------
    def _tire(self, alpha, which: str):
        """(Fy / Fz, d(Fy / Fz) / d alpha) of the front or rear axle."""
        n, dn = axle_tire(alpha, which == "f", self._P, np)
        return n, np.broadcast_to(dn, np.shape(alpha))

    def jacobians(self, x, u):
        """Analytic (df/dx (..., 6, 6), df/du (..., 6, 2)); exact derivatives of :meth:`f` wherever
        it is differentiable (the max at ``vx = v_blend_low / 2`` and the blend corners are kinks)."""
        _, A, B = self.f_and_jacobians(x, u)
        return A, B

    def f_and_jacobians(self, x, u):
        """(f (..., 6), df/dx (..., 6, 6), df/du (..., 6, 2)) in one pass (shared intermediates):
        :func:`dynamic_rhs_and_partials` placed in arrays."""
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        fs, a_entries, b_entries = dynamic_rhs_and_partials(
            x[..., 2], x[..., 3], x[..., 4], x[..., 5], u[..., 0], u[..., 1], self._P, np
        )
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1])
        A = np.zeros(shape + (6, 6))
        B = np.zeros(shape + (6, 2))
        for (i, j), value in zip(DYNAMIC_A_ENTRIES, a_entries):
            A[..., i, j] = value
        for (i, j), value in zip(DYNAMIC_B_ENTRIES, b_entries):
            B[..., i, j] = value
        f = np.empty(shape + (6,))
        for i, value in enumerate(fs):
            f[..., i] = value
        return f, A, B

    # -- helpers ----------------------------------------------------------------------------
    def speed(self, x):
        """Speed of the centre of gravity hypot(vx, vy) [m/s]."""
        x = np.asarray(x, float)
        return np.hypot(x[..., 3], x[..., 4])

    def blend_weight(self, vx):
        """Weight [0, 1] of the dynamic part at longitudinal speed vx [m/s] (0: kinematic)."""
        p = self.params
        return _smoothstep(np.asarray(vx, float), p.v_blend_low_mps, p.v_blend_high_mps, np)

    def _inverse_tire(self, n, which: str):
        """Slip angle [rad] giving normalized force Fy / Fz = n (clipped below the tire's peak)."""
        p = self.params
        if self.tire == "linear":
            cs = p.cs_front_per_rad if which == "f" else p.cs_rear_per_rad
            return n / (p.friction * cs)
        B = self._Br if which == "r" else self._Bf
        y = np.clip(n / p.friction, -0.999, 0.999)
        return _pacejka_inverse(y, B, p.pacejka_c, p.pacejka_e)

    def steady_state_full(self, kappa, v_mps):
        """Steady cornering (steering, slip, drive acceleration); see :meth:`steady_state_residual`."""
        delta, beta, a, _ = self.steady_state_residual(kappa, v_mps)
        return delta, beta, a

    def steady_state_residual(self, kappa, v_mps):
        """Steady cornering of the centre of gravity on curvature kappa [1/m] at speed v [m/s].

        Returns ``(delta [rad], beta [rad], accel [m/s^2], residual [m/s^2])``: steering, body slip
        angle (velocity direction minus yaw; the yaw trails the path heading by beta), the drive
        acceleration that holds the speed (it balances the drag of the front lateral force) and
        |G(a) - a| of the secant's last evaluation (below STEADY_ACCEL_TOL_MPS2 where the iteration
        converged). Beyond the tires' grip the force demand is clipped at the peak (no steady state
        exists there). At low speed the result blends into the kinematic steady state like the
        model does.
        """
        p = self.params
        kappa = np.asarray(kappa, float)
        v = np.broadcast_to(np.asarray(v_mps, float), kappa.shape).astype(float)
        m, L, lf, lr = p.mass_kg, p.wheelbase_m, p.lf_m, p.lr_m
        r = v * kappa
        gf_of = (lambda q: q) if self.tire == "linear" else np.arctan
        qr_of = (lambda al: -al) if self.tire == "linear" else (lambda al: np.tan(-al))

        def solve_given_accel(a, beta, delta):
            """Slip and steering for a given drive acceleration (which sets the axle loads);
            returns the acceleration they require, beta and delta."""
            Fzf = m * (p.g_mps2 * lr - a * p.h_cg_m) / L
            Fzr = m * (p.g_mps2 * lf + a * p.h_cg_m) / L
            for _ in range(2):  # beta: rear axle force m ay lf / L, weakly dependent on beta via vx
                vx = np.maximum(v * np.cos(beta), self._v_eps)
                ar = self._inverse_tire(m * r * vx * lf / (L * Fzr), "r")
                beta = np.arctan2(qr_of(ar) * vx + lr * r, vx)  # tan(beta) = vy / vx, vy = vx qr + lr r
            vx = np.maximum(v * np.cos(beta), self._v_eps)
            vy = v * np.sin(beta)
            gf = gf_of((vy + lf * r) / vx)
            n0 = m * r * vx * lr / (L * Fzf)  # front Fy / Fz needed at cos(delta) = 1
            for _ in range(3):  # Newton on delta - alpha_f(n0 / cos(delta)) - gf = 0
                n = n0 / np.cos(delta)
                af = self._inverse_tire(n, "f")
                _, slope = self._tire(af, "f")
                dg = 1.0 - n * np.tan(delta) / np.maximum(slope, 1e-9)
                delta = delta - (delta - af - gf) / np.where(np.abs(dg) > 0.1, dg, 1.0)
            return n0 / np.cos(delta) * Fzf * np.sin(delta) / m - r * vy, beta, delta

        # the load transfer couples the acceleration back: secant iteration on a = G(a)
        beta = np.zeros_like(kappa)
        delta = L * kappa
        a0 = np.zeros_like(kappa)
        g0, beta, delta = solve_given_accel(a0, beta, delta)
        a1 = g0
        for _ in range(STEADY_SECANT_ITERATIONS):
            g1, beta, delta = solve_given_accel(a1, beta, delta)
            res0, res1 = g0 - a0, g1 - a1
            if np.max(np.abs(res1), initial=0.0) < STEADY_ACCEL_TOL_MPS2:  # steering then exact to ~1e-10 rad
                break
            den = res1 - res0
            ok = np.abs(den) > 1e-14
            a_next = np.where(ok, a1 - res1 * (a1 - a0) / np.where(ok, den, 1.0), g1)
            a0, g0, a1 = a1, g1, a_next
        a = a1
        residual = np.abs(res1)
        # kinematic steady state and the blend
        beta_k = np.arcsin(np.clip(lr * kappa, -0.999, 0.999))
        delta_k = np.arctan(np.tan(beta_k) / p.lq)
        w = self.blend_weight(v * np.cos(beta))
        return w * delta + (1 - w) * delta_k, w * beta + (1 - w) * beta_k, w * a, residual

    def steady_state(self, kappa, v_mps=None):
        """(steering [rad], body slip angle [rad]) of steady cornering; see :meth:`steady_state_full`."""
        if v_mps is None:
            raise ValueError("the dynamic model's steady state depends on the speed: pass v_mps")
        delta, beta, _ = self.steady_state_full(kappa, v_mps)
        return delta, beta

    def reference(self, pose, kappa, v_mps, feedforward: bool = True):
        """Reference states and inputs for path points.

        pose : (K, 3) path points [x m, y m, heading rad]; kappa : (K,) curvature [1/m];
        v_mps : (K,) speed along the path [m/s]. Returns ``(xref (K, 6), uref (K, 2))``: with
        ``feedforward`` the steady cornering state (yaw = heading - beta, vx = v cos beta,
        vy = v sin beta, r = v kappa) and its inputs; without, the path heading, vx = v, vy = 0,
        r = v kappa and zero inputs.
        """
        pose = np.asarray(pose, float)
        kappa = np.asarray(kappa, float)
        v = np.broadcast_to(np.asarray(v_mps, float), kappa.shape)
        xref = np.empty(kappa.shape + (6,))
        uref = np.zeros(kappa.shape + (2,))
        xref[..., :3] = pose
        xref[..., 5] = v * kappa
        if feedforward:
            delta, beta, a = self.steady_state_full(kappa, v)
            xref[..., 2] -= beta
            xref[..., 3] = v * np.cos(beta)
            xref[..., 4] = v * np.sin(beta)
            uref[..., 0] = delta
            uref[..., 1] = a
        else:
            xref[..., 3] = v
            xref[..., 4] = 0.0
        return xref, uref
