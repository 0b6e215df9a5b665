"""simulate with a plant that has traffic of its own (another simulator's vehicles, moved by the
plant) and can end the episode: the controller gets the traffic at each solve, the accounting
follows the poses the plant reported, and the plant's end of the episode ends the run."""

from __future__ import annotations

import numpy as np
import pytest

from mpcdrive.models.kinematic import KinematicBicycle4, KinematicParams
from mpcdrive.paths import StraightPath
from mpcdrive.scene.footprint import Footprint
from mpcdrive.scene.geometry import shape_distance
from mpcdrive.scene.obstacles import Obstacle, rectangle
from mpcdrive.sim import compute_metrics, run_verdict, simulate
from mpcdrive.sim.closed_loop import ENDED_COLLISION, EpisodicPlant, ObservedPlant, TrafficPlant
from mpcdrive.types import STATUS_OK, ControlOutput, WarmStart

MODEL = KinematicBicycle4(KinematicParams(1.0, 1.0))
PATH = StraightPath((0.0, 0.0), (500.0, 0.0))
BODY = Footprint(4.0, 2.0)


class Coast:
    """Commands zeros (the car coasts straight); records the obstacles it was handed."""

    nx, nu, N, dt_s = 4, 2, 0, 0.1

    def __init__(self):
        self.handed: list[tuple[Obstacle, ...]] = []

    def initial_warm(self, x0):
        return WarmStart(s_m=float(x0[0]), u_prev=np.zeros(2))

    def set_obstacles(self, obstacles):
        self.handed.append(tuple(obstacles))

    def step(self, x, warm):
        X = np.asarray(x, float)[None, :]
        return ControlOutput(
            np.zeros(2),
            STATUS_OK,
            "",
            0.0,
            float(x[0]),
            float(x[1]),
            0.0,
            X,
            X,
            WarmStart(x[0], np.zeros(2), t_s=warm.t_s + self.dt_s),
        )


class CarAhead:
    """The ego (a kinematic bicycle) and a slower car ahead in its lane, moved by the plant at
    ``v_car_mps``; its traffic is the car where it is now, predicted standing (a wrong
    prediction: the accounting must follow where the plant moved it). With ``end_on_contact``
    the episode ends when the bodies overlap after a step (reason ``collision``)."""

    model = MODEL

    def __init__(self, x_car_m=30.0, v_car_mps=5.0, end_on_contact=False):
        self.x_car, self.v_car, self.end_on_contact = x_car_m, v_car_mps, end_on_contact
        self.calls: list[float] = []

    def initial_state(self, x0):
        return np.asarray(x0, float)

    def observe(self, xp):
        return xp

    def step(self, xp, u, dt_s):
        self.x_car += self.v_car * dt_s
        x = np.asarray(xp, float).copy()
        x[0] += x[3] * dt_s
        return x

    def traffic(self, t_s):
        self.calls.append(t_s)
        return (Obstacle(rectangle(4.0, 2.0), (self.x_car, 0.0, 0.0), name="car"),)

    def ended(self, xp):
        if self.end_on_contact and shape_distance(BODY.polygon(*xp[:3]), self.traffic(-1.0)[0].at(0.0)) < 0:
            return ENDED_COLLISION
        return None


def test_the_fakes_are_the_protocols():
    plant = CarAhead()
    assert isinstance(plant, ObservedPlant) and isinstance(plant, TrafficPlant) and isinstance(plant, EpisodicPlant)


def test_the_traffic_reaches_the_controller_and_the_accounting_follows_the_plant():
    ctrl, plant = Coast(), CarAhead()
    r = simulate(ctrl, plant, PATH, [0.0, 0.0, 0.0, 8.0], 0.1, 50, footprint=BODY)
    assert plant.calls == pytest.approx(0.1 * np.arange(50))
    assert len(ctrl.handed) == 50 and all(len(h) == 1 and h[0].name == "car" for h in ctrl.handed)
    # clearance against where the car was (30 m + 5 m/s t), not where it was predicted to stand
    car_x = 30.0 + 5.0 * r.t_s
    gap = car_x - r.x[:, 0] - 4.0
    np.testing.assert_allclose(r.clearance_m, gap, atol=1e-9)
    assert r.meta["obstacles"][0]["name"] == "car" and r.meta["obstacles"][0]["moving"]
    m = compute_metrics(r)
    assert m["collisions"] == 0 and m["min_obstacle_clearance_m"] == pytest.approx(26.0 - 3.0 * 4.9)
    assert r.meta["termination"] == "completed"


