"""Map utilities: one-to-one completions of a map and the pairing of duplicates with free vertices."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .. import _core

__all__ = ["hint_rows", "injective_completion", "nearest_unused"]


def hint_rows(keep: np.ndarray) -> np.ndarray:
    """``keep`` with every repeat of a column set to -1: a one-to-one partial assignment that
    covers all n_b columns when A has more vertices than B."""
    _, first = np.unique(keep, return_index=True)
    hint = np.full_like(keep, -1)
    hint[first] = keep[first]
    return hint


def injective_completion(
    f: np.ndarray, n_b: int, points: np.ndarray | None = None, *, k: int = 16
) -> np.ndarray:
    """A map as close to ``f`` as possible that is one-to-one on min(n_a, n_b) vertices: the
    first vertex mapped to each column keeps it, later duplicates take unused columns.

    With ``points`` (B's vertex positions) each duplicate takes the unused column nearest to its
    current image, closest pairs first. Without them the duplicates take the unused columns in
    index order, which ties the result to how the two meshes happen to be numbered: on a pair
    numbered alike (TOSCA cat0 → cat6, whose ground truth is the identity) the k-th duplicate
    then lands near its true match, which leaks the ground truth into the cost
    (docs/decisions.md#numbering). Only the refinement's cost needs this, so ``points`` is
    optional for other callers. ``k``: see :func:`nearest_unused`.
    """
    f = np.asarray(f, dtype=np.int64)
    _, first = np.unique(f, return_index=True)
    dup = np.ones(f.size, dtype=bool)
    dup[first] = False
    dup_rows = np.flatnonzero(dup)
    used = np.zeros(n_b, dtype=bool)
    used[f] = True
    free = np.flatnonzero(~used)
    g = f.copy()
    if points is None:
        m = min(dup_rows.size, free.size)
        g[dup_rows[:m]] = free[:m]
        return g
    if dup_rows.size and free.size:
        rows, cols = nearest_unused(f[dup_rows], free, points, k)
        g[dup_rows[rows]] = cols
    return g


def nearest_unused(
    images: np.ndarray, free: np.ndarray, points: np.ndarray, k: int = 16
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs duplicates, given by their images (vertices of B), with the unused vertices
    ``free``, closest pairs first (Euclidean, over ``points``): min(len(images), len(free))
    pairs, as (indices into ``images``, vertices of ``free``).

    Duplicates that share an image are one group with that many places to fill: each round
    ranks every group's ``2 * places + k`` nearest unused vertices by distance and keeps pairs in
    that order while the vertex is unused and the group has places left
    (``_core.greedy_pairs``); groups left short try again with the vertices still unused.
    """
    n_pairs = min(images.size, free.size)
    image, group, places = np.unique(images, return_inverse=True, return_counts=True)
    members = np.argsort(group, kind="stable")  # positions in `images`, grouped by image
    first = np.concatenate([[0], np.cumsum(places)[:-1]])
    left = places.copy()  # places still to fill per group
    unused = free
    out_rows, out_cols, paired = [], [], 0
    while paired < n_pairs:
        tree = cKDTree(points[unused])
        live = np.flatnonzero(left > 0)
        # Query sizes rounded up to powers of two, so that one query serves many groups.
        want = 2 ** np.ceil(np.log2(2 * left[live] + k)).astype(np.int64)
        want = np.minimum(unused.size, want)
        cand = []  # (distance, group, position in `unused`) per query size
        for kk in np.unique(want):
            g = live[want == kk]
            d, j = tree.query(points[image[g]], k=int(kk))
            d, j = d.reshape(g.size, -1), j.reshape(g.size, -1)
            cand.append((d.ravel(), np.repeat(g, d.shape[1]), j.ravel()))
        d, g, j = (np.concatenate(x) for x in zip(*cand))
        order = np.argsort(d, kind="stable")
        r, c = _core.greedy_pairs(g[order], j[order], left, unused.size)
        if r.size == 0:  # cannot happen (the closest candidate pair is always free): no hang
            break
        # The r-th pair of a group fills its next place, in the order the pairs were kept.
        by_group = np.argsort(r, kind="stable")
        r, c = r[by_group], c[by_group]
        start = np.searchsorted(r, r)  # first kept pair of each pair's group
        rank = np.arange(r.size) - start
        out_rows.append(members[first[r] + (places[r] - left[r]) + rank])
        out_cols.append(unused[c])
        left -= np.bincount(r, minlength=left.size)
        paired += r.size
        still = np.ones(unused.size, dtype=bool)
        still[c] = False
        unused = unused[still]
    if not out_rows:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate(out_rows), np.concatenate(out_cols)
