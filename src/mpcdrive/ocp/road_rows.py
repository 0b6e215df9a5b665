"""The road rows of a step: the body inside the road (:mod:`mpcdrive.scene.road`) as bounds on
the reference point's lateral offset at each horizon step, linearized in the yaw at the
linearization trajectory (``lo_k + dlo_k (yaw_k - yawbar_k) <= e_y,k <= hi_k + dhi_k (yaw_k -
yawbar_k)``). The OSQP controller calls this; the compiled step calls
:func:`~mpcdrive.scene.road.horizon_bounds` on its buffers, the same function."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene.footprint import Footprint
from ..scene.road import Road, horizon_bounds


@dataclass
class RoadRows:
    """Work buffers of the road rows of steps 1..N: bounds ``lo``, ``hi`` [m] at the
    linearization yaw ``yaw`` [rad], and their slopes ``dlo``, ``dhi`` [m/rad] in the yaw."""

    lo: np.ndarray
    hi: np.ndarray
    dlo: np.ndarray
    dhi: np.ndarray
    yaw: np.ndarray

    @classmethod
    def empty(cls, N: int) -> RoadRows:
        return cls(*(np.zeros(N) for _ in range(5)))

    def fill(self, road: Road, footprint: Footprint, s_arr: np.ndarray, refs: np.ndarray, Xlin: np.ndarray) -> RoadRows:
        """The rows for ``s_arr`` (N+1,) horizon arc lengths [m], ``refs`` (N+1, 4) path states
        ``[x, y, heading, curvature]`` there and ``Xlin`` (N+1, nx) the linearization trajectory
        (yaw in column 2)."""
        self.yaw[:] = Xlin[1:, 2]
        horizon_bounds(
            road.s_m,
            road.left_m,
            road.right_m,
            road.period_m,
            np.ascontiguousarray(s_arr[1:]),
            np.ascontiguousarray(refs[1:, 2]),
            np.ascontiguousarray(refs[1:, 3]),
            self.yaw,
            0.5 * footprint.length_m,
            0.5 * footprint.width_m,
            footprint.center_offset_m,
            road.margin_m,
            self.lo,
            self.hi,
            self.dlo,
            self.dhi,
        )
        return self

    def narrowed(self, lo: np.ndarray | None, hi: np.ndarray | None) -> RoadRows:
        """These rows with the bounds replaced by a corridor's ``lo``, ``hi`` (N,) where it
        narrows them (those bounds are the corridor's, with no yaw slope)."""
        if lo is None or hi is None:
            return self
        return RoadRows(
            lo, hi, np.where(lo != self.lo, 0.0, self.dlo), np.where(hi != self.hi, 0.0, self.dhi), self.yaw
        )
