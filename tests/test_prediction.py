"""Predictions from what is observable now: lanes followed, uncertainty growing with time."""

import math

import numpy as np
import pytest

from mpcdrive.prediction import (
    Lane,
    LaneMap,
    LanePredictor,
    Observation,
    PredictingController,
    PredictionConfig,
    inflated,
    observe,
)
from mpcdrive.scene.obstacles import ConstantVelocity, Obstacle, Polygon, Static, TrajectoryMotion, rectangle


def _arc(r: float, a0: float, a1: float, n: int = 60) -> np.ndarray:
    a = np.linspace(a0, a1, n)
    return np.column_stack([r * np.cos(a), r * np.sin(a)])


def _map() -> LaneMap:
    """A straight lane 1 (0..50 m along x) forking into a left quarter circle (2) and a straight
    lane (3); a lane 4 beside lane 1, the other way."""
    straight = np.column_stack([np.linspace(0, 50, 11), np.zeros(11)])
    left = _arc(30.0, -math.pi / 2, 0.0) + np.array([50.0, 30.0])
    ahead = np.column_stack([np.linspace(50, 120, 8), np.zeros(8)])
    back = np.column_stack([np.linspace(50, 0, 11), np.full(11, 3.5)])
    return LaneMap([Lane(1, straight, (2, 3)), Lane(2, left), Lane(3, ahead), Lane(4, back)])


def test_a_car_is_matched_to_the_lane_it_drives_in_not_the_one_beside_going_the_other_way():
    lm = _map()
    m = lm.match(10.0, 2.0, 0.0)  # nearer lane 4's centre (1.5 m) than lane 1's (2 m), but lane 4 runs west
    assert m is not None and m.lane == 1
    assert m.s_m == pytest.approx(10.0) and m.e_y_m == pytest.approx(2.0)
    assert lm.match(10.0, 2.0, math.pi).lane == 4
    assert lm.match(10.0, 20.0, 0.0) is None  # on no lane


