"""The verdict of a run: one judgement, computed once from the run's metrics and shown everywhere
(the summary line, ``metrics.json["verdict"]``, ``report.html``, ``mpcdrive sweep``, ``mpcdrive
run --check``).

Its parts, each ``ok`` or failed with a reason (or ``ok`` None where there is nothing to judge):

* ``divergence``: the simulated state stayed finite;
* ``collision``: the body never overlapped an obstacle (nor did an external checker find a
  collision);
* ``road``: the body stayed inside the road, up to :attr:`VerdictCriteria.max_lane_excess_m`
  (an external checker's road verdict, CommonRoad's, is the authority where there is one);
* ``goal``: what the run had to do (:attr:`VerdictCriteria.goal`: reach the end of its open path
  or its laps, or come to a standstill), done safely (inside the road, without a collision) and
  ending within :attr:`VerdictCriteria.max_final_lateral_error_m` of the path; a run with no goal
  region (a closed path without laps, a run that does not stop at the path's end) is judged on
  that final error alone; for CommonRoad the planning problem's goal region;
* one part per external checker whose block the metrics hold (:data:`EXTERNAL_PARTS`: CommonRoad's
  drivability and solution checkers, ``metrics["commonroad"]``).

A run passes when no part failed; it is *unsafe* when it diverged, collided or left the road.
Steering saturation (how often the steering sat at its angle or rate limit) and failed solves are
notes, informational: a controller that uses its full authority or recovers from a failed solve
by its fallback ladder has done nothing unsafe; the parts judge the outcome.

Pure functions of a run's metrics as a mapping in the shape of ``metrics.json``: a
:class:`~mpcdrive.sim.Metrics` (:func:`~mpcdrive.sim.compute_metrics`) or a ``metrics.json``
read back (missing keys count as fine, missing criteria as the defaults)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = [
    "EXTERNAL_PARTS",
    "GOALS",
    "LANE_TOLERANCE_M",
    "SATURATION_TOLERANCE",
    "STANDSTILL_SPEED_MPS",
    "RunVerdict",
    "VerdictCriteria",
    "VerdictPart",
    "goal_condition",
    "run_verdict",
]

#: lane excess [m] up to which a run still counts as inside the lane (the goal definition, the
#: run verdict): the excess is measured on the projection onto the path's polyline table, whose
#: chord error kappa ds^2 / 8 stays below a millimetre for the tables' spacing (<= 0.1 m) on
#: curves down to 1.25 m radius; anything beyond is a real excursion
LANE_TOLERANCE_M = 1e-3
#: speed [m/s] up to which a car counts as standing (goal ``standstill``): it covers less than a
#: centimetre a second
STANDSTILL_SPEED_MPS = 0.01
#: a command within this fraction of a limit counts as at the limit (steering saturation): the
#: commands are clipped to the limits, and a solver meets an active limit to its tolerance
#: (OSQP's 1e-5 rad on steering steps of at least r dt ~ 0.01 rad is 1e-3 of it)
SATURATION_TOLERANCE = 1e-3
#: what a run may have to do: ``reach`` the end of its open path (or its laps on a closed one),
#: or come to a ``standstill`` (e.g. before an obstacle that blocks the road)
GOALS = ("reach", "standstill")


@dataclass(frozen=True)
class VerdictCriteria:
    """How a run is judged (``metrics.json["criteria"]``; a scenario's ``verdict`` block).

    goal : ``reach`` (the end of an open path, the laps of a closed one) or ``standstill`` (at
    most ``max_final_speed_mps`` at the end); max_final_lateral_error_m : the largest |lateral
    error| at the end [m] (None: half the car's width, the path still under the body; resolved
    by :meth:`resolved`); max_final_speed_mps : standstill speed [m/s]; max_lane_excess_m : the
    largest excess outside the road [m] that still counts as inside (the measurement's accuracy,
    :data:`LANE_TOLERANCE_M`)."""

    goal: str = "reach"
    max_final_lateral_error_m: float | None = None
    max_final_speed_mps: float = STANDSTILL_SPEED_MPS
    max_lane_excess_m: float = LANE_TOLERANCE_M

    def __post_init__(self):
        if self.goal not in GOALS:
            raise ValueError(f"goal must be one of {', '.join(GOALS)}, got {self.goal!r}")
        for name in ("max_final_lateral_error_m", "max_final_speed_mps", "max_lane_excess_m"):
            v = getattr(self, name)
            if v is None and name == "max_final_lateral_error_m":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0 [SI units], got {v!r}")

    def resolved(self, car_width_m: float) -> VerdictCriteria:
        """These criteria with the final-error tolerance of a car ``car_width_m`` [m] wide filled in."""
        if self.max_final_lateral_error_m is not None:
            return self
        return VerdictCriteria(self.goal, 0.5 * float(car_width_m), self.max_final_speed_mps, self.max_lane_excess_m)

    def as_dict(self) -> dict[str, Any]:
        """The JSON object of ``metrics.json["criteria"]``."""
        return {
            "goal": self.goal,
            "max_final_lateral_error_m": self.max_final_lateral_error_m,
            "max_final_speed_mps": self.max_final_speed_mps,
            "max_lane_excess_m": self.max_lane_excess_m,
        }

    @classmethod
    def from_mapping(cls, d: Mapping[str, Any] | None) -> VerdictCriteria:
        """Criteria from their JSON object (missing keys: the defaults)."""
        d = d or {}
        return cls(
            **{
                k: d[k]
                for k in ("goal", "max_final_lateral_error_m", "max_final_speed_mps", "max_lane_excess_m")
                if k in d
            }
        )


def goal_condition(criteria: VerdictCriteria, path_goal_reached: bool | None, final_speed_mps: float) -> bool | None:
    """Whether the run did what its goal asks, safety aside (``goal_region_reached``): for
    ``reach`` the closed loop's own test (``SimResult.goal_reached``: the end of an open path or
    the laps; None without a goal region), for ``standstill`` the speed at the end."""
    if criteria.goal == "standstill":
        return bool(math.isfinite(final_speed_mps) and abs(final_speed_mps) <= criteria.max_final_speed_mps)
    return path_goal_reached


@dataclass(frozen=True)
class VerdictPart:
    """One part of a verdict: ``ok`` (None: nothing to judge), ``finding`` (the part in words, as
    the summary says it; None where there is nothing to say) and ``reason`` (why it failed; None
    unless ``ok`` is False)."""

    ok: bool | None
    finding: str | None
    reason: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"ok": self.ok, "reason": self.reason, "finding": self.finding}


def _part(ok: bool | None, finding: str | None) -> VerdictPart:
    return VerdictPart(ok, finding, finding if ok is False else None)


@dataclass(frozen=True)
class RunVerdict:
    """The verdict of a run (:func:`run_verdict`; ``metrics.json["verdict"]`` is :meth:`as_dict`).

    parts : name -> :class:`VerdictPart`, in order (``divergence``, ``collision``, ``road``,
    ``goal``, then the external checkers'); notes : name -> phrase, informational (``steering``:
    saturation, ``solver``: failed solves and how they were handled)."""

    parts: tuple[tuple[str, VerdictPart], ...]
    notes: tuple[tuple[str, str], ...] = ()

    def part(self, name: str) -> VerdictPart | None:
        """The part called ``name`` (None if the verdict has none)."""
        return dict(self.parts).get(name)

    def _failed(self, name: str) -> bool:
        p = self.part(name)
        return p is not None and p.ok is False

    @property
    def collided(self) -> bool:
        return self._failed("collision")

    @property
    def off_road(self) -> bool:
        return self._failed("road")

    @property
    def diverged(self) -> bool:
        return self._failed("divergence")

    @property
    def goal_reached(self) -> bool | None:
        """The goal part's ``ok``."""
        p = self.part("goal")
        return None if p is None else p.ok

    @property
    def unsafe(self) -> bool:
        """Collided, left the road or diverged."""
        return self.collided or self.off_road or self.diverged

    @property
    def passed(self) -> bool:
        """No part failed (``mpcdrive run --check`` exits 3 otherwise)."""
        return not any(p.ok is False for _, p in self.parts)

    @property
    def failed(self) -> bool:
        return not self.passed

    @property
    def reasons(self) -> list[str]:
        """Why the run failed: the reason of each failed part, in order (empty: passed)."""
        return [p.reason for _, p in self.parts if p.ok is False and p.reason]

    def problems(self) -> list[str]:
        """Short names of the failed parts (``diverged``, ``collision``, ``left the road``, ``goal
        not reached``, an external checker's name)."""
        short = {
            "divergence": "diverged",
            "collision": "collision",
            "road": "left the road",
            "goal": "goal not reached",
        }
        return [short.get(n, n) for n, p in self.parts if p.ok is False]

    @property
    def headline(self) -> str:
        """``UNSAFE`` (diverged, collided or left the road), ``FAILED`` (another part failed) or
        ``passed``."""
        return "UNSAFE" if self.unsafe else "FAILED" if self.failed else "passed"

    @property
    def findings(self) -> tuple[str, ...]:
        """The verdict as phrases: the parts' findings, then the notes (the external checkers
        last)."""
        core = [p.finding for n, p in self.parts if n in _CORE and p.finding]
        external = [p.finding for n, p in self.parts if n not in _CORE and p.finding]
        return (*core, *(text for _, text in self.notes), *external)

    def prefix(self) -> str:
        """``UNSAFE: `` or ``FAILED: `` before a line about a run that did not pass, else ''."""
        return "" if self.passed else self.headline + ": "

    def text(self) -> str:
        """One line: ``UNSAFE: `` or ``FAILED: `` first when the run did not pass, then the findings."""
        return self.prefix() + "; ".join(self.findings)

    def line(self, run_id: str) -> str:
        """The verdict of run ``run_id`` as the summary line begins: ``UNSAFE: <id>: <findings>``."""
        return f"{self.prefix()}{run_id}: {'; '.join(self.findings)}"

    def as_dict(self) -> dict[str, Any]:
        """``metrics.json["verdict"]``: ``passed``, ``unsafe``, ``headline``, ``text``,
        ``reasons``, ``parts`` (name -> ``{ok, reason, finding}``) and ``notes`` (name -> phrase)."""
        return {
            "passed": self.passed,
            "unsafe": self.unsafe,
            "headline": self.headline,
            "text": self.text(),
            "reasons": self.reasons,
            "parts": {n: p.as_dict() for n, p in self.parts},
            "notes": dict(self.notes),
        }


