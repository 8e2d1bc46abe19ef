"""Consistent, outward face orientation, decided by the geometry alone.

A mesh whose faces all wind the other way is the mirror image of itself to SHOT's right-handed
local frames, so it would be matched left to right. :class:`~hope_rs.Shape` therefore orients
the faces of its internal mesh (:func:`hope_rs.geometry.numbering.canonical_mesh`) with
:func:`orient_faces`; the user's :class:`~hope_rs.Mesh` keeps its arrays as given.

The rule, per connected component (faces linked through edges that exactly two faces share):

1. Consistency: two faces across such an edge must run it in opposite directions. The faces of
   an orientable component are flipped to agree with one another.
2. Outward: of the two consistent orientations, the one whose signed volume seen from the
   component's area-weighted centroid, ``sum det(p0 - c, p1 - c, p2 - c) / 6``, is positive.
   For a closed component this is its enclosed volume (normals point out); for an open one it is
   the volume of the cone from ``c`` over the surface, i.e. normals point away from the centroid
   on average (the convex side of a partial scan).
3. Ties (a flat patch, where that volume is below ``1e-12 * area**1.5``): the orientation whose
   area vector has its largest component (by magnitude) positive; if the area vector is zero
   too, the one in which the component's first face (in sorted vertex order) has its vertices
   in ascending cyclic order.

Edges shared by three or more faces (non-manifold), degenerate faces (a repeated vertex) and
duplicate faces link nothing, so a component ends there. A non-orientable component (a Möbius
strip) is oriented along a breadth-first spanning tree from its first face, which leaves one
seam of inconsistent edges, then rule 2 is applied to it as to any other.

Every step reads the faces in the order of their sorted vertex triples, and the volumes and
area vectors are summed in that order with each face's sign applied last, so reversing any
subset of the input's faces gives the same output bit for bit.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

__all__ = ["face_keys", "manifold_pairs", "orient_faces"]

#: A component whose centroid volume is below this times ``area ** 1.5`` counts as flat.
FLAT_VOLUME = 1e-12


def orient_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Which faces to flip for a consistent, outward orientation (see the module notes).

    Parameters
    ----------
    vertices : (N, 3) float array
    faces : (M, 3) int array

    Returns
    -------
    flip : (M,) bool
        ``True`` for the faces whose orientation (cyclic vertex order) must be reversed.
    """
    p = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    m = f.shape[0]
    if m == 0:
        return np.zeros(0, dtype=bool)
    srt = np.sort(f, axis=1)
    # Work in the order of the sorted vertex triples: independent of face order and winding.
    by_key = np.argsort(face_keys(srt, int(srt[:, 2].max()) + 1), kind="stable")
    f, srt = f[by_key], srt[by_key]
    # +1 if the face runs its vertices in the ascending cyclic order, -1 otherwise.
    sign = np.where(_is_ascending_cycle(f), 1.0, -1.0)
    usable = (srt[:, 0] != srt[:, 1]) & (srt[:, 1] != srt[:, 2])
    # Exact duplicates (same vertex set) link nothing either.
    dup = np.zeros(m, dtype=bool)
    same = np.all(srt[1:] == srt[:-1], axis=1)
    dup[1:] |= same
    dup[:-1] |= same
    usable &= ~dup
    rows, cols, parity = manifold_pairs(f, usable)
    comp, relative = _relative_orientation(m, rows, cols, parity)
    orient = sign * np.where(relative, -1.0, 1.0)  # the sign each face would end with
    outward = _outward_sign(p, srt, orient, comp)
    flip_sorted = relative ^ (outward[comp] < 0)
    flip = np.empty(m, dtype=bool)
    flip[by_key] = flip_sorted
    return flip


def face_keys(faces: np.ndarray, n: int) -> np.ndarray:
    """One integer per oriented face, the same for its three rotations."""
    # Rotate each face so that its smallest index comes first, which keeps the orientation.
    first = np.argmin(faces, axis=1)
    rows = np.arange(len(faces))[:, None]
    rot = faces[rows, (first[:, None] + np.arange(3)) % 3]
    n = np.int64(n)
    if n > 2_000_000:  # n**3 would overflow int64; fall back to a structured key
        return (
            np.ascontiguousarray(rot)
            .view([("a", np.int64), ("b", np.int64), ("c", np.int64)])
            .ravel()
        )
    return (rot[:, 0] * n + rot[:, 1]) * n + rot[:, 2]


def _is_ascending_cycle(f: np.ndarray) -> np.ndarray:
    """Whether each face (a, b, c) is a rotation of its sorted triple (low, mid, high)."""
    a, b, c = f[:, 0], f[:, 1], f[:, 2]
    return ((a < b) & (b < c)) | ((b < c) & (c < a)) | ((c < a) & (a < b))


