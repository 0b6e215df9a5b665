"""The friction circle as per-stage input bounds: the one owner of that rule.

A tyre transmits at most ``a_fric`` [m/s^2] in any direction: the car's lateral acceleration
``a_lat = v^2 tan(delta) / L`` (the kinematic bicycle's, an upper bound of the slip-corrected one)
and its longitudinal acceleration ``a`` must satisfy ``a^2 + a_lat^2 <= a_fric^2``. The MPC keeps
that per horizon stage as two box bounds, so both solvers take it as they take input bounds:

* the stage's speed ``v_k`` is the larger of the linearization trajectory's speeds at the
  stage's start and end (the QP cannot change it within the step);
* the circle is split between the two directions where the linearization (the previous plan)
  is: with ``(a_lat_bar, a_bar)`` the plan's accelerations and ``r^2 = a_fric^2 - a_lat_bar^2 -
  a_bar^2`` what it leaves, each direction gets its planned share plus half the rest,
  ``sqrt(a_lat_bar^2 + r^2 / 2)`` and ``sqrt(a_bar^2 + r^2 / 2)`` (a plan outside the circle is
  scaled onto it). Any input inside both boxes is inside the circle, and a plan that steers (or
  brakes) harder moves the split its way from step to step;
* braking keeps at least ``BRAKE_SHARE`` of the circle (the lateral bound then keeps
  ``sqrt(1 - BRAKE_SHARE^2)`` = 97 % of it): slowing is what brings a plan at or beyond the
  circle back inside it. Split at the plan's direction alone, a stage planned at the lateral
  limit at a steady speed had no braking at all, and the QP's solution there, the next step's
  linearization, was split the same way;
* the steering bound is ``|delta_k| <= atan(a_lat_max L / v_k^2)``, the acceleration bound
  ``|a_k| <= a_long_max``, both intersected with the problem's input bounds;
* the boxes stay reachable from the input applied last under the rate limit (a stage whose box
  the greedy sequence ``u_k = clip(u_{k-1}, box_k)`` cannot reach within one rate step is widened
  to that step), so the bounds never make the QP infeasible by themselves.

A plan slowing down therefore widens the steering range of its later stages: the MPC brakes
before a tight evasion instead of steering beyond what the tyres give.
"""

from __future__ import annotations

import math

import numpy as np

from .._subroutine import subroutine


#: the least share of the friction circle kept for braking at every stage (module docstring):
#: a quarter of the grip, 2.3 m/s^2 on a 9.3 m/s^2 circle, for 3 % of the lateral one
BRAKE_SHARE = 0.25


@subroutine
def friction_input_bounds(
    N, speed, Ubar, i_steer, i_accel, wheelbase_m, a_fric, u_min, u_max, dmax, u_prev, lo, hi
):  # pragma: no cover - compiled
    """Per-stage input bounds ``lo, hi`` (N, nu) from the friction circle (module docstring).

    speed : (N+1,) speeds [m/s] of the linearization trajectory; Ubar : (N, nu) its inputs;
    i_steer, i_accel : the steering [rad] and acceleration [m/s^2] input indices (-1: none);
    u_min, u_max, dmax : (nu,) the problem's input bounds and largest change per step (inf: none);
    u_prev : (nu,) the input applied last."""
    nu = u_min.shape[0]
    for k in range(N):
        for a in range(nu):
            lo[k, a] = u_min[a]
            hi[k, a] = u_max[a]
        if i_steer < 0:
            continue
        v = max(abs(speed[k]), abs(speed[k + 1]))
        v2 = v * v
        lat_bar = v2 * abs(math.tan(min(abs(Ubar[k, i_steer]), 1.5))) / wheelbase_m
        lon_bar = abs(Ubar[k, i_accel]) if i_accel >= 0 else 0.0
        rest = a_fric * a_fric - lat_bar * lat_bar - lon_bar * lon_bar
        if i_accel < 0:
            lat_max = a_fric
            lon_max = math.inf
        elif rest >= 0.0:
            lat_max = math.sqrt(lat_bar * lat_bar + 0.5 * rest)
            lon_max = math.sqrt(lon_bar * lon_bar + 0.5 * rest)
        else:
            scale = a_fric / math.sqrt(lat_bar * lat_bar + lon_bar * lon_bar)
            lat_max = lat_bar * scale
            lon_max = lon_bar * scale
        brake_max = lon_max
        if i_accel >= 0 and lon_max < BRAKE_SHARE * a_fric:
            brake_max = BRAKE_SHARE * a_fric
            lat_max = min(lat_max, a_fric * math.sqrt(1.0 - BRAKE_SHARE * BRAKE_SHARE))
        if v2 > 0.0:
            d = math.atan(lat_max * wheelbase_m / v2)
            lo[k, i_steer] = max(lo[k, i_steer], -d)
            hi[k, i_steer] = min(hi[k, i_steer], d)
        if i_accel >= 0:
            lo[k, i_accel] = max(lo[k, i_accel], -brake_max)
            hi[k, i_accel] = min(hi[k, i_accel], lon_max)
    # reachable from u_prev under the rate limit (the greedy sequence)
    for a in range(nu):
        prev = u_prev[a]
        for k in range(N):
            if prev - dmax[a] > hi[k, a]:
                hi[k, a] = prev - dmax[a]
            if prev + dmax[a] < lo[k, a]:
                lo[k, a] = prev + dmax[a]
            prev = min(max(prev, lo[k, a]), hi[k, a])


class FrictionBounds:
    """The friction circle of ``problem`` (its ``friction_accel_mps2``) for ``model`` (its
    ``steer`` / ``accel`` inputs, wheelbase and ``speed``), set up once: :meth:`fill` writes
    each step's per-stage bounds into ``lo, hi`` (N, nu) in place. ValueError for a model it
    cannot apply to."""

    def __init__(self, problem, model):
        names = list(model.input_names)
        if "steer" not in names:
            raise ValueError(f"friction_accel_mps2 needs a model with a steer input, got {model.input_names}")
        wheelbase = getattr(getattr(model, "params", None), "wheelbase_m", None)
        if wheelbase is None or not (math.isfinite(wheelbase) and wheelbase > 0):
            raise ValueError("friction_accel_mps2 needs a model with a positive params.wheelbase_m")
        self.model = model
        self.N = problem.N
        self.i_steer = names.index("steer")
        self.i_accel = names.index("accel") if "accel" in names else -1
        self.wheelbase_m = float(wheelbase)
        self.a_fric = float(problem.friction_accel_mps2)
        self.u_min, self.u_max = problem.u_min, problem.u_max
        self.dmax = problem.du_max_per_s * problem.dt_s
        self.lo = np.zeros((problem.N, problem.nu))
        self.hi = np.zeros((problem.N, problem.nu))

    def fill(self, Xlin: np.ndarray, Ubar: np.ndarray, u_prev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The bounds ``(lo, hi)`` at the linearization trajectory ``Xlin`` (N+1, nx) with inputs
        ``Ubar`` (N, nu), the input applied last being ``u_prev``."""
        friction_input_bounds(
            self.N,
            np.asarray(self.model.speed(Xlin), float),
            Ubar,
            self.i_steer,
            self.i_accel,
            self.wheelbase_m,
            self.a_fric,
            self.u_min,
            self.u_max,
            self.dmax,
            u_prev,
            self.lo,
            self.hi,
        )
        return self.lo, self.hi


def friction_bounds(problem, model) -> FrictionBounds | None:
    """:class:`FrictionBounds` for a problem with a friction circle, else None."""
    return None if problem.friction_accel_mps2 is None else FrictionBounds(problem, model)
