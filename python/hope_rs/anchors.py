"""A global step for HOPE: re-place untrusted vertices by their geodesic distances to witnesses.

HOPE's k-hop steps move a vertex only as far as the witnesses in its k-ball reach, so a region
whose initial matches are all wrong (a limb mapped to the wrong side) is won back a few hops per
pass. Geodesic distance to a spread of trusted correspondences ("anchors") is an intrinsic
coordinate both shapes share, whatever their triangulations: matching untrusted vertices by
these coordinates repairs such regions in one step, and the k-hop steps then sharpen the result.
The same coordinates also expose what LMD cannot see: a region mapped consistently onto its
mirror image keeps its 2-rings but not its distances to the rest of the shape (``global_check``).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ._blas import single_threaded_blas
from .shape import Shape

#: Anchors per global step: farthest-point samples among the witnesses.
N_ANCHORS = 32
#: The anchor coordinates are reduced to this many principal axes before the neighbour search
#: (geodesic distance fields are smooth, so a few axes keep nearly all their variance).
SEARCH_DIMS = 12
#: Geodesic distances agree within this share of their length plus :data:`AGREE_ABS`.
AGREE_REL = 0.1
AGREE_ABS = 0.03
#: A trusted vertex must agree with at least this share of the consistent anchors.
GLOBAL_MIN_AGREE = 0.7
#: ... and the check acts only when it flags at least this share of the trusted vertices.
GLOBAL_MIN_FLAGGED = 0.1


def distance_fields(shape: Shape, sources) -> np.ndarray:
    """Edge-graph distances / sqrt(area) from each source to every vertex, (len(sources), n)."""
    src = np.atleast_1d(np.asarray(sources, dtype=np.int64))
    return shape.graph.distance_fields(src) / shape.scale


def farthest_witnesses(a: Shape, candidates: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` farthest-point samples of ``candidates`` on A and their distance fields (n, n_a)."""
    # Start at the candidate nearest the centroid: a choice that does not depend on vertex
    # numbering, so relabelling the meshes relabels the result.
    v = a.points[candidates]
    chosen = [int(candidates[np.argmin(((v - v.mean(axis=0)) ** 2).sum(axis=1))])]
    fields = [distance_fields(a, chosen[0])[0]]
    nearest = fields[0].copy()
    for _ in range(1, min(n, candidates.size)):
        d = nearest[candidates]
        d[~np.isfinite(d)] = -1.0  # other components: never anchors of this one
        nxt = int(candidates[int(np.argmax(d))])
        if nearest[nxt] <= 0:
            break
        chosen.append(nxt)
        fields.append(distance_fields(a, nxt)[0])
        nearest = np.minimum(nearest, fields[-1])
    return np.array(chosen), np.vstack(fields)


def agree(da: np.ndarray, db: np.ndarray) -> np.ndarray:
    """Whether geodesic distances on A and their counterparts on B agree (sqrt(area) units):
    within :data:`AGREE_REL` of the distance plus :data:`AGREE_ABS`, since poses of one body
    stretch geodesics by a few percent."""
    return np.abs(da - db) < AGREE_REL * da + AGREE_ABS


def anchor_step(
    a: Shape, b: Shape, f: np.ndarray, trusted: np.ndarray, *, global_check: bool = False
) -> np.ndarray:
    """``f`` with every untrusted vertex moved to the vertex of B whose geodesic distances to
    the anchors' images are closest to its own distances to the anchors.

    Anchors are :data:`N_ANCHORS` farthest-point samples among the trusted vertices; distances
    are Dijkstra distances on the edge graphs (searched in parallel in Rust) divided by
    sqrt(area). With fewer than four trusted vertices ``f`` is returned unchanged.

    With ``global_check``, trust must also hold at the scale of the whole shape. LMD looks at
    2-rings only, so a region mapped consistently onto its mirror image (a left arm onto the
    right arm) passes it everywhere. Its distances to the rest of the shape do not survive the
    map, though: anchors whose distances to most other anchors disagree are dropped, and a
    vertex stays trusted only when its distances to at least :data:`GLOBAL_MIN_AGREE` of the
    remaining anchors agree. The check acts only when it flags at least
    :data:`GLOBAL_MIN_FLAGGED` of the trusted vertices (a region, not scattered stretch).
    """
    cand = np.flatnonzero(trusted)
    if cand.size < 4 or (cand.size == trusted.size and not global_check):
        return f
    anchors, da = farthest_witnesses(a, cand, N_ANCHORS)
    db = distance_fields(b, f[anchors])
    # Unreachable (other components) counts as far, not infinitely far.
    big = 4.0
    da = np.where(np.isfinite(da), da, big)
    db = np.where(np.isfinite(db), db, big)
    if global_check:
        good = agree(da[:, anchors], db[:, f[anchors]]).mean(axis=1) >= 0.5
        if good.sum() >= 4:
            anchors, da, db = anchors[good], da[good], db[good]
        flagged = trusted & (agree(da, db[:, f]).mean(axis=0) < GLOBAL_MIN_AGREE)
        if flagged.sum() >= GLOBAL_MIN_FLAGGED * trusted.sum():
            trusted = trusted & ~flagged
        if trusted.all():
            return f
    da, db = da.T, db.T
    mu = db.mean(axis=0)
    centred = db - mu
    with single_threaded_blas():
        _, vecs = np.linalg.eigh(centred.T @ centred)
    basis = vecs[:, ::-1][:, :SEARCH_DIMS]
    tree = cKDTree(centred @ basis)
    moved = np.flatnonzero(~trusted)
    _, q = tree.query((da[moved] - mu) @ basis, workers=2)
    g = f.copy()
    g[moved] = q
    return g
