"""The compiled obstacle kernels (ocp.avoidance_compiled) against the numpy reference kept in
ocp.avoidance: selection, tracks and hard rows on random instances, and the terms of a recorded
P4 drive."""

import copy
import math
from dataclasses import dataclass

import numpy as np
import pytest

from mpcdrive.bench.problems import PROBLEMS
from mpcdrive.bench.runner import make_controller
from mpcdrive.ocp.avoidance_compiled import obstacle_table, pose_at
from mpcdrive.ocp.avoidance import SIDE_BLOCKED, SIDE_LEFT, SIDE_RIGHT, Avoidance, AvoidanceConfig, AvoidanceMemory
from mpcdrive.paths import CirclePath, StraightPath
from mpcdrive.paths.waypoints import WaypointPath
from mpcdrive.scene import Circle, ConstantVelocity, Footprint, Obstacle, TrajectoryMotion, rectangle
from mpcdrive.scene.road import Road
from mpcdrive.sim import Plant
from shapes import random_shape

TOL = 1e-12
N, DT = 20, 0.1


def _paths():
    t = np.linspace(0.0, 60.0, 40)
    return {
        "straight": StraightPath([0.0, 0.0], [80.0, 5.0]),
        "circle": CirclePath((0.0, 0.0), 25.0, ccw=True),
        "waypoints": WaypointPath(np.column_stack([t, 4.0 * np.sin(t / 9.0)])),
    }


def _scene(rng, path, n_obs, lifetimes, trajectories=False):
    """Random circles, rectangles and pentagons near the first 40 m of ``path``, static or at
    constant velocity (or on a recorded trajectory), some with lifetimes."""
    obstacles = []
    for j in range(n_obs):
        s = rng.uniform(0.0, 40.0)
        p = path.position(s) + rng.normal(0.0, 2.0, 2)
        yaw = float(path.heading(s)) + rng.normal(0.0, 0.3)
        shape = random_shape(rng)
        motion = rng.integers(3 if trajectories else 2)
        if motion == 0:
            m = None
        elif motion == 1:
            m = ConstantVelocity(float(rng.uniform(-3.0, 8.0)), float(rng.uniform(-1.0, 1.0)))
        else:  # uneven samples, starting before or after t = 0 and ending within the horizon or
            # after it (held before the first and after the last sample), turning
            t0 = float(rng.uniform(-1.0, 1.0))
            ts = t0 + np.cumsum(rng.uniform(0.05, 0.4, int(rng.integers(1, 16))))
            v = rng.uniform(0.0, 8.0)
            m = TrajectoryMotion(ts, v * (ts - t0), rng.normal(0.0, 0.3, len(ts)).cumsum(), 0.05 * (ts - t0))
        life = {}
        if lifetimes and rng.random() < 0.4:
            t0 = float(rng.uniform(-1.0, 1.5))
            life = {"t_start_s": t0, "t_end_s": t0 + float(rng.uniform(0.0, 2.0))}
        kw = {} if m is None else {"motion": m}
        obstacles.append(Obstacle(shape, (*p, yaw), name=f"o{j}", **kw, **life))
    return obstacles


def _state(rng, path):
    """A horizon along ``path``: reference arc lengths (N+1,) and a linearization (N+1, 4) near
    them."""
    s0 = rng.uniform(0.0, 20.0)
    s_arr = s0 + rng.uniform(0.5, 2.0) * np.arange(N + 1)
    h = np.asarray(path.heading(s_arr), float)
    xy = path.position(s_arr) + rng.normal(0.0, 0.5, (N + 1, 2))
    Xlin = np.column_stack([xy, h + rng.normal(0.0, 0.1, N + 1), np.full(N + 1, 10.0)])
    return s_arr, Xlin


def _pair(obstacles, path, cfg, road=None, fp=None):
    fp = fp or Footprint(4.5, 1.8, n_discs=3)
    comp = Avoidance(cfg, obstacles, path, fp, N, DT, road)
    ref = Avoidance(cfg, obstacles, path, fp, N, DT, road)
    ref.compiled = False
    return comp, ref


