"""A numbering of a mesh's vertices and faces fixed by its geometry alone.

Every stage of HOPE breaks ties by index somewhere: which of equal overlap counts a cost row
keeps, the order in which the auction's bidders go, which vertex the initial map prefers among
equal descriptor distances. Run in the numbering of the files, the result then depends on how
the files happen to number their vertices (docs/decisions.md#numbering). Even SHOT and WKS
change in their last bits (and SHOT, where a local frame is nearly degenerate, by more).
:class:`~hope_rs.Shape` therefore renumbers each mesh by position (:func:`canonical_order`),
and every kernel and descriptor works in that numbering; :func:`hope_rs.match` translates maps
in and out. Relabelling the vertices or faces of the input then relabels the output and changes
nothing else.

The order is a Morton (Z-order) curve through the bounding box, so vertices near each other on
the surface are mostly near each other in memory: the k-hop balls, the overlap counts and the
auction's price reads stay local: a random numbering makes the refinement's steps slower,
while the Morton order runs them about as fast as the files' own order, which numbers
vertices along the surface (docs/decisions.md#numbering).
"""

from __future__ import annotations

import numpy as np

from .mesh import Mesh, scale_exponent, unique_rows
from .orientation import orient_faces

#: Bits per axis of the Morton code (3 x 21 = 63 bits in one uint64).
MORTON_BITS = 21


def _spread_bits(x: np.ndarray) -> np.ndarray:
    """The low 21 bits of each value moved to every third bit position."""
    x = x.astype(np.uint64) & np.uint64(0x1FFFFF)
    for shift, mask in (
        (32, 0x1F00000000FFFF),
        (16, 0x1F0000FF0000FF),
        (8, 0x100F00F00F00F00F),
        (4, 0x10C30C30C30C30C3),
        (2, 0x1249249249249249),
    ):
        x = (x | (x << np.uint64(shift))) & np.uint64(mask)
    return x


def morton_codes(vertices: np.ndarray) -> np.ndarray:
    """Z-order code of each vertex over the bounding box (its longest side spans the grid)."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.shape[0] == 0:
        return np.zeros(0, dtype=np.uint64)
    lo = v.min(axis=0)
    span = float((v.max(axis=0) - lo).max())
    top = (1 << MORTON_BITS) - 1
    if not span > 0:
        return np.zeros(v.shape[0], dtype=np.uint64)
    q = np.clip(np.floor((v - lo) / span * top), 0, top).astype(np.uint64)
    one, two = np.uint64(1), np.uint64(2)
    return _spread_bits(q[:, 0]) | (_spread_bits(q[:, 1]) << one) | (_spread_bits(q[:, 2]) << two)


def canonical_order(vertices: np.ndarray) -> np.ndarray:
    """Vertex ids sorted by Morton code, then by exact coordinates: ``order[i]`` is the vertex
    that gets number ``i``. Only vertices at exactly the same position keep their relative
    input order (they are interchangeable to every kernel except through their faces)."""
    v = np.asarray(vertices, dtype=np.float64)
    n = v.shape[0]
    return np.lexsort((np.arange(n), v[:, 2], v[:, 1], v[:, 0], morton_codes(v)))


def inverse_permutation(order: np.ndarray) -> np.ndarray:
    """``rank`` with ``rank[order[i]] == i``."""
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size, dtype=order.dtype)
    return rank


def canonical_faces(faces: np.ndarray, rank: np.ndarray) -> np.ndarray:
    """``faces`` in the new vertex numbering ``rank``, each rotated to start at its smallest
    vertex (a rotation keeps the orientation) and sorted, so that the result depends on the set
    of faces only, not on their order in the file."""
    f = rank[np.asarray(faces, dtype=np.int64)]
    if f.shape[0] == 0:
        return f.reshape(0, 3)
    start = np.argmin(f, axis=1)
    f = np.take_along_axis(f, (start[:, None] + np.arange(3)) % 3, axis=1)
    return f[np.lexsort((f[:, 2], f[:, 1], f[:, 0]))]


def _without_repeated_faces(f: np.ndarray) -> np.ndarray:
    """Canonical faces (:func:`canonical_faces`) with each set of three vertices once: a face
    listed again, with either winding (a double-sided export lists every face twice), adds
    no surface, and would double the area and cancel the normals. The first in the sorted
    order stays, so the result depends on the set of faces only."""
    if f.shape[0] < 2:
        return f
    lo, hi = np.minimum(f[:, 1], f[:, 2]), np.maximum(f[:, 1], f[:, 2])
    _, first = unique_rows(np.column_stack([f[:, 0], lo, hi]), return_index=True)
    if first.size == f.shape[0]:
        return f
    return f[np.sort(first)]


def canonical_mesh(mesh: Mesh, *, orient: bool = True) -> tuple[Mesh, np.ndarray, np.ndarray]:
    """``mesh`` renumbered by position: (the renumbered mesh, ``order``, ``rank``), where
    internal vertex ``i`` is ``mesh``'s vertex ``order[i]`` and ``rank`` is the inverse.

    The renumbered mesh is also scaled by ``4**scale_exponent(mesh.vertices)`` (exact; a no-op
    for meshes of ordinary size, see :func:`hope_rs.geometry.mesh.scale_exponent`) and its faces are
    oriented consistently and outward (:func:`hope_rs.geometry.orientation.orient_faces`; ``orient=False``
    keeps them as given, for meshes derived from an oriented one), so that neither the size of
    the coordinates nor the winding of the input's faces changes a result. A face listed
    more than once (either winding) is kept once.
    """
    k = scale_exponent(mesh.vertices)
    v = np.ldexp(mesh.vertices, 2 * k) if k else mesh.vertices
    order = canonical_order(v)
    rank = inverse_permutation(order)
    v = v[order]
    f = _without_repeated_faces(canonical_faces(mesh.faces, rank))
    flip = orient_faces(v, f) if orient else np.zeros(f.shape[0], dtype=bool)
    if flip.any():
        f = f.copy()
        f[flip] = f[flip][:, [0, 2, 1]]  # keeps the smallest vertex first
        f = f[np.lexsort((f[:, 2], f[:, 1], f[:, 0]))]
    return Mesh(v, f), order, rank
