"""Run metrics (``metrics.json``), computed from a SimResult only."""

from __future__ import annotations

import numpy as np

from ..types import FALLBACK_KINDS, STATUS_HELD, STATUS_INACCURATE, STATUS_OK, SimResult


def lane_excess_per_step(result: SimResult) -> np.ndarray | None:
    """(K,) distance [m] by which the body was outside the road at each step (0 inside), measured
    in the run by the road's rule (:meth:`~mpcdrive.scene.road.Road.body_excess_m`); None
    without a road."""
    return result.lane_excess_m


def _lane_excess(result: SimResult) -> float:
    """Largest distance [m] by which the body left the road (0 inside)."""
    e = lane_excess_per_step(result)
    return 0.0 if e is None or e.size == 0 else float(np.max(e))


#: lane excess [m] up to which a run still counts as inside the lane (the goal definition, the
#: run verdict): the excess is measured on the projection onto the path's polyline table, whose
#: chord error kappa ds^2 / 8 stays below a millimetre for the tables' spacing (<= 0.1 m) on
#: curves down to 1.25 m radius; anything beyond is a real excursion
LANE_TOLERANCE_M = 1e-3


def goal_met(region_reached: bool | None, max_lane_excess_m: float, collisions: int) -> bool | None:
    """The one definition of ``goal_reached``: the goal region was reached (``region_reached``)
    AND the body stayed inside the lane (largest excess <= :data:`LANE_TOLERANCE_M`) AND there
    was no collision. None when the run has no goal (``region_reached`` None: a closed path
    without ``laps``, or a run that does not stop at the path's end)."""
    if region_reached is None:
        return None
    return bool(region_reached) and max_lane_excess_m <= LANE_TOLERANCE_M and int(collisions) == 0


def apply_goal_region(
    metrics: dict, region_reached: bool, *, collision_free: bool = True, road_compliant: bool = True
) -> dict:
    """``metrics`` with the goal judged on another goal region (a CommonRoad planning problem's):
    ``goal_region_reached`` becomes ``region_reached`` and ``goal_reached`` follows
    :func:`goal_met`, also requiring an external checker's ``collision_free`` and
    ``road_compliant`` verdicts (the drivability checker's for CommonRoad). The checker's road
    is the authority on "inside the road" there: mpcdrive's own lane (one width along the route's
    centre line) is a proxy that a lane change or a wider lanelet exceeds."""
    met = goal_met(region_reached, 0.0, metrics["collisions"])  # the lane proxy gives way to the checker's road
    return {
        **metrics,
        "goal_region_reached": bool(region_reached),
        "goal_reached": bool(met and collision_free and road_compliant),
    }


def _rms(a) -> float:
    a = np.asarray(a, float)
    return float(np.sqrt(np.mean(a * a))) if a.size else float("nan")


def compute_metrics(result: SimResult) -> dict:
    """Metrics of one run (the keys of ``metrics.json``): tracking, steering, obstacle and lane figures plus ``converged_*`` (second half of the run),
    ``steer_total_variation_rad`` (sum of |steering changes|, for the smoothing study),
    ``fallback_counts`` (steps per fallback rung, every rung listed), ``termination`` (why the
    run ended: ``completed``, ``goal_reached`` or ``diverged``) and ``controller_backend`` (the
    MPC implementation that ran, ``osqp`` or ``fast``, from ``meta["backend"]``; None if absent).

    Safety: ``collisions`` (contacts with obstacles), ``collision_events`` (each contact:
    ``obstacle`` index, ``name``, ``step``, ``t_s``, ``steps``, ``depth_m``; ``[]`` without one),
    ``first_collision`` (the first event or None), ``road_given`` (False: no road or lane was
    given), ``max_lane_excess_m`` (the body's largest excess outside the road [m]). ``goal_region_reached`` is the raw test (the run reached the
    end of an open path or its laps; ``SimResult.goal_reached``), ``goal_reached`` the
    definition of :func:`goal_met`: region reached, inside the lane and without collision.

    Steering rates include the first step's change from the initial steering angle
    (``meta["initial_steer_rad"]``, 0 by default: the wheels start straight).

    ``solver_failures`` and ``solve_time_us`` count real solves only: the plant steps between
    the solves of a controller slower than the plant (status ``held``) are neither."""
    K = result.steps
    ey = result.e_y_m
    half = ey[K // 2 :]
    steer = result.steer_rad
    # steering is 0 before the first step (the controller starts from u_prev = 0)
    steer0 = np.r_[result.meta.get("initial_steer_rad", 0.0), steer]
    rate = np.diff(steer0) / result.dt_s
    solved = np.array([s != STATUS_HELD for s in result.status], dtype=bool)
    st = np.asarray(result.solve_time_s, float)[solved] * 1e6
    failures = sum(1 for s in result.status if s not in (STATUS_OK, STATUS_INACCURATE, STATUS_HELD))
    collisions = int(result.meta.get("collisions", 0))
    events = [dict(e) for e in result.meta.get("collision_events", ())]
    lane_excess = _lane_excess(result)
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
        "collisions": collisions,
        "collision_events": events,
        "first_collision": events[0] if events else None,
        "road_given": result.lane_excess_m is not None,
        "max_lane_excess_m": lane_excess,
        "solver_failures": int(failures),
        "fallbacks": int(sum(1 for f in result.fallback if f)),
        "fallback_counts": _fallback_counts(result.fallback),
        "solve_time_us": {
            "p50": float(np.percentile(st, 50)),
            "p99": float(np.percentile(st, 99)),
            "max": float(np.max(st)),
        },
        "goal_region_reached": result.goal_reached,
        "goal_reached": goal_met(result.goal_reached, lane_excess, collisions),
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
