"""The soft obstacle costs of :mod:`mpcdrive.ocp.avoidance` (formulations ``potential`` and
``gaussian``):

* ``potential`` -- the repulsive field of eq. 55, ``w / (|p - p_o|^2 + eps)``;
* ``gaussian`` -- the Gaussian of eq. 56, ``w exp(-1/2 (p - p_o)' Sigma^-1 (p - p_o))`` (the
  normalizing constant is folded into ``w``), Sigma aligned with the path at the obstacle.

Both are non-convex: each QP gets their second-order model at the linearization point with the
Hessian projected onto the positive semidefinite cone (:func:`position_cost`, sequential
quadratic programming). :func:`obstacle_cost` gives their value, for cost maps.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..paths.base import ReferencePath

if TYPE_CHECKING:
    from .avoidance import AvoidanceConfig
    from .frenet import FrenetBoxes

__all__ = ["obstacle_cost", "position_cost", "sigma_inv"]


def sigma_inv(sigma_m: tuple[float, float], heading_rad: float) -> np.ndarray:
    """Sigma^-1 of eq. 56 in the world frame, ``sigma_m`` = (sx along, sy across) the path
    heading ``heading_rad`` [m]."""
    sx, sy = sigma_m
    Rm = np.array([[math.cos(heading_rad), -math.sin(heading_rad)], [math.sin(heading_rad), math.cos(heading_rad)]])
    return Rm @ np.diag([1.0 / sx**2, 1.0 / sy**2]) @ Rm.T


def position_cost(
    config: AvoidanceConfig,
    path: ReferencePath,
    Xlin: np.ndarray,
    rel: list[int],
    boxes: dict[int, FrenetBoxes],
    centers: dict[int, np.ndarray],
    present: dict[int, np.ndarray],
    H: np.ndarray,
    g: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The convexified cost of the obstacles ``rel`` on the positions of steps 1..N, written into
    ``H`` (N, 2, 2) and ``g`` (N, 2) (the cost ``1/2 p' H p + g' p`` of each step's position p).

    Xlin : (N+1, nx) linearization trajectory; boxes, centers : the obstacles' Frenet boxes and
    centres (N+1, 2) over the horizon, by index; present : (N,) whether each obstacle exists at
    steps 1..N (no cost where it does not)."""
    H[:] = 0.0
    g[:] = 0.0
    p = Xlin[1:, :2]
    w = config.weight
    for j in rel:
        d = p - centers[j][1:]
        if config.formulation == "potential":
            den = np.einsum("ki,ki->k", d, d) + config.epsilon_m2
            grad = -2.0 * w * d / den[:, None] ** 2
            hess = (-2.0 * w / den**2)[:, None, None] * np.eye(2) + 8.0 * w * np.einsum("ki,kj->kij", d, d) / den[
                :, None, None
            ] ** 3
        else:
            Sinv = sigma_inv(config.sigma_m, float(path.heading(boxes[j][0].s_ref)))
            Sd = d @ Sinv
            val = w * np.exp(-0.5 * np.einsum("ki,ki->k", d, Sd))
            grad = -val[:, None] * Sd
            hess = val[:, None, None] * (np.einsum("ki,kj->kij", Sd, Sd) - Sinv)
        ev, V = np.linalg.eigh(hess)
        hp = np.einsum("kij,kj,klj->kil", V, np.maximum(ev, 0.0), V)
        if not present[j].all():  # no cost at the steps the obstacle does not exist
            hp = hp * present[j][:, None, None]
            grad = grad * present[j][:, None]
        H += hp
        g += grad - np.einsum("kij,kj->ki", hp, p)
    return H, g


def obstacle_cost(config: AvoidanceConfig, dx: np.ndarray, dy: np.ndarray, heading_rad: float = 0.0) -> np.ndarray:
    """The potential (eq. 55) or Gaussian (eq. 56) cost at offsets (dx, dy) [m] from an
    obstacle's reference point, Sigma aligned with ``heading_rad``; for cost maps."""
    if config.formulation == "potential":
        return config.weight / (dx * dx + dy * dy + config.epsilon_m2)
    if config.formulation != "gaussian":
        raise ValueError(f"{config.formulation!r} has no cost map (it is a constraint)")
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    a = c * dx + s * dy
    b = -s * dx + c * dy
    sx, sy = config.sigma_m
    return config.weight * np.exp(-0.5 * ((a / sx) ** 2 + (b / sy) ** 2))