def test_given_obstacles_come_first_for_the_controller_and_in_the_accounting():
    parked = Obstacle(rectangle(1.0, 1.0), (100.0, 5.0, 0.0), name="parked")
    ctrl = Coast()
    r = simulate(ctrl, CarAhead(), PATH, [0.0, 0.0, 0.0, 8.0], 0.1, 5, footprint=BODY, obstacles=(parked,))
    assert [o.name for o in ctrl.handed[0]] == ["parked", "car"]
    assert [o["name"] for o in r.meta["obstacles"]] == ["parked", "car"]


def test_the_plant_ends_the_episode_and_its_collision_counts():
    """The ego at 8 m/s closes in on the car at 5 m/s: 26 m of gap, contact after 8.67 s; the
    plant ends the episode after that step, before any logged state overlaps."""
    r = simulate(Coast(), CarAhead(end_on_contact=True), PATH, [0.0, 0.0, 0.0, 8.0], 0.1, 200, footprint=BODY)
    assert r.steps == 87 and r.meta["termination"] == ENDED_COLLISION
    assert r.clearance_m.min() > 0  # the logged states are all clear
    assert r.x_final[0] == pytest.approx(8.0 * 8.7)  # the state after the last step
    m = compute_metrics(r)
    assert m["collisions"] == 1 and m["termination"] == ENDED_COLLISION
    assert run_verdict(m).collided


def test_traffic_that_changes_its_number_is_refused():
    class Growing(CarAhead):
        def traffic(self, t_s):
            return super().traffic(t_s) * (1 + int(t_s > 0.15))

    with pytest.raises(ValueError, match="traffic changed from 1 to 2"):
        simulate(Coast(), Growing(), PATH, [0.0, 0.0, 0.0, 8.0], 0.1, 5, footprint=BODY)


def test_the_clearance_is_the_exact_nearest_distance_at_every_step():
    """Several cars and a parked circle, some overlapping the ego for a while: the clearance per
    step is the brute-force smallest distance (the accounting computes far ones only roughly)."""
    from mpcdrive.scene.obstacles import Circle

    class Cars(CarAhead):
        x0 = np.array([30.0, 60.0, -20.0, 200.0, 12.0])
        y = np.array([0.0, 3.0, 0.0, -3.5, 1.5])
        v = np.array([5.0, 2.0, 12.0, 0.0, 8.0])

        def __init__(self):
            super().__init__()
            self.t = 0.0

        def step(self, xp, u, dt_s):
            self.t += dt_s
            return super().step(xp, u, dt_s)

        def traffic(self, t_s):
            x = self.x0 + self.v * self.t
            return tuple(
                Obstacle(rectangle(4.0, 2.0), (xi, yi, 0.1 * i), name=f"car{i}")
                for i, (xi, yi) in enumerate(zip(x, self.y))
            )

    parked = Obstacle(Circle(1.0), (45.0, -1.5, 0.0), name="parked")
    r = simulate(Coast(), Cars(), PATH, [0.0, 0.0, 0.0, 8.0], 0.1, 80, footprint=BODY, obstacles=(parked,))
    brute = []
    for k, t in enumerate(r.t_s):
        body = BODY.polygon(*r.x[k, :3])
        x = Cars.x0 + Cars.v * t
        cars = [Obstacle(rectangle(4.0, 2.0), (xi, yi, 0.1 * i)).at(0.0) for i, (xi, yi) in enumerate(zip(x, Cars.y))]
        brute.append(min(shape_distance(body, o) for o in [parked.at(t), *cars]))
    np.testing.assert_allclose(r.clearance_m, brute, rtol=0, atol=1e-12)
    assert r.clearance_m.min() < 0 and r.meta["collisions"] >= 1  # car 2 from behind runs into the ego
