"""The vehicle's body: a rectangle for clearance checks, covered by discs for the MPC."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .obstacles import WorldPolygon


@dataclass(frozen=True)
class Footprint:
    """Rectangle ``length_m`` x ``width_m`` centred ``center_offset_m`` ahead of the reference point
    (the state's x, y), aligned with the yaw; ``n_discs`` discs along the body cover it."""

    length_m: float = 0.50
    width_m: float = 0.27
    center_offset_m: float = 0.0
    n_discs: int = 3

    def __post_init__(self):
        if not (self.length_m > 0 and self.width_m > 0 and self.n_discs >= 1):
            raise ValueError(f"footprint needs positive length_m, width_m and n_discs >= 1, got {self}")

    def corners(self) -> np.ndarray:
        """(4, 2) corners in the body frame [m], counter-clockwise."""
        hl, hw, c = 0.5 * self.length_m, 0.5 * self.width_m, self.center_offset_m
        return np.array([[c + hl, hw], [c - hl, hw], [c - hl, -hw], [c + hl, -hw]])

    def polygon(self, x: float, y: float, yaw: float) -> WorldPolygon:
        """The body in the world at pose (x m, y m, yaw rad)."""
        c, s = math.cos(yaw), math.sin(yaw)
        p = self.corners()
        return WorldPolygon(np.column_stack([x + c * p[:, 0] - s * p[:, 1], y + s * p[:, 0] + c * p[:, 1]]))

    @property
    def disc_offsets_m(self) -> np.ndarray:
        """(n,) disc centres along the body x axis [m] from the reference point."""
        n, L = self.n_discs, self.length_m
        return self.center_offset_m + (np.arange(n) + 0.5) * (L / n) - 0.5 * L

    @property
    def disc_radius_m(self) -> float:
        """Radius [m] of discs that together cover the rectangle."""
        return math.hypot(0.5 * self.length_m / self.n_discs, 0.5 * self.width_m)