def test_following_takes_the_straightest_successor_and_goes_on_past_the_last_lane():
    lm = _map()
    assert lm.chain(1, 100.0) == [1, 3]
    xy, h = lm.follow(1, np.array([0.0, 25.0, 60.0, 130.0, 200.0]))
    np.testing.assert_allclose(xy[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(xy[:, 0], [0.0, 25.0, 60.0, 130.0, 200.0])
    np.testing.assert_allclose(h, 0.0, atol=1e-12)


def test_following_a_curved_lane_stays_on_its_centre_line():
    lm = LaneMap([Lane(7, _arc(30.0, 0.0, math.pi, 200))])
    s = np.linspace(0.0, 80.0, 9)
    xy, h = lm.follow(7, s)
    np.testing.assert_allclose(np.hypot(xy[:, 0], xy[:, 1]), 30.0, atol=0.01)
    np.testing.assert_allclose(np.arctan2(xy[:, 1], xy[:, 0]), s / 30.0, atol=1e-3)


def test_a_car_is_predicted_at_constant_speed_along_its_lane():
    lm = LaneMap([Lane(7, _arc(30.0, 0.0, math.pi, 400))])
    pred = LanePredictor(lm, PredictionConfig(horizon_s=4.0, bands_s=(4.0,)))
    obs = Observation(2.0, (30.0, 0.0, math.pi / 2), 6.0, rectangle(4.0, 2.0), "car")
    (ob,) = pred.predict(obs)
    for tau in (0.0, 1.0, 2.5, 4.0):
        x, y, yaw = ob.pose_at(2.0 + tau)
        assert math.hypot(x, y) == pytest.approx(30.0, abs=0.02)
        assert math.atan2(y, x) == pytest.approx(6.0 * tau / 30.0, abs=2e-3)
        assert yaw == pytest.approx(math.pi / 2 + 6.0 * tau / 30.0, abs=0.02)


def test_a_car_on_no_lane_goes_straight_on():
    pred = LanePredictor(None, PredictionConfig(horizon_s=2.0, bands_s=(2.0,)))
    (ob,) = pred.predict(Observation(0.0, (1.0, 2.0, 0.5), 3.0, rectangle(4.0, 2.0)))
    x, y, _ = ob.pose_at(2.0)
    assert (x, y) == pytest.approx((1.0 + 6.0 * math.cos(0.5), 2.0 + 6.0 * math.sin(0.5)))


def test_the_uncertainty_grows_band_by_band_and_each_band_holds_over_its_own_times():
    cfg = PredictionConfig()
    pred = LanePredictor(_map(), cfg)
    obs = Observation(1.0, (10.0, 0.0, 0.0), 10.0, rectangle(4.0, 2.0), "car")
    bands = pred.predict(obs)
    assert len(bands) == pred.bands == len(cfg.bands_s)
    areas = []
    for k, ob in enumerate(bands):
        p = ob.shape.points
        areas.append((p[:, 0].max() - p[:, 0].min()) * (p[:, 1].max() - p[:, 1].min()))
        end = 1.0 + cfg.bands_s[k]
        assert ob.present(end) and not ob.present(end + 0.01)
        assert ob.present(1.0 if k == 0 else 1.0 + cfg.bands_s[k - 1] + 0.01)
    assert areas == sorted(areas) and areas[0] > 8.0
    # at a horizon step on a band's edge exactly one band holds
    for t in (2.0, 4.0):
        assert sum(bool(ob.present(t)) for ob in bands) == 1


def test_a_standing_car_grows_ahead_only():
    cfg = PredictionConfig()
    ahead, behind, side = cfg.inflation_m(3.0, 0.0)
    assert ahead > 0 and behind == 0 and side > 0
    p = inflated(rectangle(4.0, 2.0), ahead, behind, side).points
    assert p[:, 0].min() == pytest.approx(-2.0) and p[:, 0].max() == pytest.approx(2.0 + ahead)


def test_observing_uses_the_past_only():
    """Two recordings equal up to t = 2 s and different afterwards are observed the same at 2 s."""
    t = np.linspace(0.0, 5.0, 51)
    x_brake = np.where(t <= 2.0, 10.0 * t, 20.0 + 10.0 * (t - 2.0) - 4.0 * (t - 2.0) ** 2)
    x_keep = 10.0 * t
    z = np.zeros_like(t)
    shape = rectangle(4.0, 2.0)
    a = Obstacle(shape, (0.0, 0.0, 0.0), TrajectoryMotion(t, x_brake, z, z), "a")
    b = Obstacle(shape, (0.0, 0.0, 0.0), TrajectoryMotion(t, x_keep, z, z), "b")
    oa, ob = observe(a, 2.0, 0.1), observe(b, 2.0, 0.1)
    assert oa.pose == ob.pose and oa.v_mps == pytest.approx(ob.v_mps) == pytest.approx(10.0)
    # at the recording's start the first step's velocity (the recorded start velocity)
    assert observe(a, 0.0, 0.1).v_mps == pytest.approx(10.0)
    assert observe(Obstacle(shape, (0, 0, 0.0), ConstantVelocity(3.0, 4.0)), 1.0, 0.1).v_mps == pytest.approx(3.0)
    assert observe(Obstacle(shape, (0, 0, 0.0), Static(), t_start_s=5.0), 1.0, 0.1) is None


class _Recorder:
    """A controller stub that only records what it was handed (the MPC's interface)."""

    nx, nu, N = 4, 2, 10

    def __init__(self):
        self.got = []

    def set_obstacles(self, obstacles):
        self.got.append(tuple(obstacles))

    def initial_warm(self, x0):
        from mpcdrive.types import WarmStart

        return WarmStart(0.0, np.zeros(2))

    def step(self, x, warm):
        from mpcdrive.types import ControlOutput

        return ControlOutput(np.zeros(2), "ok", "", 0.0, 0.0, 0.0, 0.0, np.zeros((11, 4)), np.zeros((11, 4)), warm)


def test_the_controller_is_handed_predictions_in_a_fixed_order_never_the_future():
    t = np.linspace(0.0, 5.0, 51)
    x_brake = np.where(t <= 2.0, 10.0 * t, 20.0 + 10.0 * (t - 2.0) - 4.0 * (t - 2.0) ** 2)
    z = np.zeros_like(t)
    car = Obstacle(rectangle(4.0, 2.0), (0.0, 0.0, 0.0), TrajectoryMotion(t, x_brake, z, z), "car-1")
    rock = Obstacle(Polygon(np.array([[0, 0], [1, 0], [0, 1.0]])), (30.0, 5.0, 0.0), name="rock")
    gone = Obstacle(rectangle(4.0, 2.0), (0.0, 0.0, 0.0), ConstantVelocity(1.0, 0.0), "car-2", t_start_s=10.0)
    inner = _Recorder()
    pc = PredictingController(inner, LanePredictor(_map()), (car, rock, gone), period_s=0.1)
    from mpcdrive.types import WarmStart

    for t_now in (0.0, 2.0):
        pc.step(np.array([5.0, -3.0, 0.0, 10.0]), WarmStart(0.0, np.zeros(2), t_s=t_now))
    nb = pc.predictor.bands
    first, second = inner.got
    assert len(first) == len(second) == 1 + 2 * nb
    assert [o.name for o in second] == [f"car-1~{k}" for k in range(nb)] + ["rock"] + [f"car-2~{k}" for k in range(nb)]
    assert second[nb] is rock  # static obstacles are handed on as they are
    assert not any(o.present(2.0) or o.present(3.0) for o in second[nb + 1 :])  # not there yet: absent
    # at t = 2 s the car brakes; the prediction knows only its speed then: 10 m/s on
    x_pred, _, _ = second[1].pose_at(4.0)
    assert x_pred == pytest.approx(40.0, abs=1e-6)
    assert car.pose_at(4.0)[0] == pytest.approx(24.0)
    # outside the sensors' range nothing is seen
    far = PredictingController(_Recorder(), LanePredictor(_map()), (car,), period_s=0.1)
    assert not any(o.present(0.0) for o in far.predictions(0.0, (500.0, 0.0)))


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="bands_s"):
        PredictionConfig(bands_s=(3.0, 1.0, 8.0))
    with pytest.raises(ValueError, match="horizon_s"):
        PredictionConfig(horizon_s=5.0)
    with pytest.raises(ValueError, match="lane 3"):
        Lane(3, np.zeros((1, 2)))
    with pytest.raises(ValueError, match="set_obstacles"):
        PredictingController(
            object.__new__(type("C", (), {"nx": 1, "nu": 1, "N": 1})), LanePredictor(None), period_s=0.1
        )


def test_matching_through_the_grid_is_matching_against_every_segment():
    """The oracle: the nearest qualifying segment of all, by brute force."""
    rng = np.random.default_rng(3)
    lm = _map()
    for _ in range(300):
        x, y, yaw = rng.uniform(-10, 130), rng.uniform(-10, 40), rng.uniform(-math.pi, math.pi)
        got = lm.match(x, y, yaw)
        best = None
        for lane in lm.lanes.values():
            c = lane.centre
            for j in range(len(c) - 1):
                d = c[j + 1] - c[j]
                L = math.hypot(*d)
                u = d / L
                t = min(max((x - c[j, 0]) * u[0] + (y - c[j, 1]) * u[1], 0.0), L)
                dist = math.hypot(x - c[j, 0] - t * u[0], y - c[j, 1] - t * u[1])
                dpsi = (yaw - math.atan2(d[1], d[0]) + math.pi) % (2 * math.pi) - math.pi
                if dist <= lane.half_width_m + 1.0 and abs(dpsi) <= math.radians(45.0):
                    score = dist + 2.0 * abs(dpsi)
                    if best is None or score < best[0]:
                        best = (score, lane.id, lane.s_m[j] + t)
        if best is None:
            assert got is None
        else:
            assert got is not None and got.lane == best[1] and got.s_m == pytest.approx(best[2])
