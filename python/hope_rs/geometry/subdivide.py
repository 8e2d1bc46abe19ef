"""Midpoint subdivision of triangle meshes (each face split into four)."""

from __future__ import annotations

import numpy as np

from .mesh import Mesh

__all__ = ["subdivide"]


def subdivide(mesh: Mesh, times: int = 1) -> Mesh:
    """``mesh`` with each face split into four at its edges' midpoints, ``times`` over.

    The original vertices come first and keep their indices (a ground truth on them carries
    over); each new vertex is the midpoint of one edge, and faces keep their orientation."""
    v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    for _ in range(times):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = v.shape[0] + inv.reshape(3, -1).T
        corners = [np.stack([f[:, i], mid[:, i], mid[:, (i + 2) % 3]], 1) for i in range(3)]
        v, f = np.vstack([v, v[uniq].mean(axis=1)]), np.concatenate([*corners, mid])
    return Mesh(v, f)
