"""Angles and unit conversions (numpy only)."""

from __future__ import annotations

import math

import numpy as np

TWO_PI = 2.0 * math.pi


def wrap_angle(a):
    """Wrap an angle [rad] (scalar or array) to (-pi, pi]."""
    w = np.mod(np.asarray(a, dtype=float) + math.pi, TWO_PI) - math.pi
    w = np.where(w <= -math.pi, w + TWO_PI, w)
    return float(w) if np.ndim(w) == 0 else w


def unwrap_near(a, ref):
    """Shift angle(s) ``a`` [rad] by a multiple of 2*pi so the first lies within pi of ``ref``.

    For an array the same shift is applied to every element, keeping a continuous
    sequence continuous.
    """
    arr = np.asarray(a, dtype=float)
    first = arr.flat[0] if arr.ndim else float(arr)
    shift = TWO_PI * np.round((ref - first) / TWO_PI)
    out = arr + shift
    return float(out) if out.ndim == 0 else out


def deg2rad(d):
    """Degrees -> radians."""
    return np.deg2rad(d) if np.ndim(d) else math.radians(d)


def rad2deg(r):
    """Radians -> degrees."""
    return np.rad2deg(r) if np.ndim(r) else math.degrees(r)


def kmh2ms(v_kmh):
    """km/h -> m/s."""
    return v_kmh / 3.6
