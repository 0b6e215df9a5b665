"""The friction circle as per-stage input bounds (mpcdrive.ocp.friction), in both controllers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpcdrive.ocp.friction import BRAKE_SHARE, friction_input_bounds
from mpcdrive.ocp.problem import MpcProblem
from mpcdrive.scenarios import build_experiment, load_scenario, run_experiment
from mpcdrive.scenarios.schema import ScenarioSpec

L = 2.6  # wheelbase [m]
A = 9.0  # friction circle [m/s^2]
STEER, ACCEL = 0, 1


def bounds(speed, Ubar, u_prev, u_min=(-0.6, -11.0), u_max=(0.6, 5.0), dmax=(np.inf, np.inf)):
    N = len(Ubar)
    lo, hi = np.zeros((N, 2)), np.zeros((N, 2))
    friction_input_bounds(
        N,
        np.asarray(speed, float),
        np.asarray(Ubar, float),
        STEER,
        ACCEL,
        L,
        A,
        np.asarray(u_min, float),
        np.asarray(u_max, float),
        np.asarray(dmax, float),
        np.asarray(u_prev, float),
        lo,
        hi,
    )
    return lo, hi


def lateral(v, steer):
    return v * v * np.tan(np.abs(steer)) / L


@pytest.mark.parametrize("seed", range(5))
def test_every_input_inside_both_boxes_is_inside_the_circle(seed):
    rng = np.random.default_rng(seed)
    N = 20
    speed = rng.uniform(0.0, 30.0, N + 1)
    Ubar = np.column_stack([rng.uniform(-0.6, 0.6, N), rng.uniform(-11.0, 5.0, N)])
    lo, hi = bounds(speed, Ubar, u_prev=(0.0, 0.0))
    assert np.all(lo <= hi)
    v = np.maximum(speed[:-1], speed[1:])
    for k in range(N):
        # the box's corners are the worst case: the largest steering and acceleration together
        for s in (lo[k, STEER], hi[k, STEER]):
            for a in (lo[k, ACCEL], hi[k, ACCEL]):
                assert a * a + lateral(v[k], s) ** 2 <= A * A * (1 + 1e-9)
    # inside the problem's bounds
    assert np.all(lo >= [-0.6, -11.0]) and np.all(hi <= [0.6, 5.0])


def test_an_idle_plan_splits_the_circle_evenly_and_slowing_widens_the_steering():
    N = 3
    lo, hi = bounds([20.0, 20.0, 10.0, 5.0], np.zeros((N, 2)), u_prev=(0.0, 0.0), u_min=(-0.6, -20.0))
    share = A / math.sqrt(2.0)
    assert hi[0, STEER] == pytest.approx(math.atan(share * L / 400.0))
    assert lo[0, STEER] == pytest.approx(-hi[0, STEER])
    assert hi[0, ACCEL] == pytest.approx(min(5.0, share)) and lo[0, ACCEL] == pytest.approx(-share)
    # stage 1 runs from 10 to 20 m/s? no: from speed[1] = 20 to speed[2] = 10: judged at 20 m/s
    assert hi[1, STEER] == pytest.approx(hi[0, STEER])
    assert hi[2, STEER] == pytest.approx(math.atan(share * L / 100.0))  # at 10 m/s: four times the lateral room


def test_a_plan_that_steers_moves_the_split_towards_steering():
    v = 20.0
    steer_bar = math.atan(6.0 * L / v**2)  # 6 m/s^2 lateral, no braking: 81 - 36 = 45 left
    lo, hi = bounds([v, v], [[steer_bar, 0.0]], u_prev=(0.0, 0.0))
    assert lateral(v, hi[0, STEER]) == pytest.approx(math.sqrt(36.0 + 22.5))
    assert hi[0, ACCEL] == pytest.approx(min(5.0, math.sqrt(22.5)))
    # a plan outside the circle is scaled onto it, keeping its direction
    lo, hi = bounds([v, v], [[math.atan(12.0 * L / v**2), -9.0]], u_prev=(0.0, 0.0))
    assert lateral(v, hi[0, STEER]) == pytest.approx(12.0 * A / 15.0)
    assert lo[0, ACCEL] == pytest.approx(-9.0 * A / 15.0)


@pytest.mark.parametrize("lat", [A * math.sqrt(1.0 - 0.01**2), A, 12.0])
def test_a_plan_at_the_lateral_limit_at_a_steady_speed_can_still_brake(lat):
    """A plan that steers at (or beyond) the limit at a steady speed: split at its direction the
    circle left it no braking (its acceleration bound 0 both ways, or 0.06 m/s^2 at 99.995 % of the
    limit). Braking keeps a quarter of the circle; the steering gives up what that takes, so
    every input in both boxes is still inside the circle; speeding up gets nothing more."""
    v = 20.0
    lo, hi = bounds([v, v], [[math.atan(lat * L / v**2), 0.0]], u_prev=(0.0, 0.0))
    assert lo[0, ACCEL] == pytest.approx(-BRAKE_SHARE * A)
    assert hi[0, ACCEL] < 0.1
    assert lateral(v, hi[0, STEER]) == pytest.approx(A * math.sqrt(1.0 - BRAKE_SHARE**2))
    assert lo[0, ACCEL] ** 2 + lateral(v, hi[0, STEER]) ** 2 <= A * A * (1 + 1e-9)


def test_bounds_stay_reachable_under_the_rate_limit():
    """A previous command outside the first stage's box: the box is widened to what one rate
    step reaches, then the sequence moves in at the rate limit."""
    N = 4
    v = np.full(N + 1, 25.0)
    lo, hi = bounds(v, np.zeros((N, 2)), u_prev=(0.3, 0.0), dmax=(0.05, np.inf))
    d = math.atan(A / math.sqrt(2.0) * L / 625.0)
    assert d < 0.1
    assert hi[0, STEER] == pytest.approx(0.25)
    assert hi[1, STEER] == pytest.approx(0.20)
    # the greedy sequence clip(prev, box) moves at the rate limit and is feasible
    prev = 0.3
    for k in range(N):
        u = min(max(prev, lo[k, STEER]), hi[k, STEER])
        assert abs(u - prev) <= 0.05 + 1e-12
        prev = u
    assert hi[N - 1, STEER] == pytest.approx(max(d, 0.3 - 0.05 * N))


def test_the_problem_checks_its_friction_circle():
    with pytest.raises(ValueError, match="friction_accel_mps2"):
        MpcProblem(4, 2, 10, 0.1, 1.0, 1.0, friction_accel_mps2=-1.0)
    with pytest.raises(ValueError, match="friction_accel_mps2"):
        MpcProblem(4, 2, 10, 0.1, 1.0, 1.0, friction_accel_mps2=math.nan)
    assert MpcProblem(4, 2, 10, 0.1, 1.0, 1.0, friction_accel_mps2=3).friction_accel_mps2 == 3.0


def _circle_run(backend: str, friction: float | None, v_ref: float = 2.0):
    """paper-exp4 (circle of radius 1.5 m, kinematic model with speed state) at ``v_ref``
    (2 m/s: 2.7 m/s^2 on the circle) with the friction circle ``friction``."""
    d = load_scenario("paper-exp4").model_dump(mode="python", exclude_unset=True)
    c = d["controller"]
    c.update(backend=backend, accel_limits_mps2=(-3.0, 3.0), reference_speed_mps=v_ref)
    c.pop("speed_profile", None)
    if friction is not None:
        c["friction_accel_mps2"] = friction
    exp = build_experiment(ScenarioSpec.model_validate(d))
    assert exp.controller.problem.friction_accel_mps2 == friction
    return exp, run_experiment(exp)


@pytest.mark.parametrize("backend", ["osqp", "fast"])
def test_commands_stay_inside_the_friction_circle_on_a_curve_too_fast_for_it(backend):
    """At 2 m/s the circle needs 2.7 m/s^2 of lateral acceleration. With a friction circle of
    1.5 m/s^2 every command's lateral and longitudinal accelerations stay inside it (the car
    drifts outwards: its references move along the circle at 2 m/s, so slowing down would cost
    an ever-growing lag); without it the same controller corners at 2.7 m/s^2."""
    exp, r = _circle_run(backend, 1.5)
    L_car = exp.controller.model.params.wheelbase_m
    x, u = np.asarray(r.x), np.asarray(r.u)
    v = x[: len(u), 3]
    a_lat = v**2 * np.tan(np.abs(u[:, 0])) / L_car
    late = slice(len(u) // 2, None)
    # inside the circle, up to the speed change within a step (the bound is judged at the plan's speeds)
    assert np.max(np.hypot(a_lat, u[:, 1])) <= 1.5 * 1.02
    assert np.median(a_lat[late]) > 1.5 * 0.9  # and it uses what the tyres give
    radius = np.hypot(x[late, 0], x[late, 1])
    assert np.median(radius) > 1.5 + 0.3  # the car cannot hold the 1.5 m circle at 2 m/s
    assert np.all(np.isfinite(x)) and not any(r.fallback)
    # without the friction circle the same car corners at 2 m/s (2.7 m/s^2)
    _, r0 = _circle_run(backend, None)
    u0 = np.asarray(r0.u)
    v0 = np.asarray(r0.x)[: len(u0), 3]
    assert np.median(v0[late] ** 2 * np.tan(np.abs(u0[late, 0])) / L_car) > 2.4
