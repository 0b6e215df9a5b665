"""Run metrics (CONTRACT.md's metrics.json), computed from a SimResult only."""

from __future__ import annotations

import numpy as np

from ..scene.footprint import Footprint
from ..types import FALLBACK_KINDS, STATUS_INACCURATE, STATUS_OK, SimResult


def lane_excess_per_step(result: SimResult, footprint: Footprint = Footprint()) -> np.ndarray | None:
    """(K,) distance [m] by which a footprint corner was outside the lane at each step (0 inside);
    None without a lane."""
    if result.lane_half_width_m is None:
        return None
    h = result.yaw_rad - result.e_psi_rad  # path heading at each step
    c = footprint.corners()
    yaw = result.yaw_rad
    # corner offsets in the world frame, then onto the path's left normal
    dx = np.cos(yaw)[:, None] * c[:, 0] - np.sin(yaw)[:, None] * c[:, 1]
    dy = np.sin(yaw)[:, None] * c[:, 0] + np.cos(yaw)[:, None] * c[:, 1]
    lat = result.e_y_m[:, None] + (-np.sin(h)[:, None] * dx + np.cos(h)[:, None] * dy)
    return np.maximum(0.0, np.max(np.abs(lat), axis=1) - result.lane_half_width_m)


def _lane_excess(result: SimResult, footprint: Footprint) -> float:
    """Largest distance [m] by which a footprint corner left the lane (0 inside)."""
    e = lane_excess_per_step(result, footprint)
    return 0.0 if e is None or e.size == 0 else float(np.max(e))


def _rms(a) -> float:
    a = np.asarray(a, float)
    return float(np.sqrt(np.mean(a * a))) if a.size else float("nan")


def compute_metrics(result: SimResult, footprint: Footprint = Footprint()) -> dict:
    """Metrics of one run; keys as in CONTRACT.md plus ``converged_*`` (second half of the run),
    ``steer_total_variation_rad`` (sum of |steering changes|, for the smoothing study),
    ``fallback_counts`` (steps per fallback rung, every rung listed), ``termination`` (why the
    run ended: ``completed``, ``goal_reached`` or ``diverged``) and ``controller_backend`` (the
    MPC implementation that ran, ``osqp`` or ``fast``, from ``meta["backend"]``; None if absent).

    Steering rates include the first step's change from the initial steering angle
    (``meta["initial_steer_rad"]``, 0 by default: the wheels start straight)."""
    K = result.steps
    ey = result.e_y_m
    half = ey[K // 2:]
    steer = result.steer_rad
    # steering is 0 before the first step (the controller starts from u_prev = 0)
    steer0 = np.r_[result.meta.get("initial_steer_rad", 0.0), steer]
    rate = np.diff(steer0) / result.dt_s
    st = result.solve_time_s * 1e6
    failures = sum(1 for s in result.status if s not in (STATUS_OK, STATUS_INACCURATE))
    return {
        "steps": int(K),
        "duration_s": float(K * result.dt_s),
        "rms_lateral_error_m": _rms(ey),
        "max_abs_lateral_error_m": float(np.max(np.abs(ey))),
        "final_lateral_error_m": float(abs(ey[-1])),
        "converged_rms_lateral_error_m": _rms(half),
        "converged_max_abs_lateral_error_m": float(np.max(np.abs(half))),
        "rms_heading_error_rad": _rms(result.e_psi_rad),
        "max_abs_steer_rad": float(np.max(np.abs(steer))),
        "max_abs_steer_rate_rad_s": float(np.max(np.abs(rate))),
        "steer_total_variation_rad": float(np.sum(np.abs(np.diff(steer0)))),
        "min_obstacle_clearance_m": result.meta.get("min_obstacle_clearance_m"),
        "collisions": int(result.meta.get("collisions", 0)),
        "max_lane_excess_m": _lane_excess(result, footprint),
        "solver_failures": int(failures),
        "fallbacks": int(sum(1 for f in result.fallback if f)),
        "fallback_counts": _fallback_counts(result.fallback),
        "solve_time_us": {
            "p50": float(np.percentile(st, 50)),
            "p99": float(np.percentile(st, 99)),
            "max": float(np.max(st)),
        },
        "goal_reached": result.goal_reached,
        "termination": result.meta.get("termination", "completed"),
        # the controller implementation that ran (osqp or fast; None when not recorded)
        "controller_backend": result.meta.get("backend") or None,
    }


def _fallback_counts(fallback) -> dict[str, int]:
    counts = {k: 0 for k in FALLBACK_KINDS}
    for f in fallback:
        if f:
            counts[f] = counts.get(f, 0) + 1
    return counts
