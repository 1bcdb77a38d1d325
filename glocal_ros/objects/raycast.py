"""Vectorised ray/triangle intersection (Moller-Trumbore).

trimesh's ray module needs rtree or embree, neither of which is installed;
a few hundred rays against ~1000 triangles is cheap in plain numpy.
"""

from __future__ import annotations

import numpy as np


def first_hits(
    triangles: np.ndarray,
    origins: np.ndarray,
    directions: np.ndarray,
    min_distance: float = 1e-6,
    chunk: int = 64,
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit of each ray beyond ``min_distance``.

    :param triangles: (F, 3, 3) triangle corners.
    :param origins: (R, 3) ray origins.
    :param directions: (R, 3) unit ray directions.
    :return: distances (R,), ``inf`` where nothing is hit, and hit face
        indices (R,), -1 where nothing is hit.
    """
    v0 = triangles[:, 0]
    e1 = triangles[:, 1] - v0
    e2 = triangles[:, 2] - v0
    distances = np.full(len(origins), np.inf)
    faces = np.full(len(origins), -1, dtype=np.int64)
    for start in range(0, len(origins), chunk):
        o = origins[start : start + chunk, None, :]
        d = directions[start : start + chunk, None, :]
        pvec = np.cross(d, e2[None])
        det = np.einsum("fk,rfk->rf", e1, pvec)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tvec = o - v0[None]
            u = np.einsum("rfk,rfk->rf", tvec, pvec) * inv
            qvec = np.cross(tvec, e1[None])
            v = np.einsum("rfk,rfk->rf", d, qvec) * inv
            t = np.einsum("fk,rfk->rf", e2, qvec) * inv
            valid = (np.abs(det) > 1e-15) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > min_distance)
        t = np.where(valid, t, np.inf)
        best = np.argmin(t, axis=1)
        best_t = t[np.arange(len(best)), best]
        distances[start : start + chunk] = best_t
        faces[start : start + chunk] = np.where(np.isfinite(best_t), best, -1)
    return distances, faces
