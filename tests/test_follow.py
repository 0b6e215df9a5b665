"""The horizon references held back behind a moving stop line (car following), and the planner's
relations as the controller takes them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpcdrive.ocp.follow import follow_references
from mpcdrive.ocp.relations import REL_CLEAR, REL_RIGHT, checked_relations

N, DT = 30, 0.1


def _free(v_mps: float, s0: float = 0.0):
    """Free references at constant speed ``v_mps`` from ``s0``."""
    return s0 + v_mps * DT * np.arange(N + 1), np.full(N + 1, v_mps)


def test_nothing_ahead_and_no_cap_leaves_the_free_references():
    s, v = _free(10.0)
    assert follow_references(s, v, None, 10.0, DT, 3.0) is None
    assert follow_references(s, v, np.full(N + 1, 1e6), 10.0, DT, 3.0) is None


@pytest.mark.parametrize("gap_m", [5.0, 20.0, 40.0])
@pytest.mark.parametrize("decel", [2.0, 6.0])
def test_a_standing_line_is_approached_braking_no_harder_than_allowed(gap_m, decel):
    """A line standing ``gap_m`` ahead of a car at 10 m/s: the speed never drops by more than
    ``decel`` per second, the car never gets past the free references, and where it could stop
    in time (10^2 / (2 decel) <= gap) it comes to a stop at the line (each step's speed is the
    one that stops on the line from where the step begins: it ends past it by less than a
    step's travel at the speed that stops within one step, sqrt(2 decel v dt) dt)."""
    s, v = _free(10.0)
    out = follow_references(s, v, np.full(N + 1, gap_m), 10.0, DT, decel)
    if out is None:  # the line stays beyond the braking distance over the whole horizon
        assert np.all(gap_m - s[:-1] >= 10.0**2 / (2 * decel))
        return
    s_out, v_out = out
    assert s_out[0] == 0.0 and v_out[0] == 10.0
    assert np.all(np.diff(v_out) >= -decel * DT - 1e-12)
    assert np.all(v_out >= 0.0) and np.all(s_out <= s + 1e-12)
    assert np.all(np.diff(s_out) >= -1e-12)
    # room to brake, and time in the horizon to reach the line's braking point and stop
    if 10.0**2 / (2 * decel) <= gap_m and gap_m / 10.0 + 5.0 / decel <= N * DT:
        assert v_out[-1] <= decel * DT + 1e-9
        assert s_out[-1] <= gap_m + 10.0 * DT


def test_a_slower_leader_is_followed_at_its_speed():
    """A leader 10 m ahead at 5 m/s, the car at 8 m/s, free speed 12 m/s: the car slows to the
    leader's speed behind it (no faster than free, past the line by less than a step's travel)."""
    s, v = _free(12.0)
    line = 10.0 + 5.0 * DT * np.arange(N + 1)
    s_out, v_out = follow_references(s, v, line, 8.0, DT, 3.0)
    assert np.all(s_out <= line + 8.0 * DT)
    assert np.all(v_out <= 12.0 + 1e-12)
    assert v_out[-1] == pytest.approx(5.0, abs=1.0)


def test_a_speed_cap_alone_holds_the_car_back():
    s, v = _free(15.0)
    s_out, v_out = follow_references(s, v, None, 15.0, DT, 2.0, v_cap_mps=10.0)
    assert v_out[-1] == pytest.approx(10.0)
    assert np.all(np.diff(v_out) >= -2.0 * DT - 1e-12)  # down to the cap no harder than allowed
    assert math.isclose(v_out[1], 15.0 - 2.0 * DT)


def test_relations_are_checked_all_at_once_and_named_when_bad():
    good = {3: np.full(N, REL_CLEAR, np.int8), 7: [REL_RIGHT] * N}
    out = checked_relations(good, N)
    assert set(out) == {3, 7} and all(a.dtype == np.int64 and a.shape == (N,) for a in out.values())
    assert checked_relations(None, N) == {}
    bad = dict(good)
    bad[9] = np.r_[np.zeros(N - 1, int), REL_RIGHT + 1]
    with pytest.raises(ValueError, match="obstacle 9: codes must be REL_"):
        checked_relations(bad, N)
    with pytest.raises(ValueError, match="obstacle 4: 30 codes"):
        checked_relations({4: np.zeros(N - 1, int)}, N)
