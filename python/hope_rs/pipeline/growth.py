"""Growing the trusted part of a map over shapes that share most of their triangulation.

The last step of the shared-face finish (:mod:`hope_rs.pipeline.shared_faces`). It keeps only the part
of the map it can trust and rebuilds the rest outward from it, vertex by vertex:

- **Seeds**: handles (vertices whose faces all map onto faces of B) in connected patches of at
  least ``GrowthConfig.seed_share`` of A's vertices that hold an irregular handle
  (``GrowthConfig.seed_irregular``): wrong handles lie in small patches (a region that HOPE
  shifted as a whole by a few edges) or, on a regular lattice such as a subdivided mesh, in
  patches without an irregular vertex (a shift by whole edges keeps faces there). Patches
  must also agree with one another (:func:`agreeing_patches`): on a lattice whose every vertex
  is irregular (alternating diagonals) several patches may each be shifted differently.
- **Across shared faces**: a face of A with two mapped vertices names the image of its third
  vertex, if the two triangles have nearly the same shape (see ``_core.grow_across_faces``).
- **By local affine fits**: where the triangulations differ (retriangulated regions, often
  where the pose stretches the edges most), each unmapped vertex with enough mapped vertices
  in its 2-ring gets the affine map that best carries those onto their images; the B vertex
  nearest its predicted position is taken if it is clearly the nearest free one
  (``GrowthConfig.affine_stages``).
- **From both sides**: the same growth from B to A, and rounds that keep what the two agree on
  (see :func:`grow`).

Vertices never reached keep their image. See docs/decisions.md#growth for the measurements.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .. import _core
from ..kernels.khop import khop_neighbourhoods
from ..shape import Shape
from .anchors import firm_regions
from .config import GrowthConfig
from .handles import seed_handles


def grow(a: Shape, b: Shape, f: np.ndarray, config: GrowthConfig = GrowthConfig()) -> np.ndarray:
    """The map ``f`` (internal numbering) rebuilt from its seed handles outward; vertices the
    growth does not reach keep their image.

    The growth runs from both sides: A -> B from the seeds, and B -> A from their inverse.
    Each first grows faces first, then keeps only its handle patches large enough to seed,
    less their edge vertices (the retriangulated regions go, and wrong picks at their edges),
    and grows again affine first. Then, ``config.agreement_rounds`` times, both keep only what
    they agree on and grow again from it. See docs/decisions.md#growth for what each step
    added.
    """
    f = np.asarray(f, dtype=np.int64)
    n_a, n_b = a.n_vertices, b.n_vertices
    cfg = config
    ab, ba = _Growth(a, b, cfg), _Growth(b, a, cfg)
    seeds = seed_handles(a, b, f, cfg.seed_share, cfg.seed_irregular)
    seeds = np.where(agreeing_patches(a, b, f, seeds, cfg.face_error), f, -1)
    g = ab.regrow(ab.grow(seeds, cfg.faces_first))
    h = _inverse(ba.regrow(ba.grow(_inverse(seeds, n_b), cfg.faces_first)), n_a)
    for _ in range(cfg.agreement_rounds):
        agreed = np.where(g == h, g, -1)
        g = ab.grow(agreed, cfg.agreement_order)
        h = _inverse(ba.grow(_inverse(agreed, n_b), cfg.agreement_order), n_a)
    return np.where(g >= 0, g, f)


def agreeing_patches(
    a: Shape, b: Shape, f: np.ndarray, seeds: np.ndarray, face_error: float
) -> np.ndarray:
    """``seeds`` (bool per vertex of A) less the connected patches that disagree with the
    larger ones: largest first, a patch is kept unless the map grown across faces from the
    patches kept so far reaches it and gives most of the vertices it reaches another image
    (two patches of one right map agree wherever the growth reaches, being one map)."""
    label, sizes = firm_regions(a, seeds)
    fa, fb = a.internal.faces.astype(np.int64), b.internal.faces.astype(np.int64)
    keep = np.zeros_like(seeds)
    grown = np.full(a.n_vertices, -1, dtype=np.int64)
    for p in np.argsort(-sizes, kind="stable"):
        part = label == p
        if not part.any():
            continue
        reached = part & (grown >= 0)
        if reached.any() and np.mean(grown[reached] == f[reached]) < 0.5:
            continue
        keep |= part
        grown = np.where(keep, f, -1)
        grown = _core.grow_across_faces(fa, a.points, fb, b.points, grown, face_error)
    return keep


def _inverse(g: np.ndarray, n: int) -> np.ndarray:
    """The inverse of the one-to-one partial map ``g`` (-1 where unknown), with ``n`` entries."""
    out = np.full(n, -1, dtype=np.int64)
    known = g >= 0
    out[g[known]] = np.flatnonzero(known)
    return out


class _Growth:
    """Growth of partial maps from shape A to shape B (-1 where unknown)."""

    def __init__(self, a: Shape, b: Shape, config: GrowthConfig):
        self.a, self.b, self.config = a, b, config
        self.fa = a.internal.faces.astype(np.int64)
        self.fb = b.internal.faces.astype(np.int64)
        self.affine = _AffineGrowth(a, b, config)

    def grow(self, g: np.ndarray, order: tuple) -> np.ndarray:
        """``g`` grown in rounds of the steps in ``order`` (see ``GrowthConfig.faces_first``)."""
        a, b, cfg = self.a, self.b, self.config
        for _ in range(cfg.rounds):
            before = int((g >= 0).sum())
            for step in order:
                if step == "faces":
                    fa, fb = self.fa, self.fb
                    g = _core.grow_across_faces(fa, a.points, fb, b.points, g, cfg.face_error)
                else:
                    g = self.affine.grow(g, *cfg.affine_stages[step])
            if (g >= 0).sum() == before:
                break
        return g

    def regrow(self, g: np.ndarray) -> np.ndarray:
        """``g`` cleared but for the handle patches that could seed it (see
        :func:`~hope_rs.pipeline.handles.seed_handles`), less their edge vertices, and grown again
        affine first."""
        # Small handle patches go too: a region grown through a narrow neck one vertex off
        # is face-consistent in places, and those places would seed the same error again.
        clear = ~seed_handles(self.a, self.b, g, self.config.seed_share, self.config.seed_irregular)
        e = self.a.edges
        near = clear.copy()
        near[e[:, 0][clear[e[:, 1]]]] = True
        near[e[:, 1][clear[e[:, 0]]]] = True
        return self.grow(np.where(near, -1, g), self.config.affine_first)


class _AffineGrowth:
    """Affine growth between two shapes: A's 2-rings and B's nearest-vertex structure, built
    once for every stage."""

    def __init__(self, a: Shape, b: Shape, config: GrowthConfig):
        self.config = config
        # Closed 2-rings (the vertex included), as 0/1 floats for the counts below.
        ring = khop_neighbourhoods(a.internal.faces, 2, n_vertices=a.n_vertices)
        self.ring = ring.astype(np.float64)
        self.pa, self.pb = a.points, b.points
        self.tree = cKDTree(self.pb)
        # Each B vertex's distance to its nearest neighbour: the local spacing of B.
        self.spacing = self.tree.query(self.pb, k=2)[0][:, 1]

    def grow(self, g: np.ndarray, accept: float, ratio: float) -> np.ndarray:
        """``g`` with every vertex mapped that passes the stage's tests, repeated until none
        does."""
        g = g.copy()
        n = len(g)
        used = np.zeros(len(self.pb), dtype=bool)
        used[g[g >= 0]] = True
        k = min(8, len(self.pb))
        # Mapped vertices only ever join, so a vertex whose 2-ring count of them is unchanged
        # has the same fit and the same nearest B vertices as before: only the test, which
        # depends on which of those are used, is redone.
        fitted_with = np.full(n, -1.0)
        dist = np.zeros((n, k))
        near = np.zeros((n, k), dtype=np.int64)
        known = g >= 0
        count = self.ring @ known.astype(np.float64)
        while True:
            front = np.flatnonzero(~known & (count >= self.config.min_known))
            if len(front) == 0:
                return g
            stale = front[count[front] != fitted_with[front]]
            if len(stale):
                d, j = self.tree.query(self._predict(stale, g, known), k=k)
                dist[stale], near[stale] = d.reshape(len(stale), k), j.reshape(len(stale), k)
                fitted_with[stale] = count[stale]
            target, ok = self._nearest_free(dist[front], near[front], used, accept, ratio)
            front, target = front[ok], target[ok]
            # A B vertex two vertices both want goes to neither in this pass.
            value, times = np.unique(target, return_counts=True)
            alone = np.isin(target, value[times == 1])
            if not alone.any():
                return g
            new = front[alone]
            g[new] = target[alone]
            used[target[alone]] = True
            known[new] = True
            count += np.bincount(self.ring[new].indices, minlength=n)

    def _predict(self, front: np.ndarray, g: np.ndarray, known: np.ndarray) -> np.ndarray:
        """Where each vertex of ``front`` lands under the affine map fitted (weighted least
        squares, centred on it, slightly damped) to its mapped 2-ring neighbours."""
        sub = self.ring[front].multiply(known[None, :]).tocsr()
        sub.eliminate_zeros()
        lens = np.diff(sub.indptr)
        mask = np.arange(lens.max())[None, :] < lens[:, None]
        idx = np.zeros(mask.shape, dtype=np.int64)
        idx[mask] = sub.indices
        x = self.pa[idx] - self.pa[front][:, None, :]
        r2 = np.einsum("nki,nki->nk", x, x) * mask
        width = self.config.weight_width * r2.sum(axis=1) / mask.sum(axis=1)
        w = np.exp(-r2 / np.where(width > 0, width, 1.0)[:, None]) * mask
        x = np.concatenate([x, np.ones(x.shape[:2] + (1,))], axis=-1) * mask[..., None]
        y = self.pb[np.where(mask, g[idx], 0)] * mask[..., None]
        xtx = np.einsum("nki,nk,nkj->nij", x, w, x)
        xty = np.einsum("nki,nk,nkj->nij", x, w, y)
        # The neighbours lie on a surface, so the fit is undetermined along its normal; a
        # small damping of the linear part keeps it solvable (the prediction is at the centre,
        # where that direction does not matter).
        damp = 1e-2 * np.einsum("nii->n", xtx[:, :3, :3])
        xtx[:, :3, :3] += damp[:, None, None] * np.eye(3)
        xtx += 1e-12 * np.eye(4)
        return np.linalg.solve(xtx, xty)[:, 3, :]

    def _nearest_free(
        self, d: np.ndarray, j: np.ndarray, used: np.ndarray, accept: float, ratio: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Among each predicted point's nearest B vertices (distances ``d``, indices ``j``),
        the nearest free one, and whether it passes the stage's tests."""
        free = ~used[j]
        rows = np.arange(len(d))
        first = np.argmax(free, axis=1)
        d1, target = d[rows, first], j[rows, first]
        free[rows, first] = False
        second = np.argmax(free, axis=1)
        d2 = np.where(free.any(axis=1), d[rows, second], np.inf)
        ok = ~used[target] & (d1 < accept * self.spacing[target]) & (d2 > ratio * d1)
        return target, ok
