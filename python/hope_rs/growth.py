"""Growing the trusted part of a map over shapes that share most of their triangulation.

The last step of the shared-face finish (:mod:`hope_rs.shared_faces`). It keeps only the part
of the map it can trust and rebuilds the rest outward from it, vertex by vertex:

- **Seeds**: handles (vertices whose faces all map onto faces of B) in connected patches of at
  least :data:`SEED_SHARE` of A's vertices. On the TOSCA cat every wrong handle lay in a patch
  of at most 1% of the vertices (a region that HOPE shifted as a whole by a few edges), and
  every patch above 2% was at least 95% right.
- **Across shared faces**: a face of A with two mapped vertices names the image of its third
  vertex, if the two triangles have nearly the same shape (see ``_core.grow_across_faces``).
- **By local affine fits**: where the triangulations differ (TOSCA's cat6 is retriangulated
  on 22% of the cat, where the pose stretches its edges by a median 33%), each unmapped
  vertex with enough mapped vertices in its 2-ring gets the affine map that best carries those
  onto their images; the B vertex nearest its predicted position is taken if it is clearly the
  nearest free one (:data:`AFFINE_STAGES`).

Vertices never reached keep their image. On the cat, after the finish's rounds, 72.1% -> 89.0%
exact (cat0 -> cat6) and 74.7% -> 87.6% (cat6 -> cat0), in 1.1 s.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from . import _core
from .shape import Shape

#: Handle patches with fewer of A's vertices than this share do not seed the growth.
SEED_SHARE = 0.02
#: Largest triangle shape difference for growing across a face (in edge lengths; see
#: ``_core.grow_across_faces``). Measured on the cat's true map: a face both meshes share
#: differs by less than 0.5 in 94% of cases, a retriangulated one in 18%.
FACE_ERROR = 0.5
#: Acceptance tests of the affine growth, strict first: the nearest free B vertex is taken if
#: its distance to the prediction is below ``accept`` times its distance to its own nearest
#: neighbour, and the second nearest free one is ``ratio`` times farther.
AFFINE_STAGES = ((0.35, 2.0), (0.5, 1.5), (0.7, 1.2))
#: An unmapped vertex is fitted once at least this many vertices of its 2-ring are mapped.
MIN_KNOWN = 6
#: Alternations of growth across faces and affine growth.
ROUNDS = 3


def seed_handles(a: Shape, b: Shape, f: np.ndarray) -> np.ndarray:
    """The handles of ``f`` (see :func:`hope_rs.shared_faces.face_handles`) in connected
    patches of at least :data:`SEED_SHARE` of A's vertices."""
    from .shared_faces import face_handles

    handles = face_handles(a, b, f)
    e = a.edges[handles[a.edges[:, 0]] & handles[a.edges[:, 1]]]
    n = a.n_vertices
    graph = sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    label = connected_components(graph, directed=False)[1]
    size = np.bincount(label, weights=handles)
    return handles & (size[label] >= SEED_SHARE * n)


def grow(a: Shape, b: Shape, f: np.ndarray) -> np.ndarray:
    """The map ``f`` (internal numbering) rebuilt from its seed handles outward; vertices the
    growth does not reach keep their image."""
    g = np.where(seed_handles(a, b, f), np.asarray(f, dtype=np.int64), -1)
    fa, fb = a.internal.faces.astype(np.int64), b.internal.faces.astype(np.int64)
    grower = _AffineGrowth(a, b)
    for _ in range(ROUNDS):
        before = int((g >= 0).sum())
        g = _core.grow_across_faces(fa, a.points, fb, b.points, g, FACE_ERROR)
        for accept, ratio in AFFINE_STAGES:
            g = grower.grow(g, accept, ratio)
        if (g >= 0).sum() == before:
            break
    return np.where(g >= 0, g, f)


class _AffineGrowth:
    """Affine growth between two shapes: A's 2-rings and B's nearest-vertex structure, built
    once for every stage."""

    def __init__(self, a: Shape, b: Shape):
        n = a.n_vertices
        e = a.edges
        adj = sp.csr_matrix(
            (np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
            shape=(n, n),
        ) + sp.eye(n)
        ring = (adj @ adj).tocsr()
        ring.data[:] = 1.0
        self.ring = ring
        self.pa, self.pb = a.points, b.points
        self.tree = cKDTree(self.pb)
        # Each B vertex's distance to its nearest neighbour: the local spacing of B.
        self.spacing = self.tree.query(self.pb, k=2)[0][:, 1]

    def grow(self, g: np.ndarray, accept: float, ratio: float) -> np.ndarray:
        """``g`` with every vertex mapped that passes the stage's tests, repeated until none
        does."""
        g = g.copy()
        used = np.zeros(len(self.pb), dtype=bool)
        used[g[g >= 0]] = True
        while True:
            known = g >= 0
            front = np.flatnonzero(~known & (self.ring @ known.astype(np.float64) >= MIN_KNOWN))
            if len(front) == 0:
                return g
            target, ok = self._nearest_free(self._predict(front, g, known), used, accept, ratio)
            front, target = front[ok], target[ok]
            # A B vertex two vertices both want goes to neither in this pass.
            value, count = np.unique(target, return_counts=True)
            alone = np.isin(target, value[count == 1])
            if not alone.any():
                return g
            g[front[alone]] = target[alone]
            used[target[alone]] = True

    def _predict(self, front: np.ndarray, g: np.ndarray, known: np.ndarray) -> np.ndarray:
        """Where each vertex of ``front`` lands under the affine map fitted (least squares,
        centred on it, slightly damped) to its mapped 2-ring neighbours."""
        sub = self.ring[front].multiply(known[None, :]).tocsr()
        sub.eliminate_zeros()
        lens = np.diff(sub.indptr)
        mask = np.arange(lens.max())[None, :] < lens[:, None]
        idx = np.zeros(mask.shape, dtype=np.int64)
        idx[mask] = sub.indices
        x = self.pa[idx] - self.pa[front][:, None, :]
        x = np.concatenate([x, np.ones(x.shape[:2] + (1,))], axis=-1) * mask[..., None]
        y = self.pb[np.where(mask, g[idx], 0)] * mask[..., None]
        xtx = np.einsum("nki,nkj->nij", x, x)
        xty = np.einsum("nki,nkj->nij", x, y)
        # The neighbours lie on a surface, so the fit is undetermined along its normal; a
        # small damping of the linear part keeps it solvable (the prediction is at the centre,
        # where that direction does not matter).
        damp = 1e-2 * np.einsum("nii->n", xtx[:, :3, :3])
        xtx[:, :3, :3] += damp[:, None, None] * np.eye(3)
        xtx += 1e-12 * np.eye(4)
        return np.linalg.solve(xtx, xty)[:, 3, :]

    def _nearest_free(
        self, y: np.ndarray, used: np.ndarray, accept: float, ratio: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """The nearest free B vertex to each predicted point among its 8 nearest, and whether
        it passes the stage's tests."""
        d, j = self.tree.query(y, k=min(8, len(self.pb)))
        free = ~used[j]
        rows = np.arange(len(y))
        first = np.argmax(free, axis=1)
        d1, target = d[rows, first], j[rows, first]
        free[rows, first] = False
        second = np.argmax(free, axis=1)
        d2 = np.where(free.any(axis=1), d[rows, second], np.inf)
        ok = ~used[target] & (d1 < accept * self.spacing[target]) & (d2 > ratio * d1)
        return target, ok
