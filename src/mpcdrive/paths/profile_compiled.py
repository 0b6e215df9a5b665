"""Compiled (numba) speed profiles for the fast controller: the arc lengths a profile reaches
after given times and its speed there, reproducing :meth:`SpeedProfile.arc_length_after` and
:meth:`SpeedProfile.speed` (and those of :class:`ConstantSpeed`) to rounding, on closed paths
(laps) and open ones (stopping at a stop, going on past the end at the end speed), with the
infinite times of segments between two stops.

A profile is described to compiled code by one float array (:func:`profile_array`):
``[kind, closed, length_m, ds_m, M, v_mps]`` followed, for a grid profile, by its arc-length
grid ``s`` (M,), the time grid ``t`` (M,) and the speeds ``v`` (M,) at those arc lengths (on a
closed path all three end with the point one lap on, as in the profile's own tables).
"""

from __future__ import annotations

import math

import numpy as np

from .._subroutine import subroutine
from .speed_profile import ConstantSpeed, SpeedProfile

PROFILE_CONSTANT = 0  # speed v_mps everywhere
PROFILE_GRID = 1  # the tables of a SpeedProfile

# header of a profile array
_P_KIND, _P_CLOSED, _P_LENGTH, _P_DS, _P_M, _P_V = range(6)
_NHEAD = 6


def profile_array(profile) -> np.ndarray | None:
    """The float array describing ``profile`` to compiled code, or None for a profile the
    compiled functions do not know."""
    if type(profile) is ConstantSpeed:
        return np.array([PROFILE_CONSTANT, 0.0, 0.0, 0.0, 0.0, profile.v_mps])
    if type(profile) is SpeedProfile:
        v = np.r_[profile.v_mps, profile.v_mps[0]] if profile.closed else profile.v_mps
        s, t = profile._s_grid, profile._t_grid
        head = [PROFILE_GRID, float(profile.closed), profile.length_m, profile.ds_m, float(s.size), 0.0]
        return np.concatenate([head, s, t, v]).astype(float)
    return None


@subroutine
def _clip(x, lo, hi):
    """np.clip of one number (NaN in, NaN out)."""
    if x != x or lo != lo or hi != hi:
        return math.nan
    return min(max(x, lo), hi)


@subroutine
def bracket(xp, lo, hi, x):
    """The index ``j`` in [lo, hi) with ``xp[j] <= x < xp[j + 1]``, by bisection (``xp``
    increasing, ``xp[lo] <= x < xp[hi]``)."""
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@subroutine
def np_interp(x, xp, fp):
    """np.interp(x, xp, fp) for one x, with numpy's handling of grid points and of infinite
    values in fp (xp increasing)."""
    n = xp.size
    if x != x:
        return x
    if x < xp[0]:
        return fp[0]
    if x > xp[n - 1]:
        return fp[n - 1]
    if x == xp[n - 1]:
        return fp[n - 1]
    j = bracket(xp, 0, n - 1, x)
    if xp[j] == x:
        return fp[j]
    return lerp(x, xp[j], xp[j + 1], fp[j], fp[j + 1])


@subroutine
def lerp(x, x0, x1, f0, f1):
    """np.interp between (x0, f0) and (x1, f1) at x0 < x < x1, with its handling of infinite
    values (the value from the far end where the near end's is NaN; f0 where both are)."""
    slope = (f1 - f0) / (x1 - x0)
    y = slope * (x - x0) + f0
    if y != y:
        y = slope * (x - x1) + f1
        if y != y and f0 == f1:
            y = f0
    return y


@subroutine
def _tables(prof):
    m = int(prof[_P_M])
    o = _NHEAD
    return prof[o : o + m], prof[o + m : o + 2 * m], prof[o + 2 * m : o + 3 * m]


@subroutine
def _time_at(prof, s):
    """Time [s] from the profile's start to arc length s [m] (laps counted on a closed path)."""
    sg, tg, _ = _tables(prof)
    if prof[_P_CLOSED] != 0.0:
        length = prof[_P_LENGTH]
        laps = np.floor(s / length)
        return laps * tg[tg.size - 1] + np_interp(s - laps * length, sg, tg)
    return np_interp(s, sg, tg)


@subroutine
def _s_at_time(prof, t):
    """Arc length [m] at time t [s] from the profile's start (within one lap on a closed path)."""
    sg, tg, v = _tables(prof)
    ds_m = prof[_P_DS]
    m = tg.size
    # i = clip(searchsorted(tg, t, side="right") - 1, 0, m - 2)
    lo, hi = 0, m  # lo = the number of tg <= t
    while lo < hi:
        mid = (lo + hi) // 2
        if tg[mid] <= t:
            lo = mid + 1
        else:
            hi = mid
    i = min(max(lo - 1, 0), m - 2)
    vi, vj = v[i], v[i + 1]
    a = (vj * vj - vi * vi) / (2.0 * ds_m)
    tau = _clip(t - tg[i], 0.0, tg[i + 1] - tg[i])
    ds = vi * tau + 0.5 * a * tau * tau if math.isfinite(tau) else 0.0
    if math.isfinite(tg[i + 1]) and t >= tg[i + 1]:
        ds = ds_m
    s = sg[i] + _clip(ds, 0.0, ds_m)
    if prof[_P_CLOSED] != 0.0:
        return s
    last = m - 1  # the last arc length reached in finite time
    while last > 0 and not math.isfinite(tg[last]):
        last -= 1
    s = min(s, sg[last])
    if math.isfinite(tg[m - 1]) and v[m - 1] > 0 and t > tg[m - 1]:
        s = sg[m - 1] + v[m - 1] * (t - tg[m - 1])
    return s


@subroutine
def profile_arc_lengths(prof, s0_m, dt_s, out):
    """out[k] = the arc length [m] the profile reaches from s0_m after k dt_s [s], k < out.size
    (``arc_length_after(s0_m, dt_s * arange(out.size))``)."""
    if prof[_P_KIND] == PROFILE_CONSTANT:
        for k in range(out.size):
            out[k] = s0_m + prof[_P_V] * (dt_s * k)
        return
    t0 = _time_at(prof, s0_m)
    closed = prof[_P_CLOSED] != 0.0
    if closed:
        _, tg, _ = _tables(prof)
        lap_t = tg[tg.size - 1]
    for k in range(out.size):
        t = t0 + dt_s * k
        if closed:
            laps = np.floor(t / lap_t)
            out[k] = laps * prof[_P_LENGTH] + _s_at_time(prof, t - laps * lap_t)
        else:
            out[k] = _s_at_time(prof, t)


@subroutine
def profile_speed(prof, s_m):
    """Reference speed [m/s] at arc length s_m [m] (``speed(s_m)``)."""
    if prof[_P_KIND] == PROFILE_CONSTANT:
        return prof[_P_V]
    sg, _, v = _tables(prof)
    s = s_m
    if prof[_P_CLOSED] != 0.0:
        length = prof[_P_LENGTH]
        s = np.fmod(s, length)  # np.mod: the sign of the divisor
        if s != 0.0 and (s < 0.0) != (length < 0.0):
            s += length
    return np_interp(s, sg, v)
