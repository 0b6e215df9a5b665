"""The path interface.

Arc length ``s`` [m] is unbounded: on a closed path ``s`` keeps growing lap after lap and
``heading(s)`` keeps turning (it is continuous in ``s``, never jumps by 2*pi); on an open path
the geometry is extended along the end tangents beyond ``[0, length_m]``.
Lateral error ``e_y`` [m] is positive to the left of the path direction.
"""

from __future__ import annotations

import math
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


#: a path doubles back where it comes within the band's width of itself after a stretch more than
#: this many times that distance long (:meth:`ReferencePath.doubling_back`): a turn of more than
#: ~150 deg (legs of equal length: sin(15 deg) ~ 1 / 4), a U-turn onto its own band
DOUBLING_BACK_RATIO = 4.0
#: ... within this many band widths of path (farther returns are followed along the path)
DOUBLING_BACK_REACH = 8.0


@dataclass(frozen=True)
class DoublingBack:
    """Where a path doubles back (:meth:`ReferencePath.doubling_back`): at arc length ``s_back_m``
    [m], point ``xy`` (2,) [m], it is ``distance_m`` [m] from itself at ``s_m`` [m], closer than
    the band around both (``band_m`` [m], the two half widths)."""

    s_m: float
    s_back_m: float
    distance_m: float
    band_m: float
    xy: tuple[float, float]


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

    def doubling_back(self, half_width_m, ds_m: float | None = None) -> DoublingBack | None:
        """Where the path doubles back, or None: the first place where it turns back onto the
        band of ``half_width_m`` [m] either side of itself (a float, or a function of arc length
        giving one per point). Two points at arc lengths ``s1 < s2``, ``d = |p(s1) - p(s2)|``
        apart, with ``d < w(s1) + w(s2)`` (their bands overlap) and
        ``DOUBLING_BACK_RATIO d < s2 - s1 <= DOUBLING_BACK_REACH (w(s1) + w(s2))`` (the path got
        there by turning back within a few band widths, on a closed path ``s2 - s1`` the shorter
        way round): a position in the overlap has two arc lengths close enough for a projection
        searching near the car to take either, so its lateral offset, and every measure taken
        from it, can be wrong by the width of the turn. A reversal onto itself, a U-turn whose
        legs run inside the band, a turn sharper than ~150 deg all do; a curve of any radius, a
        90 deg corner, a hairpin whose legs keep their bands apart, a closed track's joint, a
        crossing or a return far along the path (a loop around a block back on the opposite
        lane: projections follow the car along the path there) do not. Points are compared
        every ``ds_m`` [m] (default: a quarter of the narrowest half width, at least 1/200000 of
        the length)."""
        from scipy.spatial import cKDTree  # here: only scenario checks ask

        L = float(self.length_m)
        w_of = half_width_m if callable(half_width_m) else (lambda s: np.full(np.shape(s), float(half_width_m)))
        if ds_m is None:
            probe = np.linspace(0.0, L, 201)
            ds_m = max(float(np.min(w_of(probe))) / 4.0, L / 200000.0)
        n = max(3, int(math.ceil(L / ds_m)) + 1)
        s = np.linspace(0.0, L, n, endpoint=not self.closed)
        p = np.asarray(self.position(s), float)
        w = np.asarray(w_of(s), float)
        pairs = cKDTree(p).query_pairs(2.0 * float(np.max(w)), output_type="ndarray")
        if len(pairs) == 0:
            return None
        i, j = pairs.min(axis=1), pairs.max(axis=1)
        gap = np.hypot(*(p[i] - p[j]).T)
        along = s[j] - s[i]
        if self.closed:
            along = np.minimum(along, L - along)
        band = w[i] + w[j]
        bad = (gap < band) & (DOUBLING_BACK_RATIO * gap < along) & (along <= DOUBLING_BACK_REACH * band)
        if not np.any(bad):
            return None
        k = np.flatnonzero(bad)
        first = k[np.lexsort((s[i[k]], s[j[k]]))[0]]  # the earliest place it comes back
        a, b = int(i[first]), int(j[first])
        return DoublingBack(
            float(s[a]), float(s[b]), float(gap[first]), float(band[first]), (float(p[b, 0]), float(p[b, 1]))
        )

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
