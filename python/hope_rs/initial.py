"""Initial maps from per-vertex descriptors: candidates by descriptor distance, then LAP."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import _core
from ._blas import single_threaded_blas

#: Descriptor-space neighbours kept per vertex as assignment candidates.
N_CANDIDATES = 32
#: Descriptors are projected on this many principal axes before the neighbour search.
PCA_DIMS = 64
#: Above this many target vertices the exact search (quadratic time) gives way to an inverted-file
#: search (about n^1.5), which finds most but not all of the exact candidates
#: (docs/decisions.md#initial-map).
EXACT_SEARCH_LIMIT = 60_000
#: Threads of the exhaustive nearest-neighbour search (one BLAS thread each).
MAX_THREADS = 8


def nearest_candidates(da: np.ndarray, db: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``n`` rows of ``db`` closest to each row of ``da``: (indices, squared distances).

    Exact brute force in chunks (no n_a x n_b matrix), after a shared PCA that keeps most of
    the variance while making the search several times cheaper.
    """
    da = np.asarray(da, dtype=np.float32)
    db = np.asarray(db, dtype=np.float32)
    if da.shape[1] > PCA_DIMS:
        both = np.vstack([da, db])
        mu = both.mean(axis=0)
        sample = both[:: max(1, both.shape[0] // 20000)] - mu
        # Eigenvectors of the small d x d covariance: far cheaper than an SVD of the samples.
        # One cast, then ``x.T @ x`` on a single buffer, which NumPy runs as a symmetric
        # rank-k update (faster than the mixed float64 @ float32 product, same values).
        s64 = sample.astype(np.float64)
        cov = s64.T @ s64
        # One BLAS thread for the projection: a float32 product can give other bits on two
        # threads than on one, so the map would depend on the process's thread count (a Ray
        # worker runs with one).
        with single_threaded_blas():
            _, vecs = np.linalg.eigh(cov)
            basis = vecs[:, ::-1][:, :PCA_DIMS].astype(np.float32)
            da, db = (da - mu) @ basis, (db - mu) @ basis
    n = min(n, db.shape[0])
    if db.shape[0] > EXACT_SEARCH_LIMIT:
        return _inverted_file_candidates(da, db, n)
    nb2 = np.einsum("ij,ij->i", db, db)
    if n == 1:
        return _nearest_one(da, db, nb2)
    idx = np.empty((da.shape[0], n), dtype=np.int64)
    dist = np.empty((da.shape[0], n), dtype=np.float32)
    step = max(1, 2_000_000 // max(db.shape[0], 1))
    for lo in range(0, da.shape[0], step):
        chunk = da[lo : lo + step]
        d2 = nb2[None, :] - 2.0 * chunk @ db.T
        part = np.argpartition(d2, n - 1, axis=1)[:, :n]
        pd = np.take_along_axis(d2, part, axis=1)
        order = np.argsort(pd, axis=1)
        idx[lo : lo + step] = np.take_along_axis(part, order, axis=1)
        dist[lo : lo + step] = (
            np.take_along_axis(pd, order, axis=1) + np.einsum("ij,ij->i", chunk, chunk)[:, None]
        )
    return idx, np.maximum(dist, 0.0)


def _nearest(q: np.ndarray, x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Exact ``n`` nearest rows of ``x`` for each row of ``q`` (both small), sorted."""
    d2 = np.einsum("ij,ij->i", x, x)[None, :] - 2.0 * q @ x.T
    n = min(n, x.shape[0])
    part = (
        np.argpartition(d2, n - 1, axis=1)[:, :n]
        if n < x.shape[0]
        else np.tile(np.arange(x.shape[0]), (q.shape[0], 1))
    )
    pd = np.take_along_axis(d2, part, axis=1)
    order = np.argsort(pd, axis=1)
    dist = np.take_along_axis(pd, order, axis=1) + np.einsum("ij,ij->i", q, q)[:, None]
    return np.take_along_axis(part, order, axis=1), np.maximum(dist, 0.0)


#: Inverted file: cells per sqrt(n_b), and cells searched around each query's own cell.
IVF_CELLS_PER_ROOT = 2
IVF_PROBES = 12


def _inverted_file_candidates(da: np.ndarray, db: np.ndarray, n: int):
    """Approximate ``n`` nearest rows of ``db`` per row of ``da`` for very large meshes.

    ``db`` is split into cells by k-means (on a sample, fixed seed: the result is
    deterministic); the queries of each cell are compared with the members of the
    ``IVF_PROBES`` cells nearest to it, so each query sees about ``IVF_PROBES / cells`` of
    ``db``. Memory stays linear: one block of a cell's queries times its candidates at a time.
    """
    from scipy.cluster.vq import kmeans2

    n_b = db.shape[0]
    n_cells = max(1, int(IVF_CELLS_PER_ROOT * np.sqrt(n_b)))
    rng = np.random.default_rng(0)
    sample = db[rng.choice(n_b, size=min(n_b, 50 * n_cells), replace=False)]
    centroids, _ = kmeans2(sample.astype(np.float64), n_cells, iter=8, minit="points", seed=rng)
    centroids = centroids.astype(np.float32)
    step = max(1, 4_000_000 // n_cells)

    def cell_of(x):
        return np.concatenate(
            [_nearest(x[lo : lo + step], centroids, 1)[0][:, 0] for lo in range(0, len(x), step)]
        )

    cell_b, cell_a = cell_of(db), cell_of(da)
    members = np.split(
        np.argsort(cell_b, kind="stable"), np.cumsum(np.bincount(cell_b, minlength=n_cells))[:-1]
    )
    probes, _ = _nearest(centroids, centroids, IVF_PROBES)
    idx = np.empty((da.shape[0], n), dtype=np.int64)
    dist = np.empty((da.shape[0], n), dtype=np.float32)
    queries = np.split(
        np.argsort(cell_a, kind="stable"), np.cumsum(np.bincount(cell_a, minlength=n_cells))[:-1]
    )
    for c in range(n_cells):
        q = queries[c]
        if q.size == 0:
            continue
        cand = np.concatenate([members[p] for p in probes[c]])
        if cand.size < n:  # tiny cells: widen to the whole set
            cand = np.arange(n_b)
        i, d = _nearest(da[q], db[cand], n)
        idx[q], dist[q] = cand[i], d
    return idx, dist


def _nearest_one(da: np.ndarray, db: np.ndarray, nb2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The single nearest row of ``db`` per row of ``da`` (argmin, no partial sort).

    The rows of ``da`` are split between threads that each run single-threaded BLAS: faster
    than one thread, and OpenBLAS's own threads were no faster while they slowed the small
    products around this call in the spectral pass.
    """
    idx = np.empty((da.shape[0], 1), dtype=np.int64)
    dist = np.empty((da.shape[0], 1), dtype=np.float32)
    step = max(1, 4_000_000 // max(db.shape[0], 1))
    n_threads = max(1, min(os.cpu_count() or 1, MAX_THREADS, -(-da.shape[0] // step)))
    bounds = np.linspace(0, da.shape[0], n_threads + 1).astype(np.int64)
    dbt = db.T

    def search(lo: int, hi: int) -> None:
        # One buffer for every chunk's distances, written in place: a fresh array per chunk
        # and operation had the kernel zero new pages each time (gigabytes over a large search).
        buf = np.empty((min(step, hi - lo), db.shape[0]), dtype=np.float32)
        for s in range(lo, hi, step):
            chunk = da[s : min(s + step, hi)]
            d2 = buf[: chunk.shape[0]]
            np.matmul(2.0 * chunk, dbt, out=d2)
            np.subtract(nb2[None, :], d2, out=d2)
            j = np.argmin(d2, axis=1)
            idx[s : s + j.size, 0] = j
            dist[s : s + j.size, 0] = d2[np.arange(j.size), j] + np.einsum("ij,ij->i", chunk, chunk)

    with single_threaded_blas():
        if n_threads == 1:
            search(0, da.shape[0])
        else:
            with ThreadPoolExecutor(n_threads) as pool:
                list(pool.map(search, bounds[:-1], bounds[1:]))
    return idx, np.maximum(dist, 0.0)


def initial_map(
    da: np.ndarray,
    db: np.ndarray,
    *,
    one_to_one: bool = False,
    n_candidates: int = N_CANDIDATES,
) -> np.ndarray:
    """Map A → B from descriptors: each vertex's nearest descriptor.

    With ``one_to_one``, the assignment of least total descriptor distance among each vertex's
    ``n_candidates`` nearest descriptors instead (vertices it cannot place take their nearest).
    That is not the default: forcing SHOT matches apart made every measured initial map worse
    and cost seconds more (docs/decisions.md#initial-map).
    """
    from .refine import injective_completion

    if not one_to_one:
        return nearest_candidates(da, db, 1)[0][:, 0].copy()
    idx, dist = nearest_candidates(da, db, n_candidates)
    n_a, n_b = da.shape[0], db.shape[0]
    cost = np.sqrt(dist.astype(np.float64))
    # A fallback arc per row (an injective completion of the nearest neighbours, at a price above
    # any candidate) guarantees a full assignment even when candidate sets crowd together.
    extra = injective_completion(idx[:, 0], n_b)
    cols = np.concatenate([idx, extra[:, None]], axis=1)
    vals = np.concatenate([cost, np.full((n_a, 1), 2.0 * cost.max() + 1.0)], axis=1)
    dup = (cols[:, :-1] == extra[:, None]).any(axis=1)
    vals[dup, -1] = np.inf  # already a candidate: drop the fallback copy below
    keep = np.isfinite(vals)
    indptr = np.concatenate([[0], np.cumsum(keep.sum(axis=1))]).astype(np.int64)
    g = _core.auction_assignment_float(
        indptr, cols[keep].astype(np.int32), vals[keep], n_a, n_b, False
    )
    missing = g < 0
    g[missing] = idx[missing, 0]
    return g


def shapes_initial_map(sa, sb, da: np.ndarray, db: np.ndarray, kind: str) -> np.ndarray:
    """:func:`initial_map` between two :class:`~hope_rs.Shape` objects, from their descriptors
    ``da``, ``db`` of ``kind`` in the internal numbering (the map is in it too). Where the
    vertices of a grid cell share one descriptor (SHOT on dense meshes, see
    :mod:`hope_rs.sites`), only the cells' sites are searched and each vertex of A follows
    its site."""
    site_a, site_b = sa.descriptor_sites(kind), sb.descriptor_sites(kind)
    rows_a = site_a[0] if site_a is not None else slice(None)
    rows_b = site_b[0] if site_b is not None else slice(None)
    g = initial_map(da[rows_a], db[rows_b])
    if site_b is not None:
        g = site_b[0][g]
    return g[site_a[1]] if site_a is not None else g
