"""Frenet extents of obstacle shapes along a reference path: the boxes ``[s_lo, s_hi] x [e_lo,
e_hi]`` [m] that the obstacle terms of :mod:`mpcdrive.ocp.avoidance` choose passing sides,
corridors, stop lines and detours on."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..paths.base import ReferencePath
from ..scene.obstacles import WorldCircle

__all__ = ["FrenetBox", "FrenetBoxes", "frenet_box", "frenet_boxes"]


@dataclass(frozen=True)
class FrenetBox:
    """An obstacle's extent along / across the path at one time: s in [s_lo, s_hi],
    e_y in [e_lo, e_hi] [m]; ``s_ref`` the arc length of its reference point."""

    s_ref: float
    s_lo: float
    s_hi: float
    e_lo: float
    e_hi: float


@dataclass(frozen=True)
class FrenetBoxes:
    """An obstacle's Frenet boxes at the K times of a horizon: the fields of :class:`FrenetBox`
    as arrays (K,) [m]; ``boxes[k]`` is the FrenetBox of time k."""

    s_ref: np.ndarray
    s_lo: np.ndarray
    s_hi: np.ndarray
    e_lo: np.ndarray
    e_hi: np.ndarray

    def __len__(self) -> int:
        return len(self.s_ref)

    def __getitem__(self, k: int) -> FrenetBox:
        return FrenetBox(
            float(self.s_ref[k]), float(self.s_lo[k]), float(self.s_hi[k]), float(self.e_lo[k]), float(self.e_hi[k])
        )


def frenet_boxes(
    path: ReferencePath,
    s_guess: np.ndarray,
    centers: np.ndarray,
    radius_m: float | np.ndarray = 0.0,
    points: np.ndarray | None = None,
) -> FrenetBoxes:
    """Frenet extents of K world shapes, shape k near arc length ``s_guess[k]`` (K,) [m]: discs of
    ``radius_m`` (a number or (K,)) around ``centers`` (K, 2) [m], or, given ``points``
    (K, M, 2) [m], convex polygons (their vertex mean is projected; ``centers`` unused)."""
    # the search window reaches the shape however far it is from the path point at s_guess
    if points is None:
        far = np.hypot(*(centers - path.position(s_guess)).T)
        s, e = path.project_many(centers, s_guess, np.maximum(2.0, 2 * radius_m) + far)
        r = radius_m
        return FrenetBoxes(s, s - r, s + r, e - r, e + r)
    c = points.mean(axis=1)
    far = np.hypot(*(c - path.position(s_guess)).T)
    s, _ = path.project_many(c, s_guess, 2.0 + np.ptp(points, axis=(1, 2)) + far)
    h = np.asarray(path.heading(s), float)[:, None]
    d = points - path.position(s)[:, None, :]
    along = d[..., 0] * np.cos(h) + d[..., 1] * np.sin(h)
    across = d[..., 1] * np.cos(h) - d[..., 0] * np.sin(h)
    return FrenetBoxes(s, s + along.min(axis=1), s + along.max(axis=1), across.min(axis=1), across.max(axis=1))


def frenet_box(path: ReferencePath, shape, s_guess: float) -> FrenetBox:
    """Frenet extent of a world shape near arc length ``s_guess``."""
    g = np.array([s_guess], float)
    if isinstance(shape, WorldCircle):
        return frenet_boxes(path, g, np.asarray(shape.center, float)[None], shape.radius_m)[0]
    return frenet_boxes(path, g, np.zeros((1, 2)), points=np.asarray(shape.points, float)[None])[0]