_CORE = ("divergence", "collision", "road", "goal")


# -- the phrases -------------------------------------------------------------------------------------
def _obstacle(event: Mapping[str, Any]) -> str:
    name = event.get("name")
    return f"obstacle {event['obstacle']}" + (f" ({name})" if name else "")


def collision_phrase(m: Mapping[str, Any]) -> str | None:
    """``collided with obstacle 2 (slow-car) at t = 3.10 s, 0.12 m deep`` (plus how many contacts
    in all), ``no collision (min clearance 0.21 m)``, or None without obstacles."""
    n = int(m.get("collisions") or 0)
    events = m.get("collision_events") or []
    if n == 0 and not events:
        c = m.get("min_obstacle_clearance_m")
        return None if c is None else f"no collision (min clearance {c:.3g} m)"
    if not events:
        return f"{n} collision(s)"
    first = events[0]
    text = f"collided with {_obstacle(first)} at t = {first['t_s']:.2f} s, {first['depth_m']:.3g} m deep"
    if len(events) > 1:
        which = sorted({e["obstacle"] for e in events})
        text += (
            f" ({len(events)} contacts in all, with obstacle{'s' if len(which) > 1 else ''} "
            f"{', '.join(map(str, which))})"
        )
    return text


def lane_phrase(m: Mapping[str, Any], tolerance_m: float = LANE_TOLERANCE_M) -> str:
    """``left the lane by 0.82 m``, ``inside the lane (max excess 0 m)`` or ``no lane given``; for
    a run an external checker judged on the road (CommonRoad) the lane is the route lane, a proxy
    the checker's verdict overrides."""
    if m.get("road_given") is False:
        return "no lane given"
    e = float(m.get("max_lane_excess_m") or 0.0)
    if e > tolerance_m:
        if "road_compliant" in (m.get("commonroad") or {}):
            return f"left the route lane by {e:.3g} m (the CommonRoad checker judges the road)"
        return f"left the lane by {e:.3g} m"
    return "inside the lane" + (f" (max excess {e:.2g} m)" if e > 0 else "")


