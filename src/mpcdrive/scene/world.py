"""The world a drive happens in, given once: the road, the obstacles and the vehicle's body.

A :class:`Scene` is what the controller plans against and what a run is judged against. The
controller is built with one (``LtvMpc(..., scene=...)``) and keeps it as ``controller.scene``;
:func:`~mpcdrive.sim.simulate` judges the drive against that same scene, so the two cannot
disagree and the accounting cannot be forgotten. What the controller is allowed to use at a
step (the lanes a decision layer opens, ``set_road``; fresh predictions of moving obstacles,
``set_obstacles``) changes the controller's problem, never the scene: the scene is the whole
world, and the body is judged inside the whole road (:meth:`Scene.judged_road`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .footprint import Footprint
from .obstacles import Circle, ConstantVelocity, Obstacle, Polygon, Static, TrajectoryMotion
from .road import Road


@dataclass(frozen=True, eq=False)
class Scene:
    """The road (None: none), the obstacles and the ego vehicle's ``footprint``.

    road : :class:`~mpcdrive.scene.road.Road` along the reference path, with its lanes (a road
    with neighbour lanes is the whole road: every lane counts as inside, :meth:`judged_road`);
    obstacles : every obstacle of the world with its motion and lifetime (a plant with traffic
    of its own, :class:`~mpcdrive.sim.closed_loop.TrafficPlant`, adds its vehicles to these);
    footprint : the ego body, kept inside the road and off the obstacles, and judged so.

    Two scenes are the same world when :meth:`differences` is empty: the same judged road
    edges, the same obstacles (shape, pose, motion, lifetime, name) in the same order and the
    same body rectangle."""

    road: Road | None = None
    obstacles: tuple[Obstacle, ...] = ()
    footprint: Footprint = field(default_factory=Footprint)

    def __post_init__(self):
        if self.road is not None and not isinstance(self.road, Road):
            raise ValueError(f"scene road must be a mpcdrive.scene.Road or None, got {type(self.road).__name__}")
        obstacles = tuple(self.obstacles)
        for i, ob in enumerate(obstacles):
            if not isinstance(ob, Obstacle):
                raise ValueError(f"scene obstacles[{i}] must be a mpcdrive.scene.Obstacle, got {type(ob).__name__}")
        object.__setattr__(self, "obstacles", obstacles)
        if not isinstance(self.footprint, Footprint):
            raise ValueError(f"scene footprint must be a mpcdrive.scene.Footprint, got {type(self.footprint).__name__}")

    def judged_road(self) -> Road | None:
        """The road the body is judged inside: every lane of it (:meth:`Road.whole`), or None."""
        return None if self.road is None else self.road.whole()

    def differences(self, other: Scene) -> tuple[str, ...]:
        """What differs between this scene and ``other``, one phrase per part (empty: the same
        world). Only what judging a drive reads counts: the road's judged edges (not its margin,
        which the controller keeps), each obstacle, the body's rectangle (not its discs)."""
        out = []
        a, b = self.judged_road(), other.judged_road()
        if (a is None) != (b is None):
            out.append(f"road: {'a road' if a is not None else 'none'} vs {'a road' if b is not None else 'none'}")
        elif a is not None and b is not None and not _same_road(a, b):
            out.append("road: different edges")
        if len(self.obstacles) != len(other.obstacles):
            out.append(f"obstacles: {len(self.obstacles)} vs {len(other.obstacles)}")
        else:
            for i, (p, q) in enumerate(zip(self.obstacles, other.obstacles)):
                if not same_obstacle(p, q):
                    out.append(f"obstacles[{i}] ({p.name or '?'} vs {q.name or '?'}): different shape, pose or motion")
        fa, fb = self.footprint, other.footprint
        if (fa.length_m, fa.width_m, fa.center_offset_m) != (fb.length_m, fb.width_m, fb.center_offset_m):
            out.append(
                f"footprint: {fa.length_m:g} x {fa.width_m:g} m (offset {fa.center_offset_m:g} m) vs "
                f"{fb.length_m:g} x {fb.width_m:g} m (offset {fb.center_offset_m:g} m)"
            )
        return tuple(out)


def _same_road(a: Road, b: Road) -> bool:
    return (
        a.period_m == b.period_m
        and (a.start_m, a.end_m) == (b.start_m, b.end_m)
        and np.array_equal(a.s_m, b.s_m)
        and np.array_equal(a.left_m, b.left_m)
        and np.array_equal(a.right_m, b.right_m)
    )


def same_obstacle(a: Obstacle, b: Obstacle) -> bool:
    """True when ``a`` and ``b`` are the same obstacle by value: shape, pose, motion, lifetime
    and name (two objects built from the same description are)."""
    if a is b:
        return True
    if (a.pose, a.name, a.t_start_s, a.t_end_s) != (b.pose, b.name, b.t_start_s, b.t_end_s):
        return False
    sa, sb = a.shape, b.shape
    if isinstance(sa, Circle) or isinstance(sb, Circle):
        if sa != sb:
            return False
    elif not (isinstance(sa, Polygon) and isinstance(sb, Polygon) and np.array_equal(sa.points, sb.points)):
        return False
    ma, mb = a.motion, b.motion
    if type(ma) is not type(mb):
        return False
    if isinstance(ma, (Static, ConstantVelocity)):
        return ma == mb
    if isinstance(ma, TrajectoryMotion) and isinstance(mb, TrajectoryMotion):
        return all(np.array_equal(getattr(ma, n), getattr(mb, n)) for n in ("t_s", "dx_m", "dy_m", "dyaw_rad"))
    return ma is mb
