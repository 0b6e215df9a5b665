"""Speed profiles (friction and acceleration limits) and CSV tracks (loading, bad files, the
packaged tracks and their generator)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpcdrive.models import get_preset
from mpcdrive.paths import (
    CirclePath,
    ConstantSpeed,
    SpeedProfile,
    StraightPath,
    WaypointPath,
    load_track_csv,
    track_from_text,
    write_track_csv,
)
from mpcdrive.scenarios.tracks import packaged_track_names, packaged_track_text
from mpcdrive.scenarios.tracks.generate import track_points, write_tracks

MU_G = 1.0489 * 9.81


def _track(name):
    return track_from_text(packaged_track_text(name), name, name=name)


def _check_limits(prof: SpeedProfile, a_lat, a_max, b_max):
    v = prof.v_mps
    assert np.all(v >= 0) and np.all(v <= prof.v_max_mps + 1e-12)
    # lateral acceleration on the (windowed) curvature
    assert np.all(v**2 * prof.abs_kappa <= a_lat * (1 + 1e-9))
    acc = prof.longitudinal_accel()
    assert acc.max() <= a_max * (1 + 1e-9)
    assert acc.min() >= -b_max * (1 + 1e-9)
    if prof.friction_circle:
        # combined: (a_long / a_max)^2 + (a_lat / a_lat,max)^2 <= 1, with the lateral acceleration at
        # the start of an accelerating segment and at the end of a braking one
        vv = np.r_[v, v[0]] if prof.closed else v
        kk = np.r_[prof.abs_kappa, prof.abs_kappa[0]] if prof.closed else prof.abs_kappa
        lat = vv**2 * kk / a_lat
        lat_seg = np.where(acc > 0, lat[:-1], lat[1:])
        lim = np.where(acc > 0, a_max, b_max)
        assert np.all((acc / lim) ** 2 + lat_seg**2 <= 1.0 + 1e-6)


@pytest.mark.parametrize("name", ["raceway", "hairpins"])
@pytest.mark.parametrize("frac", [0.5, 0.8, 1.0])
def test_profile_respects_friction_and_acceleration_limits(name, frac):
    tr = _track(name)
    prof = SpeedProfile.from_friction(
        tr.path,
        1.0489,
        lateral_fraction=frac,
        accel_max_mps2=4.0,
        decel_max_mps2=6.0,
        v_max_mps=9.0,
        curvature_window_m=0.3,
    )
    _check_limits(prof, frac * MU_G, 4.0, 6.0)
    # the lateral-acceleration limit is reached in the tightest bend
    assert np.max(prof.lateral_accel()) == pytest.approx(frac * MU_G, rel=0.02)
    assert prof.lap_time_s > tr.path.length_m / 9.0


def test_car_slows_before_a_bend():
    """Straight then a circle of radius 2 m: the speed falls monotonically over the braking
    distance before the bend and enters it at sqrt(mu g r)."""
    pts = [(x, 0.0) for x in np.arange(0.0, 20.0, 0.5)]
    pts += [(20.0 + 2.0 * math.sin(t), 2.0 - 2.0 * math.cos(t)) for t in np.linspace(0.1, math.pi, 30)]
    path = WaypointPath(pts)
    prof = SpeedProfile(path, MU_G, 3.0, 5.0, 12.0, friction_circle=False)
    s_bend = 20.0
    v_bend = math.sqrt(MU_G * 2.0)
    assert prof.speed(s_bend + 2.0) == pytest.approx(v_bend, rel=0.03)
    brake_dist = (12.0**2 - v_bend**2) / (2 * 5.0)
    s = np.linspace(s_bend - brake_dist + 0.5, s_bend - 0.3, 50)
    v = prof.speed(s)
    assert np.all(np.diff(v) < 0)
    # v^2 = v_bend^2 + 2 b (s_bend - s) before the bend (up to the spline's curvature onset)
    np.testing.assert_allclose(v[:20] ** 2, v_bend**2 + 2 * 5.0 * (s_bend - s[:20]), rtol=0.05)
    assert prof.speed(0.0) == pytest.approx(12.0)


def test_closed_profile_is_periodic_and_open_ends_can_be_pinned():
    circle = CirclePath(radius_m=3.0)
    prof = SpeedProfile(circle, 6.0, 2.0, 2.0, 10.0)
    np.testing.assert_allclose(prof.v_mps, math.sqrt(6.0 * 3.0), rtol=1e-6)
    assert prof.speed(5 * circle.length_m + 0.3) == pytest.approx(prof.speed(0.3))
    line = StraightPath([0, 0], [50, 0])
    stop_go = SpeedProfile(line, 5.0, 2.0, 4.0, 8.0, v_start_mps=0.0, v_end_mps=0.0)
    assert stop_go.speed(0.0) == 0.0 and stop_go.speed(50.0) == 0.0
    assert stop_go.speed(10.0) == pytest.approx(math.sqrt(2 * 2.0 * 10.0), rel=0.01)
    assert stop_go.speed(45.0) == pytest.approx(math.sqrt(2 * 4.0 * 5.0), rel=0.01)
    _check_limits(stop_go, 5.0, 2.0, 4.0)
    assert ConstantSpeed(3.0).speed(np.arange(3.0)).tolist() == [3.0, 3.0, 3.0]


def test_an_open_profile_starts_where_the_car_is():
    """A path beginning 2 m behind the car: the start speed holds up to the car and the clock
    starts there (without ``s_start_m`` the speed at the car would already be 4 m/s, not 0.5)."""
    line = StraightPath([0, 0], [50, 0])
    kw = dict(v_start_mps=0.5, v_end_mps=0.0)
    prof = SpeedProfile(line, 5.0, 2.0, 4.0, 8.0, s_start_m=2.0, **kw)
    assert prof.speed(0.0) == prof.speed(2.0) == pytest.approx(0.5)
    assert prof.speed(12.0) == pytest.approx(math.sqrt(0.25 + 2 * 2.0 * 10.0), rel=0.01)
    assert prof.time_at(2.0) == 0.0 and prof.time_at(1.0) == 0.0
    v_end = math.sqrt(0.25 + 2 * 2.0 * 10.0)  # time of the first 10 m: (v - v0) / a
    assert prof.time_at(12.0) == pytest.approx((v_end - 0.5) / 2.0, rel=0.02)
    assert SpeedProfile(line, 5.0, 2.0, 4.0, 8.0, **kw).speed(2.0) == pytest.approx(math.sqrt(0.25 + 8.0), rel=0.01)
    # a car at rest holds the profile at 0 up to it, and the clock still starts there
    rest = SpeedProfile(line, 5.0, 2.0, 4.0, 8.0, s_start_m=2.0, v_start_mps=0.0, v_end_mps=0.0)
    assert rest.speed(2.0) == 0.0 and rest.time_at(2.0) == 0.0 and math.isfinite(rest.time_at(20.0))
    with pytest.raises(ValueError, match="s_start_m"):
        SpeedProfile(line, 5.0, 2.0, 4.0, 8.0, s_start_m=60.0)


def test_a_slower_approach_caps_the_top_speed_and_then_speeds_up():
    """``top_speed_until``: 5 m/s up to 40 m, then on to 10 m/s at 2 m/s^2 (reached at
    40 + (100 - 25) / 4 = 58.75 m); it takes longer than without the cap, by the slower stretch."""
    line = StraightPath([0, 0], [150, 0])
    kw = dict(v_start_mps=5.0, v_end_mps=0.0, ds_m=0.05)
    free = SpeedProfile(line, 5.0, 2.0, 4.0, 10.0, **kw)
    slow = SpeedProfile(line, 5.0, 2.0, 4.0, 10.0, top_speed_until=((40.0, 5.0),), **kw)
    s = np.linspace(0.0, 40.0, 81)
    assert np.max(slow.speed(s)) <= 5.0 + 1e-12
    assert slow.speed(50.0) == pytest.approx(math.sqrt(25.0 + 2 * 2.0 * 10.0), rel=1e-3)
    assert slow.speed(70.0) == pytest.approx(10.0) and free.speed(20.0) == pytest.approx(10.0)
    _check_limits(slow, 5.0, 2.0, 4.0)
    # the first 40 m take 8 s at 5 m/s; without the cap the car is at 10 m/s after 18.75 m
    assert slow.time_at(40.0) == pytest.approx(8.0, rel=1e-3)
    assert free.time_at(40.0) == pytest.approx(2.5 + 21.25 / 10.0, rel=1e-3)
    with pytest.raises(ValueError, match="top_speed_until"):
        SpeedProfile(line, 5.0, 2.0, 4.0, 10.0, top_speed_until=((40.0, 0.0),))


@pytest.mark.parametrize(
    "kw",
    [
        dict(lateral_accel_max_mps2=0.0),
        dict(accel_max_mps2=-1.0),
        dict(v_max_mps=float("nan")),
        dict(decel_max_mps2=float("inf")),
    ],
)
def test_profile_rejects_bad_limits_naming_them(kw):
    args = dict(lateral_accel_max_mps2=5.0, accel_max_mps2=2.0, decel_max_mps2=2.0, v_max_mps=5.0)
    args.update(kw)
    with pytest.raises(ValueError, match=next(iter(kw))):
        SpeedProfile(CirclePath(), **args)


# ------------------------------------------------------------------ CSV tracks
def test_packaged_tracks_load_with_widths():
    assert {"raceway", "hairpins"} <= set(packaged_track_names())
    race, hair = _track("raceway"), _track("hairpins")
    assert race.closed and not hair.closed
    assert race.min_half_width_m == pytest.approx(0.8) and hair.min_half_width_m == pytest.approx(0.7)
    wr, wl = race.widths_at(np.array([0.0, 10.0, race.path.length_m + 1.0]))
    np.testing.assert_allclose(wr, 0.8)
    np.testing.assert_allclose(wl, 0.8)
    left, right = race.boundaries()
    assert np.all(np.isfinite(left)) and left.shape == right.shape
    # the start: origin, heading east
    assert np.allclose(race.path.position(0.0), 0.0, atol=1e-6)
    assert abs(race.path.heading(0.0)) < 1e-3


def test_hairpins_are_about_three_minimum_turning_radii():
    hair = _track("hairpins")
    r_min = get_preset("f1tenth").min_turning_radius_m
    s = np.linspace(0.0, hair.path.length_m, 5000)
    radius = 1.0 / np.max(np.abs(hair.path.curvature(s)))
    assert 2.7 * r_min <= radius <= 3.3 * r_min
    # three 180-degree hairpins: the heading changes sign of travel three times
    turns = np.abs(np.diff(np.unwrap(hair.path.heading(np.array([0.0, hair.path.length_m])))))
    assert turns[0] == pytest.approx(math.pi, abs=0.05)  # ends heading west


def test_shipped_csv_files_equal_the_generator_output(tmp_path):
    written = write_tracks(tmp_path)
    for f in written:
        assert f.read_text(encoding="utf-8") == packaged_track_text(f.stem), f"{f.stem}.csv is stale: regenerate"
    for name in packaged_track_names():
        pts = track_points(name)
        assert np.allclose(pts[0], 0.0)


def test_csv_round_trip_and_f1tenth_style_headers(tmp_path):
    pts = np.array([[0, 0], [1, 0.2], [2, 0.1], [3, -0.3], [4, 0.0]], float)
    f = tmp_path / "t.csv"
    write_track_csv(f, pts, [0.5] * 5, [0.6] * 5)
    tr = load_track_csv(f)
    assert not tr.closed and tr.name == "t"
    np.testing.assert_allclose(tr.points, pts)
    np.testing.assert_allclose(tr.width_left_m, 0.6)
    g = tmp_path / "semi.csv"
    g.write_text("# s_m; x_m; y_m; psi_rad\n0; 0; 0; 0\n1; 1; 0; 0\n2; 2; 1; 0\n3; 3; 1; 0\n")
    tr2 = load_track_csv(g)
    assert not tr2.has_widths and tr2.min_half_width_m is None
    with pytest.raises(ValueError, match="no road widths"):
        tr2.widths_at(0.0)
    # a closed loop is detected from the data
    th = np.linspace(0, 2 * math.pi, 40, endpoint=False)
    h = tmp_path / "loop.csv"
    write_track_csv(h, np.c_[5 * np.cos(th), 5 * np.sin(th)])
    assert load_track_csv(h).closed
    assert not load_track_csv(h, closed=False).closed


@pytest.mark.parametrize(
    "text, words",
    [
        ("", "empty file"),
        ("# a, b\n1, 2\n", "x_m, y_m"),
        ("x_m, y_m\n0, 0\n1, 1\n", "at least 3 waypoints"),
        ("x_m, y_m\n0, 0\n1, abc\n2, 2\n", "line 3: column y_m: not a number"),
        ("x_m, y_m\n0, 0\n1, nan\n2, 2\n", "line 3: column y_m: not finite"),
        ("x_m, y_m, w_tr_right_m\n0, 0, 1\n1, 1, 1\n2, 2, 1\n", "both"),
        (
            "x_m, y_m, w_tr_right_m, w_tr_left_m\n0, 0, 1, 1\n1, 1, -1, 1\n2, 2, 1, 1\n",
            "line 3: column w_tr_right_m: road width must be positive",
        ),
        ("x_m, y_m\n0, 0\n1, 1, 7\n2, 2\n", "line 3: expected 2 values"),
        ("x_m, y_m\n0, 0\n1, 1\n1, 1\n2, 2\n", "line 4: waypoint repeats"),
        ("x_m, x_m, y_m\n0, 0, 0\n", "duplicate column"),
    ],
)
def test_bad_csv_files_give_clear_errors(tmp_path, text, words):
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(ValueError) as e:
        load_track_csv(f)
    msg = str(e.value)
    assert msg.startswith(str(f)) and "\n" not in msg
    assert words in msg


def test_missing_track_file(tmp_path):
    with pytest.raises(ValueError, match="track file not found"):
        load_track_csv(tmp_path / "nope.csv")