def solver_phrase(m: Mapping[str, Any]) -> str:
    """``no failed solves``, ``5 failed solves, all recovered by relax`` or ``5 failed solves: 3
    recovered by shifted_plan, 2 by brake``."""
    n = int(m.get("solver_failures") or 0)
    counts = [(k, int(v)) for k, v in (m.get("fallback_counts") or {}).items() if v]
    counts.sort(key=lambda kv: -kv[1])
    if n == 0 and not counts:
        return "no failed solves"
    head = f"{n} failed solve{'' if n == 1 else 's'}"
    if not counts:
        return head + ", no fallback used"
    if len(counts) == 1 and counts[0][1] == n:
        return f"{head}, {'all ' if n > 1 else ''}recovered by {counts[0][0]}"
    parts = [f"{v} recovered by {k}" if i == 0 else f"{v} by {k}" for i, (k, v) in enumerate(counts)]
    return f"{head}: {', '.join(parts)}"


def _percent(fraction: float) -> str:
    p = 100.0 * fraction
    return f"{p:.0f} %" if p >= 10 or p == 0 else f"{p:.2g} %"


def steering_phrase(m: Mapping[str, Any]) -> str | None:
    """How often the steering sat at its limits: ``steering at its angle limit 12 % and at its rate
    limit 38 % of the time``; without a rate limit it says so (``ideal steering (the paper's: no
    rate limit, no lag; up to 84.9 rad/s)``); None when the run recorded no limits."""
    angle = m.get("steer_saturated_fraction")
    rate = m.get("steer_rate_saturated_fraction")
    if angle is None:
        return None
    if m.get("steer_rate_limit_rad_s") is not None and rate is not None:
        return f"steering at its angle limit {_percent(angle)} and at its rate limit {_percent(rate)} of the time"
    peak = m.get("max_abs_steer_rate_rad_s")
    up_to = f"; up to {peak:.3g} rad/s" if isinstance(peak, (int, float)) else ""
    act = m.get("steering_actuator")
    if isinstance(act, Mapping) and _is_ideal(act):
        head = f"ideal steering (the paper's: no rate limit, no lag{up_to})"
    else:
        head = f"no steering-rate limit in the controller ({up_to[2:] or 'none'})"
    return f"{head}, at its angle limit {_percent(angle)} of the time"


