"""Horizon references along a path.

Two ways to place the N+1 reference points of a horizon (both start at the projection s0 of
the vehicle onto the path):

* ``paper``: the paper's authors' scheme, a fixed arc-length step per horizon step
  (0.025 m by default), independent of the speed;
* ``arc_length``: the distance the car travels at the planned speed, ``s_k = s0 + sum v dt``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from ..units import unwrap_near
from .base import ReferencePath

HorizonMode = Literal["paper", "arc_length"]


def horizon_arc_lengths(
    s0_m: float, N: int, mode: HorizonMode, dt_s: float, speed_mps=1.0, step_m: float = 0.025
) -> np.ndarray:
    """(N+1,) arc lengths [m] of the horizon references.

    speed_mps : scalar or (N,) planned speed per step [m/s] (``arc_length`` mode);
    step_m : arc length per horizon step [m] (``paper`` mode).
    """
    if mode == "paper":
        return s0_m + step_m * np.arange(N + 1)
    if mode == "arc_length":
        v = np.broadcast_to(np.asarray(speed_mps, float), (N,))
        return s0_m + np.r_[0.0, np.cumsum(np.abs(v) * dt_s)]
    raise ValueError(f"unknown horizon mode {mode!r}; use 'paper' or 'arc_length'")


def horizon_states(path: ReferencePath, s_m: np.ndarray, yaw_now_rad: float) -> np.ndarray:
    """(N+1, 4) references ``[x m, y m, yaw rad, kappa 1/m]`` at arc lengths ``s_m``.

    The heading sequence is continuous and shifted by a multiple of 2*pi so that its first
    element lies within pi of the vehicle's (unwrapped) yaw: the yaw error never sees a 2*pi jump.
    """
    out = np.empty((len(s_m), 4))
    out[:, :2] = path.position(s_m)
    out[:, 2] = unwrap_near(path.heading(s_m), yaw_now_rad)
    out[:, 3] = path.curvature(s_m)
    return out
