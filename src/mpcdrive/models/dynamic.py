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
        for name in ("lf_m", "lr_m", "mass_kg", "yaw_inertia_kgm2", "friction", "cs_front_per_rad",
                     "cs_rear_per_rad", "kinematic_relax_s", "g_mps2", "v_blend_high_mps"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if self.h_cg_m < 0:
            raise ValueError(f"h_cg_m must be >= 0, got {self.h_cg_m}")
        if not 0 < self.v_blend_low_mps < self.v_blend_high_mps:
            raise ValueError(
                f"need 0 < v_blend_low_mps < v_blend_high_mps, got {self.v_blend_low_mps}, {self.v_blend_high_mps}")
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
        return p.mass_kg / p.wheelbase_m * (p.lr_m / p.cornering_stiffness_front_n_per_rad
                                            - p.lf_m / p.cornering_stiffness_rear_n_per_rad)

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


def _pacejka_and_slope(alpha, B, C, E):
    """(normalized force, its derivative wrt alpha) for numpy arrays."""
    z = B * alpha
    psi = z - E * (z - np.arctan(z))
    dpsi = 1.0 - E * (1.0 - 1.0 / (1.0 + z * z))
    ang = C * np.arctan(psi)
    return np.sin(ang), np.cos(ang) * C / (1.0 + psi * psi) * dpsi * B


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

    sin, cos, tan, arctan = staticmethod(math.sin), staticmethod(math.cos), staticmethod(math.tan), staticmethod(math.atan)
    fmax, fmin = staticmethod(max), staticmethod(min)


def _smoothstep(vx, lo, hi, ns):
    t = ns.fmin(ns.fmax((vx - lo) / (hi - lo), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


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
        self._Bf = p.cs_front_per_rad / p.pacejka_c
        self._Br = p.cs_rear_per_rad / p.pacejka_c
        # slip angles divide by max(vx, v_eps); below v_blend_low the dynamic part has no weight
        self._v_eps = 0.5 * p.v_blend_low_mps

    def __repr__(self) -> str:
        return f"DynamicBicycle(tire={self.tire!r}, params={self.params!r})"

    # -- the single definition of the equations -------------------------------------------------
    def f_components(self, x, u, ns=np):
        """The equations on sequences of state / input components with math namespace ``ns``
        (numpy or CasADi); returns the six derivatives. Serves :meth:`f` and symbolic backends."""
        p = self.params
        yaw, vx, vy, r = x[2], x[3], x[4], x[5]
        delta, a = u[0], u[1]
        m, L, lf, lr = p.mass_kg, p.wheelbase_m, p.lf_m, p.lr_m
        # dynamic part
        vxs = ns.fmax(vx, self._v_eps)
        Fzf = m * (p.g_mps2 * lr - a * p.h_cg_m) / L
        Fzr = m * (p.g_mps2 * lf + a * p.h_cg_m) / L
        if self.tire == "linear":
            af = delta - (vy + lf * r) / vxs
            ar = -(vy - lr * r) / vxs
            Fyf = p.friction * p.cs_front_per_rad * Fzf * af
            Fyr = p.friction * p.cs_rear_per_rad * Fzr * ar
        else:
            af = delta - ns.arctan((vy + lf * r) / vxs)
            ar = -ns.arctan((vy - lr * r) / vxs)
            Fyf = p.friction * Fzf * _pacejka(af, self._Bf, p.pacejka_c, p.pacejka_e, ns)
            Fyr = p.friction * Fzr * _pacejka(ar, self._Br, p.pacejka_c, p.pacejka_e, ns)
        sd, cd = ns.sin(delta), ns.cos(delta)
        dvx_d = a - Fyf * sd / m + r * vy
        dvy_d = (Fyf * cd + Fyr) / m - r * vx
        dr_d = (lf * Fyf * cd - lr * Fyr) / p.yaw_inertia_kgm2
        # kinematic part in the same states
        td = ns.tan(delta)
        vy_k = vx * p.lq * td
        r_k = vx * td / L
        tau = p.kinematic_relax_s
        dvy_k = a * p.lq * td + (vy_k - vy) / tau
        dr_k = a * td / L + (r_k - r) / tau
        # blend
        w = _smoothstep(vx, p.v_blend_low_mps, p.v_blend_high_mps, ns)
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

    def f(self, x, u):
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        if x.ndim == 1 and u.ndim == 1:  # a single state: plain floats are much faster
            return np.array(self.f_components(x.tolist(), u.tolist(), _ScalarMath))
        return np.stack(self.f_components(_components(x), _components(u)), axis=-1)

    # -- analytic Jacobians ---------------------------------------------------------------------
    def _tire(self, alpha, which: str):
        """(Fy / Fz, d(Fy / Fz) / d alpha) of the front or rear axle."""
        p = self.params
        if self.tire == "linear":
            cs = p.cs_front_per_rad if which == "f" else p.cs_rear_per_rad
            k = p.friction * cs
            return k * alpha, np.full_like(alpha, k)
        B = self._Bf if which == "f" else self._Br
        y, dy = _pacejka_and_slope(alpha, B, p.pacejka_c, p.pacejka_e)
        return p.friction * y, p.friction * dy

    def jacobians(self, x, u):
        """Analytic (df/dx (..., 6, 6), df/du (..., 6, 2)); exact derivatives of :meth:`f` wherever
        it is differentiable (the max at ``vx = v_blend_low / 2`` and the blend corners are kinks)."""
        _, A, B = self.f_and_jacobians(x, u)
        return A, B

    def f_and_jacobians(self, x, u):
        """(f (..., 6), df/dx (..., 6, 6), df/du (..., 6, 2)) in one pass (shared intermediates)."""
        x = np.asarray(x, float)
        u = np.asarray(u, float)
        p = self.params
        yaw, vx, vy, r = x[..., 2], x[..., 3], x[..., 4], x[..., 5]
        delta, a = u[..., 0], u[..., 1]
        m, L, lf, lr, Iz = p.mass_kg, p.wheelbase_m, p.lf_m, p.lr_m, p.yaw_inertia_kgm2
        # slip-angle arguments q = (vy +- l r) / vxs and their derivatives
        vxs = np.maximum(vx, self._v_eps)
        dvxs = (vx > self._v_eps).astype(float)
        qf = (vy + lf * r) / vxs
        qr = (vy - lr * r) / vxs
        if self.tire == "linear":
            gf, dgf = qf, np.ones_like(qf)
            gr, dgr = qr, np.ones_like(qr)
        else:
            gf, dgf = np.arctan(qf), 1.0 / (1.0 + qf * qf)
            gr, dgr = np.arctan(qr), 1.0 / (1.0 + qr * qr)
        af = delta - gf
        ar = -gr
        # d alpha / d (vx, vy, r)
        af_vx = dgf * qf / vxs * dvxs
        af_vy = -dgf / vxs
        af_r = -dgf * lf / vxs
        ar_vx = dgr * qr / vxs * dvxs
        ar_vy = -dgr / vxs
        ar_r = dgr * lr / vxs
        Fzf = m * (p.g_mps2 * lr - a * p.h_cg_m) / L
        Fzr = m * (p.g_mps2 * lf + a * p.h_cg_m) / L
        Fzf_a = -m * p.h_cg_m / L
        Fzr_a = m * p.h_cg_m / L
        nf, dnf = self._tire(af, "f")
        nr, dnr = self._tire(ar, "r")
        Fyf, Fyr = Fzf * nf, Fzr * nr
        kf, kr = Fzf * dnf, Fzr * dnr  # dFy / d alpha
        Fyf_vx, Fyf_vy, Fyf_r, Fyf_d, Fyf_a = kf * af_vx, kf * af_vy, kf * af_r, kf, Fzf_a * nf
        Fyr_vx, Fyr_vy, Fyr_r, Fyr_a = kr * ar_vx, kr * ar_vy, kr * ar_r, Fzr_a * nr
        sd, cd = np.sin(delta), np.cos(delta)
        # dynamic derivatives and their partials (vx, vy, r, delta, a)
        dvx_d = a - Fyf * sd / m + r * vy
        dvy_d = (Fyf * cd + Fyr) / m - r * vx
        dr_d = (lf * Fyf * cd - lr * Fyr) / Iz
        Dvx = (-sd / m * Fyf_vx, -sd / m * Fyf_vy + r, -sd / m * Fyf_r + vy,
               -(Fyf_d * sd + Fyf * cd) / m, 1.0 - sd / m * Fyf_a)
        Dvy = ((cd * Fyf_vx + Fyr_vx) / m - r, (cd * Fyf_vy + Fyr_vy) / m, (cd * Fyf_r + Fyr_r) / m - vx,
               (cd * Fyf_d - sd * Fyf) / m, (cd * Fyf_a + Fyr_a) / m)
        Dr = ((lf * cd * Fyf_vx - lr * Fyr_vx) / Iz, (lf * cd * Fyf_vy - lr * Fyr_vy) / Iz,
              (lf * cd * Fyf_r - lr * Fyr_r) / Iz, lf * (cd * Fyf_d - sd * Fyf) / Iz,
              (lf * cd * Fyf_a - lr * Fyr_a) / Iz)
        # kinematic part
        td = np.tan(delta)
        sec2 = 1.0 + td * td
        lq, tau = p.lq, p.kinematic_relax_s
        vy_k = vx * lq * td
        r_k = vx * td / L
        dvy_k = a * lq * td + (vy_k - vy) / tau
        dr_k = a * td / L + (r_k - r) / tau
        zero = np.zeros_like(vx)
        Kvx = (zero, zero, zero, zero, np.ones_like(vx))
        Kvy = (lq * td / tau, np.full_like(vx, -1.0 / tau), zero, (a + vx / tau) * lq * sec2, lq * td)
        Kr = (td / (L * tau), zero, np.full_like(vx, -1.0 / tau), (a + vx / tau) * sec2 / L, td / L)
        # blend weight
        lo, hi = p.v_blend_low_mps, p.v_blend_high_mps
        t = np.clip((vx - lo) / (hi - lo), 0.0, 1.0)
        w = t * t * (3.0 - 2.0 * t)
        dw = np.where((vx > lo) & (vx < hi), 6.0 * t * (1.0 - t) / (hi - lo), 0.0)
        W = 1.0 - w

        def blend(D, K, gd, gk):
            out = [w * dd + W * kk for dd, kk in zip(D, K)]
            out[0] = out[0] + dw * (gd - gk)
            return out

        Bvx = blend(Dvx, Kvx, dvx_d, a)
        Bvy = blend(Dvy, Kvy, dvy_d, dvy_k)
        Br = blend(Dr, Kr, dr_d, dr_k)
        # pose velocities
        vy_p = w * vy + W * vy_k
        vyp_vx = dw * (vy - vy_k) + W * lq * td
        vyp_vy = w
        vyp_d = W * vx * lq * sec2
        rp_vx = dw * (r - r_k) + W * td / L
        rp_r = w
        rp_d = W * vx * sec2 / L
        c, s = np.cos(yaw), np.sin(yaw)
        shape = x.shape[:-1]
        A = np.zeros(shape + (6, 6))
        B = np.zeros(shape + (6, 2))
        A[..., 0, 2] = -vx * s - vy_p * c
        A[..., 0, 3] = c - s * vyp_vx
        A[..., 0, 4] = -s * vyp_vy
        B[..., 0, 0] = -s * vyp_d
        A[..., 1, 2] = vx * c - vy_p * s
        A[..., 1, 3] = s + c * vyp_vx
        A[..., 1, 4] = c * vyp_vy
        B[..., 1, 0] = c * vyp_d
        A[..., 2, 3] = rp_vx
        A[..., 2, 5] = rp_r
        B[..., 2, 0] = rp_d
        for row, D in ((3, Bvx), (4, Bvy), (5, Br)):
            A[..., row, 3] = D[0]
            A[..., row, 4] = D[1]
            A[..., row, 5] = D[2]
            B[..., row, 0] = D[3]
            B[..., row, 1] = D[4]
        f = np.empty(shape + (6,))
        f[..., 0] = vx * c - vy_p * s
        f[..., 1] = vx * s + vy_p * c
        f[..., 2] = w * r + W * r_k
        f[..., 3] = w * dvx_d + W * a
        f[..., 4] = w * dvy_d + W * dvy_k
        f[..., 5] = w * dr_d + W * dr_k
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
        """Steady cornering of the centre of gravity on curvature kappa [1/m] at speed v [m/s].

        Returns ``(delta [rad], beta [rad], accel [m/s^2])``: steering, body slip angle (velocity
        direction minus yaw; the yaw trails the path heading by beta) and the drive acceleration
        that holds the speed (it balances the drag of the front lateral force). Beyond the tires'
        grip the force demand is clipped at the peak (no steady state exists there). At low speed
        the result blends into the kinematic steady state like the model does.
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
        for _ in range(12):
            g1, beta, delta = solve_given_accel(a1, beta, delta)
            res0, res1 = g0 - a0, g1 - a1
            if np.max(np.abs(res1), initial=0.0) < 1e-8:  # m/s^2: steering then exact to ~1e-10 rad
                break
            den = res1 - res0
            ok = np.abs(den) > 1e-14
            a_next = np.where(ok, a1 - res1 * (a1 - a0) / np.where(ok, den, 1.0), g1)
            a0, g0, a1 = a1, g1, a_next
        a = a1
        # kinematic steady state and the blend
        beta_k = np.arcsin(np.clip(lr * kappa, -0.999, 0.999))
        delta_k = np.arctan(np.tan(beta_k) / p.lq)
        w = self.blend_weight(v * np.cos(beta))
        return w * delta + (1 - w) * delta_k, w * beta + (1 - w) * beta_k, w * a

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
