"""The path interface.

Arc length ``s`` [m] is unbounded: on a closed path ``s`` keeps growing lap after lap and
``heading(s)`` keeps turning (it is continuous in ``s``, never jumps by 2*pi); on an open path
the geometry is extended along the end tangents beyond ``[0, length_m]``.
Lateral error ``e_y`` [m] is positive to the left of the path direction.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from ..units import wrap_angle


@dataclass(frozen=True)
class Projection:
    """Frenet coordinates of a pose: s [m], e_y [m] (left +), e_psi [rad] in (-pi, pi]."""

    s_m: float
    e_y_m: float
    e_psi_rad: float


class ReferencePath(ABC):
    """A planar reference path parameterized by arc length."""

    length_m: float
    closed: bool

    @abstractmethod
    def position(self, s) -> np.ndarray:
        """(..., 2) position [m] at arc length(s) ``s`` [m]."""

    @abstractmethod
    def heading(self, s) -> np.ndarray:
        """Tangent heading [rad], continuous (unwrapped) in ``s``."""

    @abstractmethod
    def curvature(self, s) -> np.ndarray:
        """Signed curvature kappa [1/m] (left turn positive)."""

    @abstractmethod
    def _project_xy(self, xy: np.ndarray, s_guess: float | None, window_m: float) -> tuple[float, float]:
        """(s, e_y) of the nearest point; near ``s_guess`` when given."""

    def project(self, xy, s_guess: float | None = None, window_m: float = 2.0) -> tuple[float, float]:
        """Nearest point of the path to position ``xy`` (2,) [m].

        With ``s_guess`` [m] only the stretch ``s_guess +- window_m`` is searched (so closed and
        self-approaching paths do not jump to another branch) and the returned ``s`` is the
        candidate closest to ``s_guess`` (laps counted on closed paths). Returns ``(s_m, e_y_m)``.
        """
        xy = np.asarray(xy, float)
        if xy.shape != (2,) or not np.all(np.isfinite(xy)):
            raise ValueError(f"position must be 2 finite numbers, got {xy!r}")
        if s_guess is not None and not np.isfinite(s_guess):
            raise ValueError(f"s_guess must be finite or None, got {s_guess!r}")
        if not (np.isfinite(window_m) and window_m > 0):
            raise ValueError(f"window_m must be a positive finite number, got {window_m!r}")
        return self._project_xy(xy, s_guess, window_m)

    def project_many(self, xy, s_guess, window_m) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`project` of the points ``xy`` (K, 2) [m], point k searched near its own
        ``s_guess[k]`` within ``window_m[k]`` [m] (arrays (K,)). Returns arrays ``(s_m, e_y_m)``."""
        xy = _checked_points(xy)
        K = len(xy)
        s_guess = np.broadcast_to(np.asarray(s_guess, float), (K,))
        window_m = np.broadcast_to(np.asarray(window_m, float), (K,))
        if not np.all(np.isfinite(s_guess)):
            raise ValueError("s_guess must be finite")
        if not (np.all(np.isfinite(window_m)) and np.all(window_m > 0)):
            raise ValueError("window_m must be positive finite numbers")
        return self._project_many_xy(xy, s_guess, window_m)

    def project_track(
        self, xy, s_guess: float, window_m: float, step_margin_m: float = 2.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`project` of the successive positions ``xy`` (K, 2) [m] of one body (a predicted
        or recorded track): the first searched near ``s_guess`` within ``window_m`` [m], each
        later one near the one before, within the distance between them plus ``step_margin_m``
        [m]. Cheaper than :meth:`project_many` with one wide window for all, and it keeps a track
        on its branch of a path that comes back near itself. Returns arrays ``(s_m, e_y_m)``."""
        xy = _checked_points(xy)
        if not np.isfinite(s_guess):
            raise ValueError(f"s_guess must be finite, got {s_guess!r}")
        for name, v in (("window_m", window_m), ("step_margin_m", step_margin_m)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive finite number, got {v!r}")
        return self._project_track_xy(xy, float(s_guess), float(window_m), float(step_margin_m))

    def _project_track_xy(
        self, xy: np.ndarray, s_guess: float, window_m: float, step_margin_m: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """(s, e_y) arrays of :meth:`project_track`, one :meth:`_project_xy` per point unless a
        path compiles it."""
        s, e = np.empty(len(xy)), np.empty(len(xy))
        guess, window = s_guess, window_m
        for k in range(len(xy)):
            if k:
                window = float(np.hypot(*(xy[k] - xy[k - 1]))) + step_margin_m
            s[k], e[k] = self._project_xy(xy[k], guess, window)
            guess = s[k]
        return s, e

    def _project_many_xy(
        self, xy: np.ndarray, s_guess: np.ndarray, window_m: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(s, e_y) arrays of :meth:`project_many`, one :meth:`_project_xy` per point unless a
        path vectorizes it."""
        out = np.array([self._project_xy(p, float(g), float(w)) for p, g, w in zip(xy, s_guess, window_m)])
        out = out.reshape(len(xy), 2)
        return out[:, 0], out[:, 1]

    def frenet(self, pose, s_guess: float | None = None, window_m: float = 2.0) -> Projection:
        """(s, e_y, e_psi) of a pose ``(x m, y m, yaw rad)``."""
        pose = np.asarray(pose, float)
        s, e_y = self.project(pose[:2], s_guess, window_m)
        e_psi = wrap_angle(pose[2] - float(self.heading(s)))
        return Projection(float(s), float(e_y), float(e_psi))

    def polyline(self, ds_m: float | None = None) -> np.ndarray:
        """(M, 2) points along one traversal of the path, for plots [m]."""
        n = max(2, int(np.ceil(self.length_m / (ds_m or self.length_m / 400))) + 1)
        return self.position(np.linspace(0.0, self.length_m, n))

    def _lap_shift(self, s_local: float, s_guess: float | None) -> float:
        """On a closed path, add the multiple of the length that brings s near s_guess."""
        if not self.closed or s_guess is None:
            return s_local
        L = self.length_m
        return s_local + L * np.round((s_guess - s_local) / L)


def _checked_points(xy) -> np.ndarray:
    """``xy`` as a (K, 2) float array of finite positions [m], else a ValueError."""
    xy = np.asarray(xy, float)
    if xy.ndim != 2 or xy.shape[1:] != (2,) or not np.all(np.isfinite(xy)):
        raise ValueError(f"positions must be (K, 2) finite numbers, got shape {xy.shape}")
    return xy
