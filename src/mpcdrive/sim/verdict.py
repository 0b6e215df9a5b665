"""A run's safety outcome in words: collisions (which obstacle, when), clearance, lane excess,
goal, failed solves and how they were handled, and an external checker's verdicts (CommonRoad's
drivability checker). Pure functions of a run's metrics as a mapping in the shape of
``metrics.json``: a :class:`~mpcdrive.sim.Metrics` (:func:`~mpcdrive.sim.compute_metrics`) or a
``metrics.json`` read back (missing keys count as fine)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from .metrics import LANE_TOLERANCE_M


@dataclass(frozen=True)
class RunVerdict:
    """What happened in a run, judged from its metrics.

    collided : the body overlapped an obstacle (or an external checker found a collision);
    off_road : the body left the lane by more than ``LANE_TOLERANCE_M`` or, when an external
    checker judged the road (CommonRoad), that checker found it off the road; diverged : the simulated state stopped being finite;
    goal_reached : the metrics' ``goal_reached`` (None: the run has no goal);
    findings : the outcome as phrases (divergence, collisions, lane, goal, failed solves, the
    external checker)."""

    collided: bool
    off_road: bool
    diverged: bool
    goal_reached: bool | None
    findings: tuple[str, ...]

    @property
    def unsafe(self) -> bool:
        """Collided, left the road or diverged."""
        return self.collided or self.off_road or self.diverged

    @property
    def failed(self) -> bool:
        """Unsafe or missed its goal (``mpcdrive run --check`` exits 3)."""
        return self.unsafe or self.goal_reached is False

    def problems(self) -> list[str]:
        """Short names of what failed (``collision``, ``left the road``, ``diverged``,
        ``goal not reached``)."""
        names = [
            ("collision", self.collided),
            ("left the road", self.off_road),
            ("diverged", self.diverged),
            ("goal not reached", self.goal_reached is False),
        ]
        return [n for n, bad in names if bad]

    def text(self) -> str:
        """One line: ``UNSAFE: `` first when unsafe, then the findings."""
        return ("UNSAFE: " if self.unsafe else "") + "; ".join(self.findings)


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


def lane_phrase(m: Mapping[str, Any]) -> str:
    """``left the lane by 0.82 m``, ``inside the lane (max excess 0 m)`` or ``no lane given``; for
    a run an external checker judged on the road (CommonRoad) the lane is the route lane, a proxy
    the checker's verdict overrides."""
    if m.get("road_given") is False:
        return "no lane given"
    e = float(m.get("max_lane_excess_m") or 0.0)
    if e > LANE_TOLERANCE_M:
        if "road_compliant" in (m.get("commonroad") or {}):
            return f"left the route lane by {e:.3g} m (the CommonRoad checker judges the road)"
        return f"left the lane by {e:.3g} m"
    return "inside the lane" + (f" (max excess {e:.2g} m)" if e > 0 else "")


def goal_phrase(m: Mapping[str, Any]) -> str | None:
    """``goal reached``, ``goal not reached`` (saying when the region was reached but not
    safely), or None for a run without a goal."""
    g = m.get("goal_reached")
    if g is None:
        return None
    if g:
        return "goal reached"
    if m.get("goal_region_reached"):
        return "goal not reached (the goal region was reached, but not safely)"
    return "goal not reached"


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
            else "goal not reached"
        )
    return "CommonRoad checker: " + ", ".join(words)


def run_verdict(m: Mapping[str, Any]) -> RunVerdict:
    """The verdict of a run with metrics ``m`` (missing keys count as fine)."""
    cr = m.get("commonroad") or {}
    collided = bool(m.get("collisions")) or bool(m.get("collision_events")) or cr.get("collision_free") is False
    if "road_compliant" in cr:  # an external checker's road (CommonRoad's lanelets) is the authority
        off_road = cr["road_compliant"] is False
    else:
        off_road = float(m.get("max_lane_excess_m") or 0.0) > LANE_TOLERANCE_M
    diverged = m.get("termination") == "diverged"
    findings = []
    if diverged:
        findings.append(f"the simulated state diverged (not finite) after {m.get('steps')} steps")
    for phrase in (collision_phrase(m), lane_phrase(m), goal_phrase(m), solver_phrase(m)):
        if phrase is not None:
            findings.append(phrase)
    if cr:
        findings.append(checker_phrase(cr))
    return RunVerdict(collided, off_road, diverged, m.get("goal_reached"), tuple(findings))
