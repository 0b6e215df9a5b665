"""The vehicle-model interface every model (kinematic, dynamic, ...) implements."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class VehicleModel(Protocol):
    """Continuous-time vehicle model ``xdot = f(x, u)``.

    Conventions: the first three states are always the pose ``x [m], y [m], yaw [rad]``
    (world frame, x east, y north, yaw counter-clockwise) so paths, plots and the simulator
    can read a pose from any model. Methods accept a single state ``(nx,)`` or a batch
    ``(..., nx)`` with matching inputs ``(..., nu)``.
    """

    nx: int
    nu: int
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """State derivative ``(..., nx)`` in SI units per second."""

    def jacobians(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Analytic ``(df/dx (..., nx, nx), df/du (..., nx, nu))``."""

    def speed(self, x: np.ndarray) -> np.ndarray:
        """Speed of the reference point [m/s] for each state of a batch ``(...,)``."""

    def steady_state(self, kappa, v_mps=None) -> tuple[np.ndarray, np.ndarray]:
        """Steady-state (steering angle [rad], slip angle [rad]) that keeps the reference point on
        a path of curvature kappa [1/m] at speed v_mps [m/s]; the yaw then trails the path
        heading by the slip angle."""

    def reference(
        self, pose: np.ndarray, kappa: np.ndarray, v_mps: np.ndarray, feedforward: bool = True
    ) -> tuple[np.ndarray, np.ndarray]:
        """Reference states ``(K, nx)`` and inputs ``(K, nu)`` for path points ``pose`` (K, 3)
        [x m, y m, heading rad] of curvature kappa (K,) [1/m] driven at v_mps (K,) [m/s]: with
        ``feedforward`` the steady-state cornering state and inputs, otherwise the path pose with
        zero inputs."""