def _same_terms(t1, t2):
    assert t1.sides == t2.sides
    np.testing.assert_allclose(t1.rows_a, t2.rows_a, rtol=0, atol=TOL)
    assert np.array_equal(np.isinf(t1.rows_b), np.isinf(t2.rows_b))
    fin = np.isfinite(t2.rows_b)
    np.testing.assert_allclose(t1.rows_b[fin], t2.rows_b[fin], rtol=0, atol=TOL)


@pytest.mark.parametrize("name", ["straight", "circle", "waypoints"])
def test_compiled_terms_match_numpy_on_random_scenes(name):
    rng = np.random.default_rng(7)
    path = _paths()[name]
    cfg = AvoidanceConfig("hard", margin_m=0.3, influence_m=30.0, max_obstacles=4)
    for trial in range(30):
        obstacles = _scene(rng, path, int(rng.integers(1, 9)), lifetimes=trial % 2 == 1)
        road = Road.constant(float(rng.uniform(4.0, 12.0))) if trial % 3 else None
        comp, ref = _pair(obstacles, path, cfg, road)
        mem1, mem2 = AvoidanceMemory(), AvoidanceMemory()
        for step in range(3):
            t_s = 0.3 * step
            s_arr, Xlin = _state(rng, path)
            assert comp.relevant(t_s, Xlin[0, :2]) == ref.relevant(t_s, Xlin[0, :2])
            t1 = comp.terms(t_s, Xlin[0], Xlin, s_arr, mem1)
            t2 = ref.terms(t_s, Xlin[0], Xlin, s_arr, mem2)
            _same_terms(t1, t2)
            assert mem1.sides == mem2.sides


@pytest.mark.parametrize("name", ["straight", "circle", "waypoints"])
def test_compiled_tracks_match_numpy(name):
    rng = np.random.default_rng(11)
    path = _paths()[name]
    cfg = AvoidanceConfig("hard", margin_m=0.2, influence_m=50.0, max_obstacles=6)
    for trial in range(30):
        obstacles = _scene(rng, path, 6, lifetimes=False, trajectories=trial % 3 == 2)
        comp, ref = _pair(obstacles, path, cfg)
        s_arr, _ = _state(rng, path)
        rel = list(rng.permutation(6)[: int(rng.integers(0, 7))])
        b1, c1, o1, packed = comp._tracks(rel, 0.7, s_arr)
        b2, c2, o2, none = ref._tracks(rel, 0.7, s_arr)
        assert packed is not None and none is None
        for j in rel:
            np.testing.assert_allclose(c1[j], c2[j], rtol=0, atol=TOL)
            assert (o1[j] is None) == (o2[j] is None)
            if o1[j] is not None:
                np.testing.assert_allclose(o1[j], o2[j], rtol=0, atol=TOL)
            for f in ("s_ref", "s_lo", "s_hi", "e_lo", "e_hi"):
                np.testing.assert_allclose(getattr(b1[j], f), getattr(b2[j], f), rtol=0, atol=TOL)


