"""Contacts between logged states (sim/contact.py): an obstacle that crosses the car between two
samples is a collision with its time and depth, found against a dense brute-force oracle, and a
drive whose bodies keep apart pays for no extra distance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpcdrive.models import KinematicBicycle3
from mpcdrive.paths import StraightPath
from mpcdrive.scene import Circle, ConstantVelocity, Footprint, Obstacle, Polygon, TrajectoryMotion, rectangle
from mpcdrive.scene.geometry import shape_distance
from mpcdrive.sim import Plant, compute_metrics, contact, simulate
from mpcdrive.sim.contact import SWEEP_DEPTH_M, clearances
from mpcdrive.types import STATUS_OK, ControlOutput, WarmStart

BODY = Footprint(0.5, 0.27)
MODEL = KinematicBicycle3(v_mps=1.0)
PATH = StraightPath((0.0, 0.0), (10.0, 0.0))


class Straight:
    """Steers straight: the car drives along x at 1 m/s."""

    nx, nu, N, dt_s = 3, 1, 0, 0.01

    def initial_warm(self, x0):
        return WarmStart(s_m=float(x0[0]), u_prev=np.zeros(1))

    def step(self, x, warm):
        X = np.asarray(x, float)[None, :]
        return ControlOutput(np.zeros(1), STATUS_OK, "", 0.0, float(x[0]), float(x[1]), 0.0, X, X, warm)


def _distances(X, T, ob, k, ts):
    """Signed distances between the body (pose linear between steps k and k + 1) and ``ob`` at
    the times ``ts``."""
    w = (ts - T[k]) / (T[k + 1] - T[k])
    dyaw = (X[k + 1, 2] - X[k, 2] + math.pi) % (2 * math.pi) - math.pi
    return np.array(
        [
            shape_distance(BODY.polygon(*(X[k, :2] + wi * (X[k + 1, :2] - X[k, :2])), X[k, 2] + wi * dyaw), ob.at(t))
            for wi, t in zip(w, ts)
        ]
    )


def _oracle(X, T, ob, k, coarse=200, fine=6000):
    """Smallest signed distance over the interval between steps k and k + 1 and the first time
    it is negative: at ``coarse`` + 1 times, then, where that comes within 0.05 m, at the
    spacing of ``fine`` + 1 times over the interval."""
    ts = np.linspace(T[k], T[k + 1], coarse + 1)
    d = _distances(X, T, ob, k, ts)
    near = np.flatnonzero(d < 0.05)
    if near.size:
        a, b = ts[max(near[0] - 1, 0)], ts[min(near[-1] + 1, coarse)]
        ts = np.linspace(a, b, int(math.ceil(fine * (b - a) / (T[k + 1] - T[k]))) + 1)
        d = _distances(X, T, ob, k, ts)
    neg = np.flatnonzero(d < 0)
    return float(d.min()), (float(ts[neg[0]]) if neg.size else math.nan)


def test_an_obstacle_crossing_the_car_between_two_samples_is_a_collision():
    """A disc at 300 m/s moves 3 m per 0.01 s step: 0.25 m clear of the car's front at t = 1.00 s,
    2 m behind it at 1.01 s. It passed through the car in between."""
    bullet = Obstacle(Circle(0.1), (301.6, 0.0, 0.0), ConstantVelocity(-300.0, 0.0), name="bullet")
    r = simulate(Straight(), Plant(MODEL), PATH, [0.0, 0.0, 0.0], 0.01, 150, obstacles=(bullet,), footprint=BODY)
    assert np.all(r.clearance_m > 0.2)  # every logged state is clear
    m = compute_metrics(r)
    assert m.collisions == 1
    ev = m.collision_events[0]
    k = ev.step
    assert k == 100 and r.t_s[k] < ev.t_s < r.t_s[k + 1]
    low, first = _oracle(r.x, r.t_s, bullet, k, fine=50000)
    assert low == pytest.approx(-0.235, abs=1e-3)  # through the middle: radius + half the width
    assert ev.depth_m == pytest.approx(-low, abs=SWEEP_DEPTH_M)
    assert abs(ev.t_s - first) <= 2 * SWEEP_DEPTH_M / 301.0  # the sweep's resolution in time
    assert m.min_obstacle_clearance_m == pytest.approx(-ev.depth_m)


def test_random_encounters_agree_with_a_dense_oracle():
    """Turning car, moving, weaving and rotating obstacles: between every two logged states the
    sweep finds each contact deeper than SWEEP_DEPTH_M to within it, and none where the oracle
    has none."""
    rng = np.random.default_rng(7)
    K, dt = 6, 0.05
    T = dt * np.arange(K)
    found = 0
    for trial in range(12):
        v, w = rng.uniform(1.0, 20.0), rng.uniform(-3.0, 3.0)
        yaw = w * T
        X = np.column_stack([v * T * np.cos(0.5 * yaw), v * T * np.sin(0.5 * yaw), yaw])
        mid = X[K // 2, :2] + rng.normal(0.0, 0.3, 2)
        speed = rng.uniform(0.0, 80.0)
        heading = rng.uniform(-math.pi, math.pi)
        if trial % 3 == 0:
            shape = Circle(rng.uniform(0.05, 0.3))
        elif trial % 3 == 1:
            shape = rectangle(rng.uniform(0.1, 1.0), rng.uniform(0.05, 0.4))
        else:
            shape = Polygon(np.array([[0.3, 0.0], [-0.2, 0.15], [-0.2, -0.15]]))
        t_mid = T[K // 2]
        start = mid - speed * t_mid * np.array([math.cos(heading), math.sin(heading)])
        # samples at the logged times (linear between them), or four times as often on a weave
        # (not linear between the logged times: the sweep adds the motions up there)
        tt = T if trial % 2 == 0 else np.linspace(0.0, T[-1], 4 * (K - 1) + 1)
        weave = 0.0 if trial % 2 == 0 else rng.uniform(0.2, 1.0)
        side = weave * np.sin(2 * math.pi * tt / (2 * dt))
        motion = TrajectoryMotion(
            tt,
            speed * tt * math.cos(heading) - side * math.sin(heading),
            speed * tt * math.sin(heading) + side * math.cos(heading),
            rng.uniform(-20.0, 20.0) * tt,  # spinning
        )
        ob = Obstacle(shape, (*start, 0.0), motion)
        at_steps, swept, began, _ = clearances(X, T, (ob,), BODY)
        for k in range(K - 1):
            if min(at_steps[0, k], at_steps[0, k + 1]) < 0:
                continue  # a contact at a logged step: counted there already
            # the points move < 10 m relative to each other in an interval: coarse (< 50 mm a
            # sample: 0.05 m apart is clear), dense (< 1.7 mm a sample: the oracle within 0.9 mm)
            # where the bodies come close
            low, first = _oracle(X, T, ob, k)
            if low < -SWEEP_DEPTH_M:
                found += 1
                assert swept[0, k] == pytest.approx(low, abs=SWEEP_DEPTH_M + 9e-4), (trial, k)
                assert T[k] < began[0, k] < T[k + 1]
            elif low >= 0:
                assert swept[0, k] == at_steps[0, k] and math.isnan(began[0, k]), (trial, k)
    assert found >= 4, found  # the test did meet contacts between samples


def test_an_obstacle_appearing_on_the_car_between_two_samples_is_found():
    """A CommonRoad vehicle exists from its first recorded time on: one appearing on the car at
    t = 0.013 s, between the steps at 0.01 and 0.02 s, and gone by 0.017 s."""
    blip = Obstacle(rectangle(0.2, 0.2), (0.0, 0.0, 0.0), name="blip", t_start_s=0.013, t_end_s=0.017)
    X = np.column_stack([0.01 * np.arange(5) * 0, np.zeros(5), np.zeros(5)])
    T = 0.01 * np.arange(5)
    at_steps, swept, began, _ = clearances(X, T, (blip,), BODY)
    assert np.all(np.isinf(at_steps))  # absent at every logged step
    assert swept[0, 1] < 0 and began[0, 1] == pytest.approx(0.013)
    events = contact.collision_events(swept, T, (blip,), began)
    assert [(e["step"], e["t_s"]) for e in events] == [(1, pytest.approx(0.013))]


def test_a_drive_whose_bodies_keep_apart_costs_no_extra_distance(monkeypatch):
    """Driving past an obstacle at 0.3 m while the bodies move 1 cm per step: no interval needs
    a look between its samples."""
    calls = []
    original = contact._Interval.distance

    def counting(self, t):
        calls.append(t)
        return original(self, t)

    monkeypatch.setattr(contact._Interval, "distance", counting)
    cone = Obstacle(Circle(0.2), (1.0, 0.635, 0.0), name="cone")
    r = simulate(Straight(), Plant(MODEL), PATH, [0.0, 0.0, 0.0], 0.01, 300, obstacles=(cone,), footprint=BODY)
    assert compute_metrics(r).min_obstacle_clearance_m == pytest.approx(0.3, abs=1e-9)
    assert calls == []
