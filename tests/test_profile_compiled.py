"""The compiled speed profile of the fast controller against SpeedProfile / ConstantSpeed: arc
lengths reached after given times and speeds there, on closed and open paths, from rest, to a
stop, past the end and across a stretch at standstill (infinite segment times)."""

from __future__ import annotations

import numpy as np
import pytest

from mpcdrive.paths import CirclePath, ConstantSpeed, SpeedProfile, StraightPath, WaypointPath
from mpcdrive.paths.profile_compiled import np_interp, profile_arc_lengths, profile_array, profile_speed

TOL = 1e-9
DT_S = 0.05
N = 40


def _with_standstill(prof: SpeedProfile, i0: int, i1: int) -> SpeedProfile:
    """``prof`` with zero speed on grid points i0..i1 and its time table rebuilt as the
    constructor builds it (segments between two stops take forever)."""
    prof.v_mps = prof.v_mps.copy()
    prof.v_mps[i0 : i1 + 1] = 0.0
    v = np.r_[prof.v_mps, prof.v_mps[0]] if prof.closed else prof.v_mps
    vs = v[1:] + v[:-1]
    seg_t = np.where(vs > 0, 2.0 * prof.ds_m / np.maximum(vs, 1e-300), np.inf)
    prof._t_grid = np.r_[0.0, np.cumsum(seg_t)]
    return prof


def _profiles():
    loop = WaypointPath([[0, 0], [4, 0], [5, 3], [2, 5], [-1, 3]], closed=True)
    wiggle = WaypointPath([[0, 0], [3, 1], [6, -1], [9, 0.5], [12, 0]], smoothing=0.0)
    return {
        "closed circle": SpeedProfile(CirclePath((0.0, 0.0), 3.0), 6.0, 2.0, 3.0, 5.0),
        "closed waypoints": SpeedProfile(loop, 4.0, 2.0, 3.0, 3.0, curvature_window_m=0.3),
        "open from rest to a stop": SpeedProfile(
            StraightPath([0, 0], [6, 0]), 5.0, 2.0, 4.0, 8.0, v_start_mps=0.0, v_end_mps=0.0
        ),
        "open, going on past the end": SpeedProfile(wiggle, 3.0, 1.5, 2.0, 2.5, v_start_mps=0.0),
        "open with a standstill": _with_standstill(
            SpeedProfile(StraightPath([0, 0], [8, 0]), 5.0, 2.0, 4.0, 3.0, ds_m=0.05), 60, 70
        ),
    }


def _starts(prof: SpeedProfile) -> np.ndarray:
    L = prof.length_m
    grid = prof.s_m[[0, 1, len(prof.s_m) // 3, -2, -1]]
    return np.r_[grid, 0.37 * L, 0.999 * L, L, 1.7 * L, -0.2, 2.5 * L + 0.013, -1.3 * L]


@pytest.mark.parametrize("name", list(_profiles()))
def test_compiled_profile_equals_speed_profile(name):
    prof = _profiles()[name]
    arr = profile_array(prof)
    out = np.empty(N + 1)
    t = DT_S * np.arange(N + 1)
    for s0 in _starts(prof):
        ref = np.asarray(prof.arc_length_after(s0, t), float)
        profile_arc_lengths(arr, s0, DT_S, out)
        assert np.array_equal(np.isfinite(out), np.isfinite(ref)), (s0, out, ref)
        assert np.allclose(out, ref, rtol=0.0, atol=TOL), (s0, np.abs(out - ref).max())
        for s in np.r_[ref, s0]:
            assert abs(profile_speed(arr, s) - prof.speed(s)) <= TOL, (s0, s)


def test_standstill_and_stop_are_really_exercised():
    """The cases above reach the situations they are named for."""
    profs = _profiles()
    still = profs["open with a standstill"]
    assert np.isinf(still._t_grid[-1])
    s = still.arc_length_after(0.0, [0.0, 100.0])
    assert s[1] == pytest.approx(still.s_m[60])  # stopped at the standstill
    stop = profs["open from rest to a stop"]
    assert stop.v_mps[0] == 0.0 and stop.v_mps[-1] == 0.0
    assert stop.arc_length_after(0.0, [50.0])[0] == pytest.approx(stop.length_m)
    past = profs["open, going on past the end"]
    assert past.arc_length_after(past.length_m, [1.0])[0] > past.length_m


def test_compiled_constant_speed():
    arr = profile_array(ConstantSpeed(1.3))
    out = np.empty(N + 1)
    profile_arc_lengths(arr, 2.5, DT_S, out)
    assert np.allclose(out, ConstantSpeed(1.3).arc_length_after(2.5, DT_S * np.arange(N + 1)), rtol=0.0, atol=TOL)
    assert profile_speed(arr, 7.0) == 1.3


def test_profiles_without_a_compiled_form_are_none():
    class Ramp:
        def speed(self, s_m):
            return 1.0 + 0.1 * np.asarray(s_m)

    assert profile_array(Ramp()) is None


def test_one_point_interpolation_is_numpys_bit_for_bit():
    rng = np.random.default_rng(3)
    t = 0.2 * np.arange(31)
    fps = (np.cumsum(rng.uniform(0.0, 3.0, 31)), rng.normal(size=31), rng.normal(size=31))
    # the nodes themselves, the last one, points between and points a rounding away from a node
    xs = np.r_[t, rng.uniform(0.0, t[-1], 200), np.nextafter(t[1:-1], 0.0), np.nextafter(t[1:-1], 9.0)]
    for x in xs.tolist():
        for fp in fps:
            assert float(np_interp(x, t, fp)) == float(np.interp(x, t, fp)), x
