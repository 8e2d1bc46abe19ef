"""Handles: the vertices a map has placed consistently with the faces both shapes share.

A vertex of A is a handle of a map ``f`` when every face around it maps onto a face of B with
the same orientation and no other vertex shares its image. On shapes that are one
triangulation in two poses, the true map makes almost every vertex a handle; on shapes
remeshed independently few vertices are. The shared-face finish (:mod:`hope_rs.pipeline.shared_faces`)
deforms towards them, and the growth (:mod:`hope_rs.pipeline.growth`) starts from those in large
connected patches pinned by an irregular vertex (:func:`irregular_vertices`).
"""

from __future__ import annotations

import numpy as np

from ..geometry.mesh import Mesh
from ..geometry.orientation import face_keys
from ..shape import Shape
from .anchors import masked_components

__all__ = [
    "face_handles",
    "face_keys",
    "irregular_vertices",
    "edge_large_patches",
    "large_patches",
    "mesh_face_handles",
    "seed_handles",
]


def face_handles(a: Shape, b: Shape, f: np.ndarray) -> np.ndarray:
    """Vertices of A whose faces all map onto faces of B, with the same orientation, and
    whose image is the image of no other vertex. ``f`` may be partial (-1 where unknown):
    unknown vertices are not handles, nor are those with an unknown neighbour on a face."""
    return mesh_face_handles(a.internal, b.internal, f)


def mesh_face_handles(ma: Mesh, mb: Mesh, f: np.ndarray) -> np.ndarray:
    """:func:`face_handles` of the map ``f`` from mesh ``ma`` to mesh ``mb``, in their own
    numberings (a mesh not yet made a Shape)."""
    fa, fb = ma.faces.astype(np.int64), mb.faces.astype(np.int64)
    n_b = mb.n_vertices
    f = np.asarray(f, dtype=np.int64)
    known = f >= 0
    f = np.where(known, f, 0)
    mapped = f[fa]
    ok = np.isin(face_keys(mapped, n_b), face_keys(fb, n_b)) & known[fa].all(axis=1)
    bad = np.zeros(ma.n_vertices, dtype=bool)
    bad[fa[~ok].ravel()] = True
    shared = np.bincount(f[known], minlength=n_b)[f] > 1
    return known & ~bad & ~shared


def seed_handles(
    a: Shape, b: Shape, f: np.ndarray, min_share: float, min_irregular: int = 0
) -> np.ndarray:
    """The handles of ``f`` (see :func:`face_handles`) in connected patches of at least
    ``min_share`` of A's vertices (``GrowthConfig.seed_share``) holding at least
    ``min_irregular`` irregular vertices (``GrowthConfig.seed_irregular``, see
    :func:`irregular_vertices`)."""
    return large_patches(a, face_handles(a, b, f), min_share, min_irregular)


def irregular_vertices(a: Shape) -> np.ndarray:
    """A's vertices where the triangulation is not a regular lattice: inside, not six faces;
    on a boundary, not three. A patch of handles without one is a piece of a regular lattice,
    which a map shifted by whole edges also sends face onto face (subdivided meshes are such
    lattices between their original vertices); a patch holding one is pinned."""
    n = a.n_vertices
    faces = np.bincount(a.internal.faces.ravel(), minlength=n)
    neighbours = np.bincount(a.edges.ravel(), minlength=n)
    inside = neighbours == faces
    return np.where(inside, faces != 6, (faces != 3) | (neighbours != 4))


def large_patches(
    a: Shape, mask: np.ndarray, min_share: float, min_irregular: int = 0
) -> np.ndarray:
    """``mask`` restricted to its connected patches (over A's edges) of at least
    ``min_share`` of A's vertices and at least ``min_irregular`` irregular vertices of
    ``mask`` (:func:`irregular_vertices`): wrong handles lie in small patches or in patches
    of a regular lattice (see :mod:`hope_rs.pipeline.growth` and docs/decisions.md#growth)."""
    pinned = irregular_vertices(a) if min_irregular > 0 else None
    return _large(a.edges, mask, min_share, pinned, min_irregular)


def edge_large_patches(edges: np.ndarray, mask: np.ndarray, min_share: float) -> np.ndarray:
    """:func:`large_patches` (without the irregular-vertex condition) over undirected
    ``edges`` (a Shape's ``edges``, or ``unique_edges`` of a mesh not yet made a Shape)."""
    return _large(edges, mask, min_share, None, 0)


def _large(
    edges: np.ndarray,
    mask: np.ndarray,
    min_share: float,
    pinned: np.ndarray | None,
    min_pinned: int,
) -> np.ndarray:
    """``mask`` restricted to its connected patches over ``edges`` of at least ``min_share``
    of the vertices and, with ``pinned`` (bool per vertex), ``min_pinned`` pinned vertices."""
    if not mask.any():
        return mask
    label, sizes = masked_components(edges, len(mask), mask)
    keep = sizes >= min_share * len(mask)
    if pinned is not None:
        keep &= np.bincount(label[mask & pinned], minlength=len(sizes)) >= min_pinned
    # Vertices outside ``mask`` (label -1) are dropped by the ``&`` whatever they read.
    return mask & keep[label]