@pytest.mark.parametrize("name", ["straight", "circle", "waypoints"])
def test_compiled_rows_match_numpy_for_every_side_and_mode(name):
    """The rows kernel for random sides, followers and lifetimes (terms picks them by rule; here
    every combination), from compiled tracks and from numpy tracks (recorded trajectories)."""
    rng = np.random.default_rng(5)
    path = _paths()[name]
    cfg = AvoidanceConfig("hard", margin_m=0.25, influence_m=float(rng.uniform(2.0, 30.0)), max_obstacles=5)
    for trial in range(40):
        obstacles = _scene(rng, path, 5, lifetimes=True, trajectories=trial % 2 == 0)
        comp, ref = _pair(obstacles, path, cfg, fp=Footprint(4.0, 1.7, 1.0, n_discs=int(rng.integers(1, 4))))
        s_arr, Xlin = _state(rng, path)
        t_s = float(rng.uniform(0.0, 1.0))
        rel = list(rng.permutation(5)[: int(rng.integers(0, 6))])
        sides = {j: int(rng.choice([SIDE_LEFT, SIDE_RIGHT, SIDE_BLOCKED])) for j in rel}
        following = {j for j in rel if rng.random() < 0.3}
        ahead = {j: bool(rng.random() < 0.7) for j in rel}  # where a blocked one gets a stop row
        times = t_s + DT * np.arange(1, N + 1)
        present = {j: obstacles[j].present(times) if obstacles[j].has_lifetime else ref._always for j in rel}
        boxes, centers, world, packed = comp._tracks(rel, t_s, s_arr)
        assert packed is not None
        a1, b1 = (
            v.copy()
            for v in comp._hard_rows(Xlin, s_arr, rel, boxes, centers, world, sides, present, following, packed, ahead)
        )
        a3, b3 = (
            v.copy()
            for v in comp._hard_rows(Xlin, s_arr, rel, boxes, centers, world, sides, present, following, None, ahead)
        )
        boxes, centers, world, _ = ref._tracks(rel, t_s, s_arr)
        a2, b2 = ref._hard_rows(Xlin, s_arr, rel, boxes, centers, world, sides, present, following, None, ahead)
        for a, b in ((a1, b1), (a3, b3)):
            np.testing.assert_allclose(a, a2, rtol=0, atol=TOL)
            assert np.array_equal(np.isinf(b), np.isinf(b2))
            np.testing.assert_allclose(b[np.isfinite(b2)], b2[np.isfinite(b2)], rtol=0, atol=TOL)


@dataclass(frozen=True)
class _Circling:
    """A motion of the user's own (no compiled form): a circle of radius 3 m."""

    def offset(self, t_s):
        return 3.0 * np.cos(t_s) - 3.0, 3.0 * np.sin(t_s), 0.0 * np.asarray(t_s)


def test_compiled_pose_equals_the_obstacle_motion():
    """pose_at against Obstacle.pose_at (np.interp for recorded trajectories) at times before,
    inside, on and after the samples."""
    rng = np.random.default_rng(13)
    obstacles = _scene(rng, _paths()["straight"], 40, lifetimes=False, trajectories=True)
    tab = obstacle_table(obstacles)
    assert tab.all_simple
    for j, ob in enumerate(obstacles):
        m = ob.motion
        times = list(rng.uniform(-2.0, 8.0, 20)) + (list(m.t_s) if isinstance(m, TrajectoryMotion) else [])
        for t in times:
            np.testing.assert_allclose(pose_at(j, float(t), *tab.motion), ob.pose_at(float(t)), rtol=0, atol=TOL)


def test_a_recorded_pose_is_numpys_interpolation_to_the_bit():
    """pose_at searches the three columns' common sample once: each column is np.interp's value
    exactly, before, on, between and after the samples, with infinite offsets and a NaN time."""
    rng = np.random.default_rng(5)
    n = 9
    tr_t = np.cumsum(rng.uniform(0.05, 0.3, n))
    tr_d = rng.normal(0.0, 5.0, (n, 3))
    tr_d[4, 1] = np.inf
    tr_d[5, 1] = np.inf
    tr_d[6, 2] = -np.inf
    tr_d[7, 2] = np.inf
    pose = np.array([[3.7, -1.2, 0.4]])
    vel = np.zeros((1, 2))
    lo, hi = np.array([0]), np.array([n])
    times = [*rng.uniform(tr_t[0] - 1.0, tr_t[-1] + 1.0, 200), *tr_t, tr_t[0] - 1e-12, tr_t[-1] + 1e-12, math.nan]
    for t in times:
        got = pose_at(0, float(t), pose, vel, lo, hi, tr_t, tr_d)
        want = [pose[0, c] + np.interp(t, tr_t, tr_d[:, c]) for c in range(3)]
        np.testing.assert_array_equal(np.array(got), np.array(want))