def _is_ideal(act: Mapping[str, Any]) -> bool:
    return not act.get("time_constant_s") and not act.get("dead_time_s") and act.get("max_rate_rad_s") is None


def checker_phrase(cr: Mapping[str, Any]) -> str:
    """The drivability checker's verdicts of a CommonRoad run (``metrics["commonroad"]``)."""
    words = [
        "collision-free" if cr.get("collision_free") else "COLLISION",
        "road-compliant" if cr.get("road_compliant") else "OFF THE ROAD",
    ]
    if "ks_feasible" in cr:
        model = cr.get("vehicle_model") or "KS"  # the solution's model (ST for a drive on the ST plant)
        words.append(f"{model}-feasible" if cr["ks_feasible"] else f"not {model}-feasible")
    goal = cr.get("goal_reached")
    if goal is not None:
        step = cr.get("goal_step")
        words.append(
            f"goal reached at step {step}"
            if goal and step is not None
            else "goal reached"
            if goal
            else "goal not reached" + (f" ({cr['goal_miss']})" if cr.get("goal_miss") else "")
        )
    if cr.get("solution_valid") is False:
        words.append("solution rejected by CommonRoad's solution checker")
    text = "CommonRoad checker: " + ", ".join(words)
    whole = whole_drive_phrase(cr)
    return text if whole is None else f"{text}; {whole}"


