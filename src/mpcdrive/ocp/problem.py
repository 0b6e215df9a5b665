"""Frozen description of a tracking MPC problem (the paper's eq. 15 plus extensions)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..scene.road import Road


def _as_matrix(w, n: int, name: str) -> np.ndarray:
    w = np.asarray(w, float)
    if w.ndim == 0:
        w = np.full(n, float(w))
    if w.ndim == 1:
        if w.shape != (n,):
            raise ValueError(f"{name} must have {n} diagonal entries, got {w.shape[0]}")
        w = np.diag(w)
    if w.shape != (n, n):
        raise ValueError(f"{name} must be {n}x{n}, got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError(f"{name} contains non-finite values")
    if not np.allclose(w, w.T):
        raise ValueError(f"{name} must be symmetric")
    if np.linalg.eigvalsh(w).min() < -1e-12:
        raise ValueError(f"{name} must be positive semidefinite")
    return w


def _as_bounds(lo, hi, n: int, name: str) -> tuple[np.ndarray, np.ndarray]:
    lo = np.broadcast_to(np.asarray(-np.inf if lo is None else lo, float), (n,)).copy()
    hi = np.broadcast_to(np.asarray(np.inf if hi is None else hi, float), (n,)).copy()
    if np.any(np.isnan(lo)) or np.any(np.isnan(hi)):
        raise ValueError(f"{name} bounds contain NaN")
    if np.any(lo == np.inf) or np.any(hi == -np.inf):
        raise ValueError(f"{name} bounds are impossible (lower bound +inf or upper bound -inf): {lo}, {hi}")
    if np.any(lo > hi):
        raise ValueError(f"{name} lower bound exceeds upper bound: {lo} > {hi}")
    return lo, hi


@dataclass(frozen=True, eq=False, init=False)
class MpcProblem:
    """Tracking MPC over ``N`` steps of ``dt_s`` seconds.

    Cost: ``sum_{k=1}^{N-1} (x_k - r_k)' Q (x_k - r_k) + (x_N - r_N)' QN (x_N - r_N)
    + sum_{k=0}^{N-1} (u_k - ur_k)' R (u_k - ur_k) + (u_k - u_{k-1})' Rc (u_k - u_{k-1})
    + sum_k lane_slack_weight * eps_k^2 + lane_slack_weight_l1 * eps_k``
    where ``u_{-1}`` is the input applied at the previous step.

    Constraints: the (linearized) dynamics; ``u_min <= u_k <= u_max``;
    ``|u_k - u_{k-1}| <= du_max_per_s * dt_s``; ``x_min <= x_k <= x_max`` for k >= 1;
    and, when ``road`` is set, the soft road bound ``lo_k - eps_k <= e_y,k <= hi_k + eps_k`` (eq. 53)
    with ``eps_k >= 0``, where ``lo_k, hi_k`` keep the body inside the road
    (:class:`~mpcdrive.scene.road.Road`, the one owner of that rule) -- per step the bounds may be
    narrowed further (a corridor).

    Obstacles: ``obstacle_rows`` half-plane rows per step ``a . (x_k, y_k, yaw_k) + sigma_k >= b``
    with one slack ``sigma_k >= 0`` per step, penalized by ``obstacle_slack_weight`` (quadratic)
    and ``obstacle_slack_weight_l1`` (linear); ``position_cost=True`` marks a problem whose
    stage weights carry a non-convex obstacle cost's (x, y) Hessian, approximated each step (SQP).

    Friction: with ``friction_accel_mps2`` set, the input bounds of each stage are narrowed to
    the friction circle ``a^2 + (v^2 tan(delta) / L)^2 <= friction_accel_mps2^2`` at the stage's
    planned speed (:mod:`mpcdrive.ocp.friction`, for models with ``steer`` and ``accel`` inputs).

    Weights may be given as scalars, diagonals or full matrices; bounds as scalars or vectors
    (None or +-inf = unbounded). Units follow the model's states and inputs (SI, radians). The
    attributes hold them normalized: full matrices, and one bound per state / input.
    """

    nx: int
    nu: int
    N: int
    dt_s: float
    Q: np.ndarray
    R: np.ndarray
    QN: np.ndarray
    Rc: np.ndarray
    u_min: np.ndarray
    u_max: np.ndarray
    du_max_per_s: np.ndarray
    x_min: np.ndarray
    x_max: np.ndarray
    road: Road | None
    lane_slack_weight: float
    lane_slack_weight_l1: float
    obstacle_rows: int
    obstacle_slack_weight: float
    obstacle_slack_weight_l1: float
    position_cost: bool
    friction_accel_mps2: float | None

    def __init__(
        self,
        nx: int,
        nu: int,
        N: int,
        dt_s: float,
        Q: npt.ArrayLike,
        R: npt.ArrayLike,
        *,
        QN: npt.ArrayLike | None = None,
        Rc: npt.ArrayLike | None = None,
        u_min: npt.ArrayLike | None = None,
        u_max: npt.ArrayLike | None = None,
        du_max_per_s: npt.ArrayLike | None = None,
        x_min: npt.ArrayLike | None = None,
        x_max: npt.ArrayLike | None = None,
        road: Road | None = None,
        lane_slack_weight: float = 1e4,
        lane_slack_weight_l1: float = 1e3,
        obstacle_rows: int = 0,
        obstacle_slack_weight: float = 1e4,
        obstacle_slack_weight_l1: float = 1e3,
        position_cost: bool = False,
        friction_accel_mps2: float | None = None,
    ):
        for name, v in (("nx", nx), ("nu", nu)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        if isinstance(N, bool) or not isinstance(N, (int, float, np.integer, np.floating)) or not np.isfinite(N):
            raise ValueError(f"horizon N must be a positive integer, got {N!r}")
        if int(N) != N or N < 1:
            raise ValueError(f"horizon N must be a positive integer, got {N}")
        if not (np.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s must be a positive finite number, got {dt_s}")
        for name, value in (
            ("nx", nx),
            ("nu", nu),
            ("N", int(N)),
            ("dt_s", dt_s),
            ("road", road),
            ("lane_slack_weight", lane_slack_weight),
            ("lane_slack_weight_l1", lane_slack_weight_l1),
            ("obstacle_rows", obstacle_rows),
            ("obstacle_slack_weight", obstacle_slack_weight),
            ("obstacle_slack_weight_l1", obstacle_slack_weight_l1),
            ("position_cost", position_cost),
            ("friction_accel_mps2", None if friction_accel_mps2 is None else float(friction_accel_mps2)),
        ):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "Q", _as_matrix(Q, nx, "Q"))
        object.__setattr__(self, "R", _as_matrix(R, nu, "R"))
        object.__setattr__(self, "QN", _as_matrix(self.Q if QN is None else QN, nx, "QN"))
        object.__setattr__(self, "Rc", _as_matrix(0.0 if Rc is None else Rc, nu, "Rc"))
        u_min, u_max = _as_bounds(u_min, u_max, nu, "input")
        object.__setattr__(self, "u_min", u_min)
        object.__setattr__(self, "u_max", u_max)
        du = np.broadcast_to(np.asarray(np.inf if du_max_per_s is None else du_max_per_s, float), (nu,)).copy()
        if np.any(np.isnan(du)) or np.any(du <= 0):
            raise ValueError(f"du_max_per_s must be positive, got {du}")
        object.__setattr__(self, "du_max_per_s", du)
        x_min, x_max = _as_bounds(x_min, x_max, nx, "state")
        object.__setattr__(self, "x_min", x_min)
        object.__setattr__(self, "x_max", x_max)
        if road is not None and not isinstance(road, Road):
            raise ValueError(f"road must be a mpcdrive.scene.road.Road or None, got {type(road).__name__}")
        for name in ("lane_slack_weight", "lane_slack_weight_l1"):
            w = getattr(self, name)
            if not (np.isfinite(w) and w >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {w!r}")
        unbounded = np.isinf(u_min) & np.isinf(u_max)
        if np.any(unbounded):
            # every input without bounds needs a positive definite weight on it
            W = (self.R + self.Rc)[np.ix_(unbounded, unbounded)]
            if np.linalg.eigvalsh(W).min() <= 1e-12 * max(1.0, float(np.abs(W).max())):
                raise ValueError("R + Rc must be positive definite on the inputs without bounds")
        if int(self.obstacle_rows) != self.obstacle_rows or self.obstacle_rows < 0:
            raise ValueError(f"obstacle_rows must be a non-negative integer, got {self.obstacle_rows}")
        if self.obstacle_slack_weight < 0 or self.obstacle_slack_weight_l1 < 0:
            raise ValueError("obstacle slack weights must be >= 0")
        if (self.obstacle_rows or self.position_cost) and nx < 3:
            raise ValueError("obstacle terms need states x, y, yaw")
        f = self.friction_accel_mps2
        if f is not None and not (math.isfinite(f) and f > 0):
            raise ValueError(f"friction_accel_mps2 must be a positive finite number or None, got {f!r}")

    def stage_weights(self) -> np.ndarray:
        """(N, nx, nx) the state weights of x_1..x_N: Q for the first N-1, QN for the last (a new
        array)."""
        return np.stack([self.Q] * (self.N - 1) + [self.QN]).astype(float)

    @property
    def lane(self) -> bool:
        """True when the problem has the soft road rows."""
        return self.road is not None

    @property
    def has_rate_limit(self) -> bool:
        return bool(np.any(np.isfinite(self.du_max_per_s)))

    @property
    def bounded_states(self) -> np.ndarray:
        """Indices of states with at least one finite bound."""
        return np.flatnonzero(np.isfinite(self.x_min) | np.isfinite(self.x_max))