def test_recorded_trajectories_are_compiled_and_other_motions_keep_numpy():
    rng = np.random.default_rng(3)
    path = _paths()["straight"]
    obstacles = _scene(rng, path, 6, lifetimes=True, trajectories=True)
    obstacles.append(
        Obstacle(
            Circle(1.0), (10.0, 0.0, 0.0), TrajectoryMotion(np.array([0.0, 1.0]), np.zeros(2), np.zeros(2), np.zeros(2))
        )
    )
    cfg = AvoidanceConfig("hard", influence_m=40.0, max_obstacles=8)
    comp, ref = _pair(obstacles, path, cfg)
    assert comp._obstacle_table().all_simple
    for _ in range(5):
        s_arr, Xlin = _state(rng, path)
        assert comp._tracks(comp.relevant(0.4, Xlin[0, :2]), 0.4, s_arr)[3] is not None
        _same_terms(
            comp.terms(0.4, Xlin[0], Xlin, s_arr, AvoidanceMemory()),
            ref.terms(0.4, Xlin[0], Xlin, s_arr, AvoidanceMemory()),
        )
    own = Obstacle(rectangle(4.0, 2.0), (12.0, 1.0, 0.0), _Circling())  # type: ignore[arg-type]
    comp, ref = _pair([*obstacles, own], path, cfg)
    assert not comp._obstacle_table().all_simple
    for _ in range(5):
        s_arr, Xlin = _state(rng, path)
        rel = comp.relevant(0.4, Xlin[0, :2])
        assert rel == ref.relevant(0.4, Xlin[0, :2])
        if len(obstacles) in rel:
            assert comp._tracks(rel, 0.4, s_arr)[3] is None  # the numpy tracks
        _same_terms(
            comp.terms(0.4, Xlin[0], Xlin, s_arr, AvoidanceMemory()),
            ref.terms(0.4, Xlin[0], Xlin, s_arr, AvoidanceMemory()),
        )


def test_obstacle_table_follows_replaced_obstacles():
    path = _paths()["straight"]
    comp, _ = _pair([Obstacle(Circle(1.0), (5.0, 0.0, 0.0))], path, AvoidanceConfig("hard", influence_m=50.0))
    assert comp.relevant(0.0, np.zeros(2)) == [0]
    comp.obstacles = [Obstacle(Circle(1.0), (90.0, 0.0, 0.0)), Obstacle(Circle(1.0), (4.0, 0.0, 0.0))]
    assert comp.relevant(0.0, np.zeros(2)) == [1]


@pytest.mark.parametrize("backend", ["fast", "osqp"])
def test_p4_drive_rows_compiled_equal_numpy(backend):
    """On a recorded P4 drive (the first 60 steps, the controller's own inputs), the compiled
    terms equal the numpy reference's to 1e-12: rows, sides and the side memory."""
    prob = PROBLEMS["P4"]()
    c = make_controller(prob, backend)
    av = c.avoidance
    assert av.compiled and av._compiled_path() is not None and av._obstacle_table().all_simple
    ref = copy.copy(av)
    ref.compiled = False
    ref._a, ref._b = av._a.copy(), av._b.copy()
    checked = []
    real = av.terms

    def recording(t_s, x, Xlin, s_arr, memory, *rest):
        before = copy.deepcopy(memory)
        out = real(t_s, x, Xlin, s_arr, memory, *rest)
        got = (out.rows_a.copy(), out.rows_b.copy(), dict(out.sides), dict(memory.sides))
        want = ref.terms(t_s, x, Xlin, s_arr, before, *rest)
        checked.append((got, (want.rows_a.copy(), want.rows_b.copy(), dict(want.sides), dict(before.sides))))
        return out

    av.terms = recording
    plant = Plant(prob.model)
    x = prob.x0.copy()
    warm = c.initial_warm(x)
    for _ in range(60):
        out = c.step(x, warm)
        warm = out.warm
        x = plant.step(x, out.u, prob.dt_s)
    assert len(checked) >= 60
    for (a1, b1, s1, m1), (a2, b2, s2, m2) in checked:
        assert s1 == s2 and m1 == m2
        np.testing.assert_allclose(a1, a2, rtol=0, atol=TOL)
        assert np.array_equal(np.isinf(b1), np.isinf(b2))
        np.testing.assert_allclose(b1[np.isfinite(b2)], b2[np.isfinite(b2)], rtol=0, atol=TOL)


