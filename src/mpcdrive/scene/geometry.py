"""Signed distances between world shapes (negative = penetration)."""

from __future__ import annotations

import numpy as np

from .obstacles import WorldCircle, WorldPolygon


def point_polygon(p: np.ndarray, poly: np.ndarray) -> tuple[float, np.ndarray]:
    """Signed distance [m] from point ``p`` (2,) to convex polygon ``poly`` (M, 2) ccw, and the
    nearest boundary point."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    d = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
    q = a + t[:, None] * d
    dist = np.hypot(*(p - q).T)
    j = int(np.argmin(dist))
    inside = np.all(d[:, 0] * (p[1] - a[:, 1]) - d[:, 1] * (p[0] - a[:, 0]) >= 0.0)
    return (-float(dist[j]) if inside else float(dist[j])), q[j]


def points_polygon(P: np.ndarray, poly: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vectorized :func:`point_polygon` for points P (K, 2): distances (K,), nearest points (K, 2)."""
    return points_polygons(P, poly[None])


def points_polygons(P: np.ndarray, polys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`point_polygon` of point ``P[k]`` (K, 2) and convex ccw polygon ``polys[k]`` (K, M, 2)
    (or one polygon for all points, (1, M, 2)): distances (K,), nearest points (K, 2)."""
    a = polys
    d = np.roll(polys, -1, axis=1) - polys
    rel = P[:, None, :] - a
    t = np.clip(np.einsum("kmi,kmi->km", rel, np.broadcast_to(d, rel.shape)) / np.einsum("kmi,kmi->km", d, d), 0.0, 1.0)
    q = a + t[..., None] * d
    diff = P[:, None, :] - q
    dist = np.hypot(diff[..., 0], diff[..., 1])
    j = np.argmin(dist, axis=1)
    k = np.arange(len(P))
    cross = d[..., 0] * rel[..., 1] - d[..., 1] * rel[..., 0]
    inside = np.all(cross >= 0.0, axis=1)
    return np.where(inside, -dist[k, j], dist[k, j]), q[k, j]


def point_shape(p: np.ndarray, shape) -> tuple[float, np.ndarray]:
    """Signed distance [m] from point p to a world shape, and the nearest boundary point."""
    if isinstance(shape, WorldCircle):
        v = p - shape.center
        n = float(np.hypot(*v))
        u = v / n if n > 1e-12 else np.array([1.0, 0.0])
        return n - shape.radius_m, shape.center + shape.radius_m * u
    return point_polygon(p, shape.points)


def _sat_overlap(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest overlap along the edge normals of two convex polygons (> 0: they intersect)."""
    best = np.inf
    for poly in (a, b):
        d = np.roll(poly, -1, axis=0) - poly
        normals = np.column_stack([d[:, 1], -d[:, 0]])
        normals /= np.hypot(normals[:, 0], normals[:, 1])[:, None]
        pa = a @ normals.T
        pb = b @ normals.T
        overlap = np.minimum(pa.max(0), pb.max(0)) - np.maximum(pa.min(0), pb.min(0))
        best = min(best, float(overlap.min()))
    return best


def _polygon_polygon(a: np.ndarray, b: np.ndarray) -> float:
    ov = _sat_overlap(a, b)
    if ov > 0:
        return -ov
    d1 = min(point_polygon(p, b)[0] for p in a)
    d2 = min(point_polygon(p, a)[0] for p in b)
    return float(min(d1, d2))


def shape_distance(a: WorldPolygon, b) -> float:
    """Signed distance [m] between a convex world polygon (e.g. the vehicle body) and a world
    shape: the gap when apart, minus the penetration depth when they overlap."""
    if isinstance(b, WorldCircle):
        d, _ = point_polygon(b.center, a.points)
        return d - b.radius_m
    return _polygon_polygon(a.points, b.points)


def road_edges(path_xy: np.ndarray, profile: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Left and right road edges (M, 2) [m] along the polyline ``path_xy``, from a road profile
    (rows ``[s_m, left_m, right_m]``, :meth:`~mpcdrive.scene.road.Road.profile`): each point
    offset along its unit normal by the edges' lateral offsets at its arc length."""
    p = np.asarray(path_xy, dtype=float)
    prof = np.asarray(profile, dtype=float)
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p, axis=0).T))]
    normal = _unit_normals(p)
    left = np.interp(s, prof[:, 0], prof[:, 1])
    right = np.interp(s, prof[:, 0], prof[:, 2])
    return p + left[:, None] * normal, p + right[:, None] * normal


def _unit_normals(path_xy: np.ndarray) -> np.ndarray:
    """(M, 2) unit left normals of a polyline (central-difference tangents; repeated points keep
    the previous normal)."""
    p = np.asarray(path_xy, dtype=float)
    tangent = np.gradient(p, axis=0)
    norm = np.hypot(tangent[:, 0], tangent[:, 1])
    good = norm > 1e-12
    if not good.any():
        raise ValueError("reference path has no extent; cannot draw lane boundaries")
    # carry the last valid tangent over degenerate (repeated) points
    idx = np.where(good, np.arange(len(p)), 0)
    idx = np.maximum.accumulate(idx)
    first_good = int(np.argmax(good))
    idx[: first_good + 1] = first_good
    unit = tangent[idx] / norm[idx, None]
    return np.column_stack([-unit[:, 1], unit[:, 0]])  # left of the direction of travel
