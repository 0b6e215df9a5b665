"""Reference speed along a path, limited by curvature, friction and acceleration.

On a grid of arc lengths the speed is first capped by the lateral-acceleration limit
``v <= sqrt(a_lat,max / |kappa|)`` (``a_lat,max = mu g`` times a margin) and by ``v_max``; a forward
pass then limits acceleration, ``v_{i+1}^2 <= v_i^2 + 2 a_max ds``, and a backward pass limits
braking, ``v_i^2 <= v_{i+1}^2 + 2 b_max ds``, so the car slows down *before* a bend. With
``friction_circle`` the longitudinal limits shrink with the lateral acceleration in use,
``a_long <= a_max sqrt(1 - (v^2 kappa / a_lat,max)^2)``. On a closed path both passes start at the
slowest point of the lap, which makes the profile periodic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from .base import ReferencePath


class SpeedReference(Protocol):
    """What a controller needs of a reference speed along a path: ``speed(s_m)`` [m/s] at arc
    length(s) ``s_m`` [m] (a float for a scalar, an array for an array). :class:`ConstantSpeed` and
    :class:`SpeedProfile` have it, and also ``arc_length_after(s0_m, t_s)``, which a controller
    uses when present."""

    def speed(self, s_m: npt.ArrayLike) -> np.ndarray | float: ...


@dataclass(frozen=True)
class ConstantSpeed:
    """The same reference speed ``v_mps`` [m/s] everywhere (the interface of :class:`SpeedProfile`)."""

    v_mps: float

    def __post_init__(self):
        if not math.isfinite(self.v_mps):
            raise ValueError(f"v_mps must be finite, got {self.v_mps}")

    def speed(self, s_m: npt.ArrayLike) -> np.ndarray | float:
        """Reference speed [m/s] at arc length(s) s_m [m]."""
        return np.full(np.shape(s_m), self.v_mps) if np.ndim(s_m) else self.v_mps

    def arc_length_after(self, s0_m: float, t_s) -> np.ndarray:
        """Arc length [m] reached from ``s0_m`` after time(s) ``t_s`` [s] at this speed."""
        return s0_m + self.v_mps * np.asarray(t_s, float)


def segment_times(ds_m, v_mps: np.ndarray) -> np.ndarray:
    """The time [s] each step ``ds_m`` [m] (a scalar or one per step) between the speeds
    ``v_mps`` (M,) [m/s] takes at constant acceleration (``v^2`` linear in s): ``2 ds / (v_i +
    v_{i+1})``, (M - 1,); ``inf`` for a step between two standstills."""
    vs = v_mps[1:] + v_mps[:-1]
    return np.where(vs > 0, 2.0 * ds_m / np.maximum(vs, 1e-300), np.inf)


#: the distance [m] over which the change of the path's curvature is measured for the steering
#: rate's speed limit (either side of each point)
CURVATURE_RATE_BASE_M = 2.0


class SpeedProfile:
    """Speed profile of ``path``.

    lateral_accel_max_mps2 : largest lateral acceleration [m/s^2] (e.g. 0.8 * mu * g);
    accel_max_mps2, decel_max_mps2 : largest forward acceleration and braking deceleration
    [m/s^2] (both positive); v_max_mps : top speed [m/s]; v_start_mps, v_end_mps : speed at the start
    and at the end of an open path (None: free); s_start_m : where the start is [m] (the car's
    arc length when the path begins behind it: the profile holds ``v_start_mps`` up to there and
    its clock starts there, ``time_at(s_start_m) = 0``); top_speed_until : ``(s_until_m, v_mps)`` pairs,
    each capping the top speed at ``v_mps`` [m/s] on the arc lengths up to ``s_until_m`` [m] (an
    approach slower than ``v_max_mps``: e.g. to reach a goal region later but at its speed; the
    forward pass then accelerates to ``v_max_mps`` after ``s_until_m``); ds_m : grid spacing [m]; curvature_window_m : the
    curvature used at s is the largest |kappa| within +- this distance (guards against sampling a
    bend between grid points); friction_circle : share the friction between lateral and longitudinal
    acceleration; curvature_rate_max_1pms : the fastest change of path curvature the vehicle can
    steer [1/(m s)] (its steering rate over its wheelbase): the speed is at most this over the
    path's |d kappa / d s| (a bend that sets in within a few metres is entered slowly enough for
    the steering to follow; None: no such limit).

    Attributes ``s_m`` (M,) and ``v_mps`` (M,) hold the grid; :meth:`speed` interpolates it
    (periodically on a closed path; clamped to the end values on an open one).
    """

    def __init__(
        self,
        path: ReferencePath,
        lateral_accel_max_mps2: float,
        accel_max_mps2: float,
        decel_max_mps2: float,
        v_max_mps: float,
        *,
        v_start_mps: float | None = None,
        v_end_mps: float | None = None,
        ds_m: float | None = None,
        curvature_window_m: float = 0.0,
        friction_circle: bool = True,
        s_start_m: float = 0.0,
        top_speed_until: tuple[tuple[float, float], ...] = (),
        curvature_rate_max_1pms: float | None = None,
    ):
        for name, val in (
            ("lateral_accel_max_mps2", lateral_accel_max_mps2),
            ("accel_max_mps2", accel_max_mps2),
            ("decel_max_mps2", decel_max_mps2),
            ("v_max_mps", v_max_mps),
        ):
            if not (math.isfinite(val) and val > 0):
                raise ValueError(f"{name} must be a positive finite number, got {val}")
        for name, v_opt in (("v_start_mps", v_start_mps), ("v_end_mps", v_end_mps)):
            if v_opt is not None and not (math.isfinite(v_opt) and v_opt >= 0):
                raise ValueError(f"{name} must be >= 0, got {v_opt}")
        if curvature_rate_max_1pms is not None and not (
            math.isfinite(curvature_rate_max_1pms) and curvature_rate_max_1pms > 0
        ):
            raise ValueError(f"curvature_rate_max_1pms must be a positive number, got {curvature_rate_max_1pms}")
        if curvature_window_m < 0 or not math.isfinite(curvature_window_m):
            raise ValueError(f"curvature_window_m must be >= 0, got {curvature_window_m}")
        if not (math.isfinite(s_start_m) and 0.0 <= s_start_m <= float(path.length_m)):
            raise ValueError(f"s_start_m must lie on the path [0, {float(path.length_m):.3f}] m, got {s_start_m}")
        if path.closed and s_start_m != 0.0:
            raise ValueError("s_start_m is for open paths")
        caps = tuple((float(su), float(vc)) for su, vc in top_speed_until)
        for su, vc in caps:
            if not (math.isfinite(su) and math.isfinite(vc) and vc > 0):
                raise ValueError(f"top_speed_until needs finite (s_until_m, v_mps > 0) pairs, got ({su}, {vc})")
        if caps and path.closed:
            raise ValueError("top_speed_until is for open paths")
        self.top_speed_until = caps
        self.s_start_m = float(s_start_m)
        self.path = path
        self.closed = bool(path.closed)
        self.length_m = float(path.length_m)
        self.lateral_accel_max_mps2 = float(lateral_accel_max_mps2)
        self.accel_max_mps2 = float(accel_max_mps2)
        self.decel_max_mps2 = float(decel_max_mps2)
        self.v_max_mps = float(v_max_mps)
        self.friction_circle = bool(friction_circle)
        if ds_m is None:
            ds_m = min(0.05, self.length_m / 200.0)
        if not (math.isfinite(ds_m) and ds_m > 0):
            raise ValueError(f"ds_m must be positive, got {ds_m}")
        n = max(3, int(math.ceil(self.length_m / ds_m)) + (0 if self.closed else 1))
        if self.closed:
            s = np.arange(n) * (self.length_m / n)
        else:
            s = np.linspace(0.0, self.length_m, n)
        self.ds_m = float(s[1] - s[0])
        signed = np.asarray(path.curvature(s), float)
        kappa = self._window_max(np.abs(signed), curvature_window_m)
        self.s_m = s
        self.abs_kappa = kappa
        self.v_limit_mps = np.minimum(self.v_max_mps, np.sqrt(self.lateral_accel_max_mps2 / np.maximum(kappa, 1e-12)))
        self.curvature_rate_max_1pms = curvature_rate_max_1pms
        #: the path's curvature change per metre over the curvature rate [s/m] (0: no rate given):
        #: the inverse of the speed above which the bend sets in faster than the steering follows
        self.bend_s_per_m = np.zeros_like(self.v_limit_mps)
        if curvature_rate_max_1pms is not None:
            # the change of curvature over CURVATURE_RATE_BASE_M either side (a waypoint path's
            # curvature jitters over centimetres; the steering follows the change over metres)
            h = max(1, int(round(CURVATURE_RATE_BASE_M / self.ds_m)))
            if self.closed:
                ahead, behind = np.roll(signed, -h), np.roll(signed, h)
            else:
                padded = np.concatenate([np.full(h, signed[0]), signed, np.full(h, signed[-1])])
                ahead, behind = padded[2 * h :], padded[: -2 * h]
            dk = np.abs(ahead - behind) / (2.0 * h * self.ds_m)
            self.bend_s_per_m = dk / curvature_rate_max_1pms
            np.minimum(self.v_limit_mps, curvature_rate_max_1pms / np.maximum(dk, 1e-12), out=self.v_limit_mps)
        for s_until, v_cap in caps:
            np.minimum(self.v_limit_mps, v_cap, out=self.v_limit_mps, where=s <= s_until)
        self.v_mps = self._passes(v_start_mps, v_end_mps)
        # time along the grid: v^2 is linear in s on each segment (constant acceleration), so a
        # segment takes exactly 2 ds / (v_i + v_{i+1}); a segment between two stops takes forever
        v = np.r_[self.v_mps, self.v_mps[0]] if self.closed else self.v_mps
        seg_t = segment_times(self.ds_m, v)
        if self.s_start_m > 0.0:  # open paths only: the clock starts at the start
            seg_t[s[1:] <= self.s_start_m + 1e-12] = 0.0
        self._t_grid = np.r_[0.0, np.cumsum(seg_t)]
        self._s_grid = np.r_[self.s_m, self.length_m] if self.closed else self.s_m

    # -- construction -----------------------------------------------------------------------
    def _window_max(self, a: np.ndarray, window_m: float) -> np.ndarray:
        """``a`` on the grid, each value the largest within +- ``window_m`` [m] (periodic on a
        closed path)."""
        if window_m <= 0:
            return a
        half = int(math.ceil(window_m / self.ds_m))
        if self.closed:
            padded = np.concatenate([a[-half:], a, a[:half]])
        else:
            padded = np.concatenate([np.full(half, a[0]), a, np.full(half, a[-1])])
        return np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1).max(axis=1)

    def _long_limit(self, a_max: float, v: float, kappa: float) -> float:
        if not self.friction_circle:
            return a_max
        used = v * v * kappa / self.lateral_accel_max_mps2
        return a_max * math.sqrt(max(0.0, 1.0 - used * used))

    def _passes(self, v_start, v_end) -> np.ndarray:
        lim = self.v_limit_mps.copy()
        kap = self.abs_kappa
        ds = self.ds_m
        n = lim.size
        if self.closed:
            i0 = int(np.argmin(lim))
            order = np.r_[np.arange(i0, n), np.arange(0, i0), i0]  # one lap, back to the start
        else:
            order = np.arange(n)
            if v_start is not None:
                held = self.s_m <= max(self.s_start_m, self.s_m[0])  # up to the start, at least the first point
                lim[held] = np.minimum(lim[held], v_start)
            if v_end is not None:
                lim[-1] = min(lim[-1], v_end)
        v = lim[order].copy()
        k = kap[order]
        for j in range(1, v.size):  # forward: acceleration limit
            a = self._long_limit(self.accel_max_mps2, v[j - 1], k[j - 1])
            v[j] = min(v[j], math.sqrt(v[j - 1] ** 2 + 2.0 * a * ds))
        if self.closed:
            v[-1] = min(v[-1], v[0])
        for j in range(v.size - 2, -1, -1):  # backward: braking limit
            b = self._long_limit(self.decel_max_mps2, v[j + 1], k[j + 1])
            v[j] = min(v[j], math.sqrt(v[j + 1] ** 2 + 2.0 * b * ds))
        out = np.empty(n)
        out[order[:n]] = v[:n]
        return out

    @classmethod
    def from_friction(
        cls, path: ReferencePath, friction: float, *, lateral_fraction: float = 0.8, g_mps2: float = 9.81, **kw
    ) -> SpeedProfile:
        """Profile with ``lateral_accel_max = lateral_fraction * friction * g``; other arguments as
        for the constructor."""
        if not (0 < lateral_fraction <= 1):
            raise ValueError(f"lateral_fraction must lie in (0, 1], got {lateral_fraction}")
        return cls(path, lateral_fraction * friction * g_mps2, **kw)

    # -- evaluation ---------------------------------------------------------------------------
    def bend(self, s_m: npt.ArrayLike) -> np.ndarray:
        """:attr:`bend_s_per_m` [s/m] at arc length(s) ``s_m`` [m]: the inverse of the speed above
        which the path's curvature changes faster than the vehicle can steer
        (``curvature_rate_max_1pms``, over :data:`CURVATURE_RATE_BASE_M` either side); 0 where no
        rate is given."""
        return self._on_grid(self.bend_s_per_m, s_m)

    def speed(self, s_m: npt.ArrayLike) -> np.ndarray | float:
        """Reference speed [m/s] at arc length(s) ``s_m`` [m]."""
        v = self._on_grid(self.v_mps, s_m)
        return float(v) if v.ndim == 0 else v

    def _on_grid(self, values: np.ndarray, s_m: npt.ArrayLike) -> np.ndarray:
        """``values`` on the profile's grid interpolated at arc length(s) ``s_m`` [m] (a closed
        path wraps round)."""
        s = np.asarray(s_m, float)
        if self.closed:
            s = np.mod(s, self.length_m)
            return np.interp(s, np.r_[self.s_m, self.length_m], np.r_[values, values[0]])
        return np.interp(s, self.s_m, values)

    def time_at(self, s_m) -> np.ndarray:
        """Time [s] the profile takes from its start to arc length(s) ``s_m`` [m] (counting laps on a
        closed path; ``inf`` beyond a stop)."""
        s = np.asarray(s_m, float)
        if self.closed:
            laps = np.floor(s / self.length_m)
            return laps * self._t_grid[-1] + np.interp(s - laps * self.length_m, self._s_grid, self._t_grid)
        return np.interp(s, self._s_grid, self._t_grid)

    def arc_length_after(self, s0_m: float, t_s) -> np.ndarray:
        """Arc length [m] the profile reaches from ``s0_m`` after time(s) ``t_s`` [s] (>= 0): exact
        for the constant acceleration between grid points, so a car at rest at ``s0`` with a profile
        rising from 0 gets references moving off as it should (a fixed point on the speed would
        stay put). On an open path the arc length stops at a stop, and continues past the end at
        the end speed."""
        t = self.time_at(s0_m) + np.asarray(t_s, float)
        if self.closed:
            T = self._t_grid[-1]
            laps = np.floor(t / T)
            tt = t - laps * T
            s_loc = self._s_at_time(tt)
            return laps * self.length_m + s_loc
        return self._s_at_time(t)

    def _s_at_time(self, t):
        tg, sg = self._t_grid, self._s_grid
        finite = np.isfinite(tg)
        i = np.clip(np.searchsorted(tg, t, side="right") - 1, 0, len(tg) - 2)
        # within segment i: constant acceleration from v_i
        v = np.r_[self.v_mps, self.v_mps[0]] if self.closed else self.v_mps
        vi, vj = v[i], v[i + 1]
        a = (vj * vj - vi * vi) / (2.0 * self.ds_m)
        with np.errstate(invalid="ignore"):  # past a stop both ends are inf: nan, taken as no motion
            tau = np.clip(t - tg[i], 0.0, tg[i + 1] - tg[i])  # inf for a segment between two stops
        ds = np.where(np.isfinite(tau), vi * tau + 0.5 * a * tau * tau, 0.0)
        ds = np.where(np.isfinite(tg[i + 1]) & (t >= tg[i + 1]), self.ds_m, ds)
        s = sg[i] + np.clip(ds, 0.0, self.ds_m)
        if self.closed:
            return s
        s = np.minimum(s, sg[finite][-1])
        if np.isfinite(tg[-1]) and v[-1] > 0:  # beyond the end of an open path: on at the end speed
            s = np.where(t > tg[-1], sg[-1] + v[-1] * (t - tg[-1]), s)
        return s

    def longitudinal_accel(self) -> np.ndarray:
        """(M-1,) or (M,) on a closed path: the acceleration (v_{i+1}^2 - v_i^2) / (2 ds) [m/s^2]
        between grid points."""
        v = np.r_[self.v_mps, self.v_mps[0]] if self.closed else self.v_mps
        return np.diff(v * v) / (2.0 * self.ds_m)

    def lateral_accel(self) -> np.ndarray:
        """(M,) v^2 |kappa| [m/s^2] at the grid points (with the windowed curvature)."""
        return self.v_mps**2 * self.abs_kappa

    @property
    def lap_time_s(self) -> float:
        """Time to drive the path once at the profile speed [s] (trapezoidal in 1/v)."""
        v = np.r_[self.v_mps, self.v_mps[0]] if self.closed else self.v_mps
        vm = 0.5 * (v[1:] + v[:-1])
        if np.any(vm <= 0):
            return math.inf
        return float(np.sum(self.ds_m / vm))
