"""Settings of the maneuver planner, each with its unit and physical meaning.

The costs are in seconds: every term is what the planner would give up in travel time to avoid
it (a lane change "costs" ``lane_change_s`` seconds, a second spent in the oncoming lane
``oncoming_s_per_s`` seconds), so that weights compare like with like and read as a driver's
trade-offs rather than as tuning numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["PlannerConfig", "VehicleLimits"]


@dataclass(frozen=True)
class VehicleLimits:
    """What the vehicle can do (the controller's limits, SI units).

    length_m / width_m : the body [m]; center_offset_m : the body's centre ahead of the reference
    point [m]; wheelbase_m [m]; max_steer_rad / max_steer_rate_rad_s : steering angle and rate
    limits; max_accel_mps2 / max_decel_mps2 : the longitudinal input's limits (decel positive)
    [m/s^2]; max_speed_mps : the top speed the controller may drive [m/s]; friction_mps2 : the
    friction circle the controller plans within, sqrt(a_lon^2 + a_lat^2) [m/s^2] (inf: none);
    disc_offsets_m / disc_radius_m : the discs that cover the body for the controller's obstacle
    rows (centres along the body from the reference point, radius) [m]: a maneuver keeps them
    clear of every obstacle, as the rows will (0 radius: the rectangle's half diagonal);
    disc_margin_m : the clearance [m] those rows keep beyond the discs (at most the planner's
    ``margin_m``);
    rear_axle_m : the rear axle behind the reference point [m]: a reference point ahead of it
    (the centre of gravity) moves at the slip angle ``asin(rear_axle_m kappa)`` to the body on a
    path of curvature kappa, so the body's heading is the path's less that (0: the rear axle)."""

    length_m: float
    width_m: float
    wheelbase_m: float
    max_steer_rad: float
    max_steer_rate_rad_s: float
    max_accel_mps2: float
    max_decel_mps2: float
    max_speed_mps: float
    friction_mps2: float = math.inf
    center_offset_m: float = 0.0
    disc_offsets_m: tuple[float, ...] = (0.0,)
    disc_radius_m: float = 0.0
    disc_margin_m: float = 0.0
    rear_axle_m: float = 0.0

    def __post_init__(self):
        for name in ("length_m", "width_m", "wheelbase_m", "max_steer_rad", "max_steer_rate_rad_s", "friction_mps2"):
            v = getattr(self, name)
            if not (v > 0):
                raise ValueError(f"{name} must be positive, got {v!r}")
        if not (math.isfinite(self.rear_axle_m) and 0.0 <= self.rear_axle_m <= self.wheelbase_m):
            raise ValueError(f"rear_axle_m must lie in [0, wheelbase_m], got {self.rear_axle_m!r}")
        if not (math.isfinite(self.disc_margin_m) and self.disc_margin_m >= 0.0):
            raise ValueError(f"disc_margin_m must be a non-negative finite number, got {self.disc_margin_m!r}")
        for name in ("max_accel_mps2", "max_decel_mps2", "max_speed_mps"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive finite number, got {v!r}")

    @property
    def max_curvature_1pm(self) -> float:
        """Tightest path curvature [1/m] at full steering (at the rear axle: tan(delta) / L)."""
        return math.tan(min(self.max_steer_rad, 1.5)) / self.wheelbase_m

    @property
    def max_curvature_rate_1pms(self) -> float:
        """Fastest change of path curvature [1/(m s)] at the steering-rate limit (d kappa / d delta
        is at least 1 / L)."""
        return self.max_steer_rate_rad_s / self.wheelbase_m


@dataclass(frozen=True)
class PlannerConfig:
    """How the maneuver planner samples, checks and chooses (SI units; costs in seconds).

    Sampling
    --------
    horizon_s : how far ahead each maneuver is planned and checked [s]: long enough to stop
        from the top speed at the comfortable deceleration (30 m/s at 5 m/s^2 takes 6 s);
    dt_s : the grid the checks run on [s]: each step between two samples is checked swept (the
        segment of the two footprints' relative motion over the step against both), so a fast
        crossing car is not stepped over; over 0.2 s a car turning at 0.1 1/m and 10 m/s leaves
        its chord by 5 cm;
    lateral_s : durations of a lateral move [s] (an evasive 2 s, a usual 4 s, a relaxed 6 s lane
        change), turned into lengths along the road at the speed the car drives, no shorter than
        ``lateral_min_m``;
    lateral_min_m : the shortest lateral move [m] (a move is also no shorter than what half the
        vehicle's steering range allows: its peak curvature 5.77 dd / L^2 for a shift dd);
    lane_shift_m : offsets inside the car's lane [m] (to either side of its line, kept inside the
        lane), for more room beside a car or obstacle without leaving the lane;
    speed_s : durations of a change of speed [s] (to a target speed, or to a stop at a point);
    comfort_accel_mps2 / comfort_decel_mps2 : the accelerations [m/s^2] a maneuver plans with
        (braking harder is the emergency's, up to the vehicle's limit);
    creep_mps : the pace [m/s] a car drives round an obstacle too close to swerve round at speed
        (a brisk walk: at 2 m/s a full steering lock turns at 2.8 m/s^2);
    oncoming : sample the oncoming lane for a pass where no lane going the car's way serves.

    Checks
    ------
    margin_m : the clearance [m] every maneuver keeps between the controller's discs covering the
        car's body and every other road user's predicted footprint (the controller's own
        obstacle rows keep as much);
    road_margin_m : the room [m] a maneuver keeps between the body and the road's edges and ends
        (at least the road's own margin): what the controller's tracking of a lane change leaves
        on a plant with tyres (ST, multi-body), about 0.2 m; a maneuver may use it over its first
        second, shrinking to nothing by then (a car drifting towards the edge turns back), never
        the road beyond the edge; a car already in the margin keeps it until it has also driven
        the way its shortest lateral move needs beyond a second's (a slow car turns back only as
        it drives);
    rows_tolerance_m : how far [m] the controller's obstacle rows along and across the path may
        hold the car off a maneuver (what its tracking leaves anyway, about 0.2 m). Those rows
        keep an obstacle's Frenet box; a maneuver is checked against its oriented box. Where the
        Frenet box exceeds the outline (an obstacle yawed to the path) by more than this and the
        margin the planner keeps beyond the rows' own, the maneuver hands the controller the
        outline's nearest-point half-plane for that obstacle instead;
    time_gap_s : the time gap [s] to a car ahead or behind in the same lane below which a
        maneuver pays (``gap_cost_s_per_s``) -- two seconds is the rule of thumb, one the legal
        minimum in many countries;
    standstill_m : the gap [m] kept to a car ahead when stopped behind it;
    stop_speed_mps : below this speed [m/s] the car counts as standing (it cannot move sideways).

    Choice (costs in seconds of travel time)
    ----------------------------------------
    lane_change_s : a maneuver that ends in another lane than the one the car is in;
    off_route_s_per_s : each second spent out of the route lane (in a same-direction lane);
    oncoming_s_per_s : each second spent (partly) in the oncoming lane;
    switch_s : choosing another lane than the last replanning did (hysteresis: a choice does not
        flip between two nearly equal maneuvers);
    gap_cost_s_per_s : each second spent closer than the time gap to a car ahead or behind;
    goal_miss_s : a maneuver that, with the goal's time window inside the horizon, misses the
        goal (region, time, speed, orientation);
    rate_excess_s : a maneuver that steers faster than the steering rate allows (its own move,
        or the path's bends at its speed), per unit of the excess (at 100 s: 1 % beyond the
        rate costs 1 s, 20 % as much as a missed goal); a cost, not a wall: a hard stop within
        the rate is not better than keeping on 1 % above it;
    jerk_ref_mps3 : the jerk [m/s^3] whose square, held for a second, costs one second;
    lat_accel_ref_mps2 : the lateral acceleration [m/s^2] whose square, held for a second, costs
        one second.
    """

    horizon_s: float = 6.0
    dt_s: float = 0.2
    lateral_s: tuple[float, ...] = (2.0, 4.0, 6.0)
    lateral_min_m: float = 5.0
    lane_shift_m: float = 0.5
    speed_s: tuple[float, ...] = (2.0, 4.0)
    comfort_accel_mps2: float = 2.0
    comfort_decel_mps2: float = 3.0
    creep_mps: float = 2.0
    oncoming: bool = False
    margin_m: float = 0.3
    road_margin_m: float = 0.25
    rows_tolerance_m: float = 0.2
    time_gap_s: float = 1.0
    standstill_m: float = 2.0
    stop_speed_mps: float = 0.3
    lane_change_s: float = 1.0
    off_route_s_per_s: float = 0.3
    oncoming_s_per_s: float = 2.0
    switch_s: float = 1.5
    gap_cost_s_per_s: float = 3.0
    goal_miss_s: float = 20.0
    rate_excess_s: float = 100.0
    jerk_ref_mps3: float = 4.0
    lat_accel_ref_mps2: float = 4.0

    def __post_init__(self):
        for name in (
            "horizon_s",
            "dt_s",
            "lateral_min_m",
            "comfort_accel_mps2",
            "comfort_decel_mps2",
            "creep_mps",
            "stop_speed_mps",
            "jerk_ref_mps3",
            "lat_accel_ref_mps2",
        ):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive finite number, got {v!r}")
        for name in (
            "lane_shift_m",
            "margin_m",
            "road_margin_m",
            "rows_tolerance_m",
            "time_gap_s",
            "standstill_m",
            "lane_change_s",
            "off_route_s_per_s",
            "oncoming_s_per_s",
            "switch_s",
            "gap_cost_s_per_s",
            "goal_miss_s",
            "rate_excess_s",
        ):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        for name in ("lateral_s", "speed_s"):
            v = getattr(self, name)
            if not v or not all(math.isfinite(x) and x > 0 for x in v):
                raise ValueError(f"{name} must be positive durations [s], got {v!r}")
        if self.steps > 200:
            raise ValueError(f"horizon_s / dt_s gives {self.steps} steps; at most 200 are checked")
        if self.dt_s > 0.25:
            raise ValueError(f"dt_s must be at most 0.25 s (the checks' grid), got {self.dt_s!r}")

    @property
    def steps(self) -> int:
        """Steps of the check grid over the horizon."""
        return int(round(self.horizon_s / self.dt_s))
