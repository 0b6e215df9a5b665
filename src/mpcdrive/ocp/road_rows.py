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


@dataclass(eq=False)
class RoadRows:
    """Work buffers of the road rows of steps 1..N: bounds ``lo``, ``hi`` [m] at the
    linearization yaw ``yaw`` [rad], and their slopes ``dlo``, ``dhi`` [m/rad] in the yaw;
    ``path`` (3, N): the arc lengths, path headings and curvatures they were evaluated at."""

    lo: np.ndarray
    hi: np.ndarray
    dlo: np.ndarray
    dhi: np.ndarray
    yaw: np.ndarray
    path: np.ndarray

    @classmethod
    def empty(cls, N: int) -> RoadRows:
        return cls(np.zeros(N), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros((3, N)))

    def fill(self, road: Road, footprint: Footprint, s_arr: np.ndarray, refs: np.ndarray, Xlin: np.ndarray) -> RoadRows:
        """The rows for ``s_arr`` (N+1,) horizon arc lengths [m], ``refs`` (N+1, 4) path states
        ``[x, y, heading, curvature]`` there and ``Xlin`` (N+1, nx) the linearization trajectory
        (yaw in column 2)."""
        self.yaw[:] = Xlin[1:, 2]
        path = self.path  # updated in place: no allocation per step
        path[0] = s_arr[1:]
        path[1] = refs[1:, 2]
        path[2] = refs[1:, 3]
        horizon_bounds(
            road.s_m,
            road.left_m,
            road.right_m,
            road.period_m,
            path[0],
            path[1],
            path[2],
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

    def narrow(self, lo: np.ndarray | None, hi: np.ndarray | None) -> RoadRows:
        """Replace the bounds, in place, by a corridor's ``lo``, ``hi`` (N,) (None: no corridor)."""
        if lo is not None and hi is not None:
            narrow_road_rows(self.lo, self.hi, self.dlo, self.dhi, lo, hi)
        return self


def narrow_road_rows(lo, hi, dlo, dhi, corridor_lo, corridor_hi) -> None:
    """The road rows ``lo``, ``hi`` with their yaw slopes ``dlo``, ``dhi`` (N,), narrowed in place
    by a corridor's bounds: where the corridor's bound differs from the road's it is the
    corridor's, with no yaw slope (the corridor bounds the reference point). Both controllers
    call this: the OSQP one on :class:`RoadRows`, the compiled one on its buffers."""
    dlo[corridor_lo != lo] = 0.0
    dhi[corridor_hi != hi] = 0.0
    lo[:] = corridor_lo
    hi[:] = corridor_hi