def _when(t_s: float, goal_t_s: float | None) -> str:
    """``after the goal at t = 7.30 s`` (a time past the goal's), else ``at t = 7.30 s``."""
    return ("after the goal " if goal_t_s is not None and t_s > goal_t_s else "") + f"at t = {t_s:.2f} s"


def _past_end(w: Mapping[str, Any]) -> str:
    """`` (the body 2.24 m beyond the road's start or end)`` where the body reached past the mapped road's
    start or end, else ''."""
    past = w.get("past_road_end_m")
    beyond = isinstance(past, (int, float)) and past > LANE_TOLERANCE_M
    return f" (the body {past:.3g} m beyond the road's start or end)" if beyond else ""


def whole_drive_phrase(cr: Mapping[str, Any]) -> str | None:
    """The CommonRoad checks of the whole drive, start to end of the run
    (``metrics["commonroad"]["whole_drive"]``): ``whole drive clean`` or what failed first and
    when, e.g. ``whole drive: COLLISION after the goal at t = 7.30 s``; None without them."""
    w = cr.get("whole_drive")
    if not w:
        return None
    goal_t = w.get("goal_t_s")
    failed = []
    if w.get("collision_free") is False:
        failed.append(
            "COLLISION" + (f" {_when(w['collision_t_s'], goal_t)}" if w.get("collision_t_s") is not None else "")
        )
    if w.get("road_compliant") is False:
        t = w.get("off_road_t_s")
        failed.append("OFF THE ROAD" + (f" {_when(t, goal_t)}" if t is not None else "") + _past_end(w))
    if w.get("feasible") is False:
        model = cr.get("vehicle_model") or "KS"
        t = w.get("infeasible_t_s")
        failed.append(f"not {model}-feasible" + (f" {_when(t, goal_t)}" if t is not None else ""))
    if not failed:
        return f"whole drive clean ({w.get('states_checked')} states)"
    return "whole drive: " + ", ".join(failed)


def _commonroad_part(cr: Mapping[str, Any]) -> VerdictPart:
    ok = cr.get("passed")
    return _part(None if ok is None else bool(ok), checker_phrase(cr))


#: the parts of external checkers: metrics key -> the part judged from that block of the metrics
#: (present only when the metrics hold the block). CommonRoad's drivability and solution checkers
#: up to the goal and its drivability checks of the whole drive (``commonroad.whole_drive``) are
#: ``commonroad``; another checker adds its key and function here
EXTERNAL_PARTS: dict[str, Callable[[Mapping[str, Any]], VerdictPart]] = {"commonroad": _commonroad_part}


# -- the verdict ---------------------------------------------------------------------------------------
def _safe_to_goal(m: Mapping[str, Any], collided: bool, off_road: bool) -> tuple[bool, bool]:
    """(collided, off the road) up to the goal: for a CommonRoad run its checker's verdicts up to
    the goal and mpcdrive's contacts that began by then (what happens after the goal fails the
    drive, not the goal); for any other run, the whole run's."""
    cr = m.get("commonroad") or {}
    if "road_compliant" not in cr:
        return collided, off_road
    goal_t = (cr.get("whole_drive") or {}).get("goal_t_s")
    off_to_goal = cr["road_compliant"] is False
    if goal_t is None:  # (no time of the goal: the whole run's contacts, as the metrics say)
        return collided, off_to_goal
    before = any(e.get("t_s", 0.0) <= goal_t for e in m.get("collision_events") or [])
    return cr.get("collision_free") is False or before, off_to_goal