def manifold_pairs(f: np.ndarray, usable: np.ndarray):
    """Pairs of usable faces sharing an edge that exactly two faces (all faces counted) use,
    with ``parity`` True when both run it the same way (one of them must flip)."""
    m = f.shape[0]
    u = f.reshape(-1)
    w = f[:, [1, 2, 0]].reshape(-1)
    face = np.repeat(np.arange(m), 3)
    lo, hi = np.minimum(u, w), np.maximum(u, w)
    forward = u < w
    keep = lo != hi
    lo, hi, forward, face = lo[keep], hi[keep], forward[keep], face[keep]
    # One int64 key per undirected edge; the stable sort keeps faces ascending within an edge.
    order = np.argsort(lo * (int(hi.max(initial=0)) + 1) + hi, kind="stable")
    lo, hi, forward, face = lo[order], hi[order], forward[order], face[order]
    new = np.ones(lo.size, dtype=bool)
    new[1:] = (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])
    start = np.flatnonzero(new)
    count = np.diff(np.append(start, lo.size))
    two = start[count == 2]
    a, b = face[two], face[two + 1]
    ok = usable[a] & usable[b] & (a != b)
    a, b = a[ok], b[ok]
    parity = forward[two][ok] == forward[two + 1][ok]
    return a, b, parity


def _relative_orientation(m: int, a: np.ndarray, b: np.ndarray, parity: np.ndarray):
    """Component of each face and whether it flips relative to its component's first face."""
    base = sp.coo_matrix((np.ones(a.size), (a, b)), shape=(m, m)).tocsr()
    n_comp, comp = connected_components(base, directed=False)
    # Double cover: node f is face f as given, node f + m face f flipped. An orientable
    # component splits into two sheets; a non-orientable one stays connected.
    same = ~parity
    r = np.concatenate([np.where(same, a, a), np.where(same, a + m, a + m)])
    c = np.concatenate([np.where(same, b, b + m), np.where(same, b + m, b)])
    cover = sp.coo_matrix((np.ones(r.size), (r, c)), shape=(2 * m, 2 * m)).tocsr()
    _, sheet = connected_components(cover, directed=False)
    first = np.full(n_comp, m, dtype=np.int64)
    np.minimum.at(first, comp, np.arange(m))
    root = first[comp]
    relative = sheet[:m] != sheet[root]
    bad = np.flatnonzero(sheet[first] == sheet[first + m])
    if bad.size:
        weights = sp.coo_matrix((np.where(parity, 2.0, 1.0), (a, b)), shape=(m, m)).tocsr()
        weights = weights.maximum(weights.T)
        for k in bad:
            relative[comp == k] = False
            _tree_orientation(weights, int(first[k]), relative)
    return comp, relative


def _tree_orientation(weights, root: int, relative: np.ndarray) -> None:
    """Orient a non-orientable component along its breadth-first tree from ``root``."""
    order, pred = breadth_first_order(weights, root, directed=False, return_predecessors=True)
    nodes = order[1:]
    flips = np.asarray(weights[nodes, pred[nodes]]).ravel() == 2.0
    rel = relative.tolist()
    for node, parent, fl in zip(nodes.tolist(), pred[nodes].tolist(), flips.tolist()):
        rel[node] = rel[parent] ^ fl
    relative[order] = np.asarray(rel, dtype=bool)[order]


def _outward_sign(p: np.ndarray, srt: np.ndarray, orient: np.ndarray, comp: np.ndarray):
    """Per component: +1 if the faces with signs ``orient`` point outward, else -1."""
    n_comp = int(comp.max()) + 1
    q0, q1, q2 = p[srt[:, 0]], p[srt[:, 1]], p[srt[:, 2]]
    normal = _cross(q1 - q0, q2 - q0)  # of the ascending cycle; orientation-free
    area = 0.5 * np.linalg.norm(normal, axis=1)
    total = np.bincount(comp, weights=area, minlength=n_comp)
    centre = (q0 + q1 + q2) / 3.0
    c = (
        np.stack(
            [np.bincount(comp, weights=area * centre[:, j], minlength=n_comp) for j in range(3)],
            axis=1,
        )
        / np.where(total > 0, total, 1.0)[:, None]
    )
    cf = c[comp]
    det = np.einsum("ij,ij->i", q0 - cf, _cross(q1 - cf, q2 - cf))
    vol = np.bincount(comp, weights=orient * det, minlength=n_comp) / 6.0
    vec = np.stack(
        [np.bincount(comp, weights=orient * normal[:, j], minlength=n_comp) for j in range(3)],
        axis=1,
    )
    out = np.sign(vol)
    flat = np.abs(vol) <= FLAT_VOLUME * total**1.5
    axis = np.argmax(np.abs(vec), axis=1)
    by_vec = np.sign(vec[np.arange(n_comp), axis])
    out = np.where(flat, by_vec, out)
    # Nothing decides: keep the first face in ascending cyclic order.
    first = np.full(n_comp, srt.shape[0], dtype=np.int64)
    np.minimum.at(first, comp, np.arange(srt.shape[0]))
    return np.where(out == 0, orient[first], out)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product (``np.cross`` without its axis handling)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out
