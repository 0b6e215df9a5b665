"""Frozen description of a tracking MPC problem (the paper's eq. 15 plus extensions)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
    if np.any(lo > hi):
        raise ValueError(f"{name} lower bound exceeds upper bound: {lo} > {hi}")
    return lo, hi


@dataclass(frozen=True, eq=False)
class MpcProblem:
    """Tracking MPC over ``N`` steps of ``dt_s`` seconds.

    Cost: ``sum_{k=1}^{N-1} (x_k - r_k)' Q (x_k - r_k) + (x_N - r_N)' QN (x_N - r_N)
    + sum_{k=0}^{N-1} (u_k - ur_k)' R (u_k - ur_k) + (u_k - u_{k-1})' Rc (u_k - u_{k-1})
    + sum_k lane_slack_weight * eps_k^2 + lane_slack_weight_l1 * eps_k``
    where ``u_{-1}`` is the input applied at the previous step.

    Constraints: the (linearized) dynamics; ``u_min <= u_k <= u_max``;
    ``|u_k - u_{k-1}| <= du_max_per_s * dt_s``; ``x_min <= x_k <= x_max`` for k >= 1;
    and, when ``lane_half_width_m`` is set, the soft lane bound ``|e_y,k| <= lane_half_width_m + eps_k``
    (eq. 53) with ``eps_k >= 0``.

    Weights may be given as scalars, diagonals or full matrices; bounds as scalars or vectors
    (None or +-inf = unbounded). Units follow the model's states and inputs (SI, radians).
    """

    nx: int
    nu: int
    N: int
    dt_s: float
    Q: np.ndarray
    R: np.ndarray
    QN: np.ndarray | None = None
    Rc: np.ndarray | None = None
    u_min: np.ndarray | float | None = None
    u_max: np.ndarray | float | None = None
    du_max_per_s: np.ndarray | float | None = None
    x_min: np.ndarray | float | None = None
    x_max: np.ndarray | float | None = None
    lane_half_width_m: float | None = None
    lane_slack_weight: float = 1e4
    lane_slack_weight_l1: float = 1e3

    def __post_init__(self):
        if int(self.N) != self.N or self.N < 1:
            raise ValueError(f"horizon N must be a positive integer, got {self.N}")
        if not (np.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"dt_s must be a positive finite number, got {self.dt_s}")
        nx, nu = self.nx, self.nu
        object.__setattr__(self, "N", int(self.N))
        object.__setattr__(self, "Q", _as_matrix(self.Q, nx, "Q"))
        object.__setattr__(self, "R", _as_matrix(self.R, nu, "R"))
        object.__setattr__(self, "QN", _as_matrix(self.Q if self.QN is None else self.QN, nx, "QN"))
        object.__setattr__(self, "Rc", _as_matrix(0.0 if self.Rc is None else self.Rc, nu, "Rc"))
        u_min, u_max = _as_bounds(self.u_min, self.u_max, nu, "input")
        object.__setattr__(self, "u_min", u_min)
        object.__setattr__(self, "u_max", u_max)
        du = np.broadcast_to(np.asarray(np.inf if self.du_max_per_s is None else self.du_max_per_s, float), (nu,)).copy()
        if np.any(np.isnan(du)) or np.any(du <= 0):
            raise ValueError(f"du_max_per_s must be positive, got {du}")
        object.__setattr__(self, "du_max_per_s", du)
        x_min, x_max = _as_bounds(self.x_min, self.x_max, nx, "state")
        object.__setattr__(self, "x_min", x_min)
        object.__setattr__(self, "x_max", x_max)
        if self.lane_half_width_m is not None and not (np.isfinite(self.lane_half_width_m) and self.lane_half_width_m > 0):
            raise ValueError(f"lane_half_width_m must be positive, got {self.lane_half_width_m}")
        if self.lane_slack_weight < 0 or self.lane_slack_weight_l1 < 0:
            raise ValueError("lane slack weights must be >= 0")
        RRc = self.R + self.Rc
        if np.linalg.eigvalsh(RRc).min() <= 1e-12 * max(1.0, float(np.abs(RRc).max())) and np.all(np.isinf(u_max)):
            raise ValueError("R + Rc must be positive definite when inputs are unbounded")

    @property
    def has_rate_limit(self) -> bool:
        return bool(np.any(np.isfinite(self.du_max_per_s)))

    @property
    def bounded_states(self) -> np.ndarray:
        """Indices of states with at least one finite bound."""
        return np.flatnonzero(np.isfinite(self.x_min) | np.isfinite(self.x_max))