def _goal_part(m: Mapping[str, Any], crit: VerdictCriteria, collided: bool, off_road: bool) -> VerdictPart:
    region = m.get("goal_region_reached")
    cr = m.get("commonroad") or {}
    fe = m.get("final_lateral_error_m")
    tol = crit.max_final_lateral_error_m
    off_path = None  # why the end is too far from the path, or None
    if not cr and tol is not None and isinstance(fe, (int, float)):
        if not math.isfinite(fe):
            off_path = "the final lateral error is not finite"
        elif abs(fe) > tol:
            off_path = f"ended {abs(fe):.3g} m from the path (the goal allows {tol:.3g} m)"
    what = "a standstill" if crit.goal == "standstill" else "the goal region"
    if region is None:  # no goal region: the run is judged on where it ends
        if off_path is not None:
            return _part(False, f"no goal region, but {off_path}")
        return _part(True, None)
    if not region:
        if crit.goal == "standstill":
            v = m.get("final_speed_mps")
            moving = f"still moving at {v:.3g} m/s at the end" if isinstance(v, (int, float)) else "not stopped"
            return _part(False, f"goal not reached ({moving}; the goal is a standstill)")
        return _part(False, "goal not reached")
    if collided or off_road:
        return _part(False, f"goal not reached ({what} was reached, but not safely)")
    if off_path is not None:
        return _part(False, f"goal not reached ({what} was reached, but {off_path})")
    return _part(True, "goal reached" + (" (a standstill)" if crit.goal == "standstill" else ""))


def run_verdict(m: Mapping[str, Any]) -> RunVerdict:
    """The verdict of a run with metrics ``m`` (missing keys count as fine; criteria from
    ``m["criteria"]``, else the defaults)."""
    crit = VerdictCriteria.from_mapping(m.get("criteria"))
    cr = m.get("commonroad") or {}
    diverged = m.get("termination") == "diverged"
    parts: list[tuple[str, VerdictPart]] = [
        (
            "divergence",
            _part(False, f"the simulated state diverged (not finite) after {m.get('steps')} steps")
            if diverged
            else _part(True, None),
        )
    ]
    whole = cr.get("whole_drive") or {}
    cr_collided = cr.get("collision_free") is False or whole.get("collision_free") is False
    collided = bool(m.get("collisions")) or bool(m.get("collision_events")) or cr_collided
    phrase = collision_phrase(m)
    if cr_collided and not (m.get("collisions") or m.get("collision_events")):
        t = None if cr.get("collision_free") is False else whole.get("collision_t_s")
        when = "" if t is None else f" {_when(t, whole.get('goal_t_s'))}"
        phrase = f"the CommonRoad checker found a collision{when}" + (f" ({phrase})" if phrase else "")
    # without obstacles (no phrase) there is nothing to judge
    parts.append(("collision", _part(False if collided else None if phrase is None else True, phrase)))
    lane = lane_phrase(m, crit.max_lane_excess_m)
    if "road_compliant" in cr:  # an external checker's road (CommonRoad's lanelets) is the authority
        off_to_goal = cr["road_compliant"] is False
        off_road = off_to_goal or whole.get("road_compliant") is False
        if off_to_goal and not lane.startswith("left"):
            lane = "the CommonRoad checker found the car off the road"
        elif off_road and not off_to_goal:  # on the road up to the goal, not after it
            t = whole.get("off_road_t_s")
            lane = "left the road" + ("" if t is None else f" {_when(t, whole.get('goal_t_s'))}") + _past_end(whole)
        parts.append(("road", VerdictPart(not off_road, lane, lane if off_road else None)))
    elif m.get("road_given") is False:
        off_road = False
        parts.append(("road", VerdictPart(None, lane)))
    else:
        off_road = float(m.get("max_lane_excess_m") or 0.0) > crit.max_lane_excess_m
        parts.append(("road", _part(not off_road, lane)))
    parts.append(("goal", _goal_part(m, crit, *_safe_to_goal(m, collided, off_road))))
    for key, judge in EXTERNAL_PARTS.items():
        block = m.get(key)
        if block:
            parts.append((key, judge(block)))
    notes = []
    steering = steering_phrase(m)
    if steering is not None:
        notes.append(("steering", steering))
    notes.append(("solver", solver_phrase(m)))
    return RunVerdict(tuple(parts), tuple(notes))