def _decide(boxes, moving, prev=None, *, road=3.5, follow=False, e_car=0.0):
    """The compiled decisions for boxes given as (s_ref, s_lo, s_hi, e_lo, e_hi) arrays (K,)
    each, on s_arr 0, 2, .., 8 m, dt 0.1 s, a road +-``road`` m (None: no road), passing room
    2 m, reach 3 m, body 4 x 1.7 m, stop distance 1 m."""
    from mpcdrive.ocp.avoidance_compiled import SIDE_NONE, decide

    n = len(boxes)
    box = np.array([[np.broadcast_to(np.asarray(v, float), (5,)) for v in b] for b in boxes]).reshape(n, 5, 5)
    side, fol, ahead = np.empty(n, np.int64), np.empty(n, np.bool_), np.empty(n, np.bool_)
    prev = np.full(n, SIDE_NONE, np.int64) if prev is None else np.array(prev, np.int64)
    tab = np.zeros(1)
    decide(
        box, np.array(moving, np.bool_), np.arange(0.0, 10.0, 2.0), road is not None, tab,
        tab + (road or 0.0), tab - (road or 0.0), 0.0, 2.0, 3.0, 0.1, 1.0, follow, e_car, 0.85, 2.0, 1.0,
        prev, side, fol, ahead,
    )  # fmt: skip
    return side.tolist(), fol.tolist(), ahead.tolist()


def test_decisions_pass_on_the_roomier_side_keep_a_side_with_room_and_block_without():
    right_roomier = (5.0, 4.0, 6.0, 0.5, 1.5)  # room left 2.0 (just enough), right 4.0
    no_room = (5.0, 4.0, 6.0, -1.0, 1.0)
    assert _decide([right_roomier], [False])[0] == [SIDE_RIGHT]
    assert _decide([right_roomier], [False], [SIDE_LEFT])[0] == [SIDE_LEFT]  # kept: it still has room
    assert _decide([no_room], [False], road=2.5)[0] == [SIDE_BLOCKED]  # 1.5 m each side < 2 m
    assert _decide([no_room], [False])[0] == [SIDE_LEFT]  # 2.5 m each side: a tie goes left
    assert _decide([no_room], [False], road=None)[0] == [SIDE_LEFT]  # no road: no edge to run out of


def test_decisions_yield_to_oncoming_and_crossing_traffic_on_the_road_only():
    s = np.array([10.0, 8.0, 6.0, 4.0, 2.0])  # 20 m/s towards the car, met at step 2
    oncoming = (s, s - 2.0, s + 2.0, -0.5, 0.5)
    beside_the_road = (s, s - 2.0, s + 2.0, 4.0, 5.0)
    e = np.array([-8.0, -6.0, -4.0, -2.0, 0.0])  # crossing the road at 20 m/s, standing in s
    crossing = (6.0, 5.0, 7.0, e - 0.5, e + 0.5)
    assert _decide([oncoming, beside_the_road, crossing], [True, True, True])[0] == [
        SIDE_BLOCKED,
        SIDE_RIGHT,
        SIDE_BLOCKED,
    ]
    # without a road there is nothing to yield on: passed beside
    assert _decide([oncoming], [True], road=None)[0] == [SIDE_LEFT]
    # the same car standing (not moving) is passed, not yielded to
    assert _decide([(6.0, 4.0, 8.0, -0.5, 0.5)], [False])[0] == [SIDE_LEFT]


