"""How rough a surface is at its own resolution, and a coarse copy smoothed to match.

A coarse copy of a noisy dense scan keeps the noise of the vertices it keeps, at a
resolution where the noise is no longer small against the edges; matched to a clean template
its descriptors and k-hop balls compare a rough surface with a smooth one.
"""

from __future__ import annotations

import numpy as np

from .mesh import Mesh, unique_edges
from .normals import vertex_normal_sums
from .sites import owner_means

__all__ = ["ROUGHNESS_FLOOR", "at_owner_means", "normal_roughness", "rougher", "umbrella_smoothed"]

#: The least roughness a comparison divides by (mean edge lengths): a flat surface measures
#: 0 and a finely subdivided one about 0.017, so against them any noise would read as
#: infinitely rougher.
ROUGHNESS_FLOOR = 0.02


def _ring_sums(v: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Per vertex, the sum of its 1-ring's points (``e``: the unique edges)."""
    # One bincount per coordinate adds in the order np.add.at over e[:, 0], then e[:, 1] would
    # (the same sums bit for bit), several times faster.
    at = np.concatenate([e[:, 0], e[:, 1]])
    src = np.concatenate([e[:, 1], e[:, 0]])
    n = len(v)
    return np.column_stack(
        [np.bincount(at, weights=v[src, k].astype(np.float64), minlength=n) for k in range(3)]
    )


def normal_roughness(mesh: Mesh) -> float:
    """The median over vertices of how far a vertex lies off the centroid of its 1-ring along
    its normal (area-weighted), in units of its mean edge length: a scale-free measure that
    smooth curvature keeps small and vertex noise makes large. 0 for a mesh without edges."""
    v, f = mesh.vertices, mesh.faces
    e = unique_edges(f)
    if e.size == 0:
        return 0.0
    n = len(v)
    deg = np.bincount(e.ravel(), minlength=n).astype(float)
    ring = _ring_sums(v, e)
    length = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    total = np.bincount(e[:, 0], length, n) + np.bincount(e[:, 1], length, n)
    normal = vertex_normal_sums(v, f)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    ok = (deg > 0) & (total > 0)
    off = np.abs(np.sum((v[ok] - ring[ok] / deg[ok, None]) * normal[ok], axis=1))
    return float(np.median(off / (total[ok] / deg[ok])))


def rougher(mesh: Mesh, than: Mesh) -> float:
    """How many times as rough ``mesh`` is as ``than`` (:func:`normal_roughness`, each at its
    own resolution; ``than``'s measure at least :data:`ROUGHNESS_FLOOR`)."""
    return normal_roughness(mesh) / max(normal_roughness(than), ROUGHNESS_FLOOR)


def at_owner_means(coarse: Mesh, fine: np.ndarray, owner: np.ndarray) -> Mesh:
    """``coarse`` with each vertex at the mean of the fine points ``fine`` it owns
    (``owner[i]``: the coarse vertex of fine point ``i``); a vertex that owns none stays."""
    means, has = owner_means(fine, owner, coarse.n_vertices)
    pts = coarse.vertices.copy()
    pts[has] = means[has]
    return Mesh(pts, coarse.faces)


def umbrella_smoothed(mesh: Mesh, iterations: int) -> Mesh:
    """``mesh`` with each vertex moved ``iterations`` times halfway to the centroid of its
    1-ring (the faces kept): takes vertex noise out, and shrinks the surface a little."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    e = unique_edges(mesh.faces)
    if e.size == 0 or iterations <= 0:
        return Mesh(v, mesh.faces)
    n = len(v)
    deg = np.bincount(e.ravel(), minlength=n).astype(float)
    has = deg > 0  # a vertex in no edge stays
    for _ in range(iterations):
        ring = _ring_sums(v, e)
        v = v.copy()
        v[has] = 0.5 * v[has] + 0.5 * ring[has] / deg[has, None]
    return Mesh(v, mesh.faces)
