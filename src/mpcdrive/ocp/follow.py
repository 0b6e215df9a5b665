"""Horizon references held back behind a stop line that moves (car following) or below a speed
cap: where the tracking references of the MPC go when something ahead, or a decision layer,
says the car may not drive at its free reference speed."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["follow_references"]


def follow_references(
    s_arr: np.ndarray,
    v_arr: np.ndarray,
    s_max: np.ndarray | None,
    v0_mps: float,
    dt_s: float,
    decel_mps2: float,
    v_cap_mps: float = math.inf,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Horizon references behind a stop line that moves: arc lengths (N+1,) [m] and speeds (N+1,)
    [m/s] of a car starting at ``s_arr[0]`` with speed ``v0_mps`` that drives at the free
    references' speed ``v_arr`` where it can, and otherwise at the speed from which braking at
    ``decel_mps2`` relative to the line ``s_max`` (N+1,) [m] ends on it (past the line, the
    speed that falls back behind it the same way) -- never braking harder than ``decel_mps2``,
    and never faster than ``v_cap_mps`` (a speed cap, e.g. a decision layer's, with or without a
    line: ``s_max`` None). None when nothing holds the car back (the free references stand)."""
    N = len(s_arr) - 1
    if s_max is None:
        s_max = np.full(N + 1, math.inf)
        v_line = np.zeros(N + 1)
    else:
        v_line = np.append(np.diff(s_max) / dt_s, (s_max[-1] - s_max[-2]) / dt_s if N > 1 else 0.0)
    s_out, v_out = np.empty(N + 1), np.empty(N + 1)
    held = _follow(
        np.asarray(s_arr, float), np.asarray(v_arr, float), np.asarray(s_max, float), v_line,
        float(v0_mps), float(dt_s), float(decel_mps2), float(v_cap_mps), s_out, v_out,
    )  # fmt: skip
    return (s_out, v_out) if held else None


@njit(cache=True)
def _follow(s_arr, v_arr, s_max, v_line, v0_mps, dt_s, decel_mps2, v_cap_mps, s_out, v_out):
    """:func:`follow_references`' loop over the horizon (compiled: it runs every control step);
    writes ``s_out``, ``v_out``, returns whether the line or the cap held the car back."""
    N = len(s_arr) - 1
    v = max(v0_mps, 0.0)
    s, held = s_arr[0], False
    s_out[0], v_out[0] = s, v
    for k in range(1, N + 1):
        room = s_max[k - 1] - s  # now; < 0: past the line, fall back behind it
        if math.isfinite(room):
            v_allow = max(v_line[k - 1], 0.0) + math.copysign(math.sqrt(2.0 * decel_mps2 * abs(room)), room)
        else:
            v_allow = math.inf
        v_allow = min(v_allow, v_cap_mps)
        held |= v_allow < v_arr[k]
        v_next = max(min(v_arr[k], v_allow), v - decel_mps2 * dt_s, 0.0)
        s = min(s + 0.5 * (v + v_next) * dt_s, s_arr[k])
        s_out[k], v_out[k], v = s, v_next, v_next
    return held