def test_decisions_find_followers_and_stop_lines():
    behind = (-5.0, -6.0, -3.0, -0.5, 0.5)  # wholly behind the rear (s0 - 2 m), in the lane
    behind_beside = (-5.0, -6.0, -3.0, 1.0, 2.0)  # behind, in the next lane
    touching = (-2.0, -3.0, -1.5, -0.5, 0.5)  # its front beyond the car's rear
    ahead_near = (6.0, 5.0, 7.0, -0.5, 0.5)
    ahead_far = (12.0, 9.5, 14.0, -0.5, 0.5)  # near end beyond the last reference + 1 m
    boxes = [behind, behind_beside, touching, ahead_near, ahead_far]
    _, fol, ahead = _decide(boxes, [False] * 5, follow=True)
    assert fol == [True, False, False, False, False]
    assert ahead == [False, False, False, True, False]
    assert _decide(boxes, [False] * 5, follow=False)[1] == [False] * 5
    assert _decide([behind_beside], [False], follow=True, e_car=1.2)[1] == [True]  # the car beside it


def _corridor(boxes, use, side, present=None, lo=-3.0, hi=3.0):
    """The compiled corridor bounds of steps 1..4 for boxes as in :func:`_decide`, on s_arr 0, 2,
    .., 8 m, margin 0.5 m, body 4 x 1.7 m (reach 2.5 m, clearance 1.35 m), road bounds lo, hi."""
    from mpcdrive.ocp.avoidance_compiled import corridor_bounds

    n = len(boxes)
    box = np.array([[np.broadcast_to(np.asarray(v, float), (5,)) for v in b] for b in boxes]).reshape(n, 5, 5)
    pres = np.ones((n, 4), np.bool_) if present is None else np.array(present, np.bool_)
    lo_a, hi_a = np.full(4, lo), np.full(4, hi)
    corridor_bounds(
        box,
        np.array(use, np.bool_),
        np.array(side, np.int64),
        pres,
        np.arange(0.0, 10.0, 2.0),
        0.5,
        2.0,
        0.85,
        lo_a,
        hi_a,
    )
    return lo_a.tolist(), hi_a.tolist()


def test_corridor_bounds_narrow_the_road_beside_obstacles_within_reach():
    # s 4..6 m, e 0.5..1.5 m: reaches the references at s 2, 4, 6, 8 (steps 1..4) within 2.5 m
    box = (5.0, 4.0, 6.0, 0.5, 1.5)
    lo, hi = _corridor([box], [True], [SIDE_RIGHT])
    assert hi == pytest.approx([0.5 - 1.35] * 4) and lo == [-3.0] * 4
    lo, hi = _corridor([box], [True], [SIDE_LEFT])
    assert lo == pytest.approx([1.5 + 1.35] * 4) and hi == [3.0] * 4
    # out of reach of s 8 m at steps 3, 4 once it ends at 5 m: s_hi 5 + 2.5 = 7.5 < 8
    short = (4.0, 3.0, 5.0, 0.5, 1.5)
    assert _corridor([short], [True], [SIDE_RIGHT])[1] == pytest.approx([-0.85, -0.85, -0.85, 3.0])
    # not used (a car following), absent at a step, blocked: no bound from it
    assert _corridor([box], [False], [SIDE_RIGHT]) == ([-3.0] * 4, [3.0] * 4)
    assert _corridor([box], [True], [SIDE_RIGHT], [[True, False, True, True]])[1] == pytest.approx(
        [-0.85, 3.0, -0.85, -0.85]
    )
    assert _corridor([box], [True], [SIDE_BLOCKED]) == ([-3.0] * 4, [3.0] * 4)


def test_corridor_bounds_keep_the_tube_non_empty_and_take_the_tightest():
    left_of = (5.0, 4.0, 6.0, -1.0, 0.0)  # passed on the left: lo = 1.35
    right_of = (5.0, 4.0, 6.0, 0.5, 1.0)  # passed on the right: hi = -0.85
    lo, hi = _corridor([left_of, right_of], [True, True], [SIDE_LEFT, SIDE_RIGHT])
    assert lo == hi and lo == pytest.approx([0.25] * 4)  # crossed: both at the middle
    tighter = (5.0, 4.0, 6.0, 0.2, 1.0)  # hi = -1.15
    assert _corridor([right_of, tighter], [True, True], [SIDE_RIGHT, SIDE_RIGHT])[1] == pytest.approx([0.2 - 1.35] * 4)
