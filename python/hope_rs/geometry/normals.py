"""Face and vertex normals of a triangle mesh, unnormalised (area-weighted)."""

from __future__ import annotations

import numpy as np

__all__ = ["face_normals", "vertex_normal_sums"]


def face_normals(p: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m, 3) cross products of the faces' edges: normal times twice the area."""
    return np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])


def vertex_normal_sums(p: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(n, 3) area-weighted sums of the normals of each vertex's faces (n = len(p))."""
    n = face_normals(p, faces)
    out = np.zeros((len(p), 3))
    for corner in range(3):
        for axis in range(3):
            out[:, axis] += np.bincount(faces[:, corner], n[:, axis], minlength=len(p))
    return out
