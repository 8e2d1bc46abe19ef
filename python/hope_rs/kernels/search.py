"""Nearest-neighbour search between descriptor sets: exact in chunks, or by an inverted file.

Used by the initial map (descriptors of A against B's) and by ZoomOut (spectral embeddings).
"""

from __future__ import annotations

import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy.cluster.vq import kmeans2

from .. import _core
from .._blas import single_threaded_blas

__all__ = ["SearchConfig", "nearest_candidates", "nearest_descriptor", "nearest_one"]


@dataclass(frozen=True)
class SearchConfig:
    """Settings of :func:`nearest_candidates` (docs/decisions.md#initial-map).

    Attributes
    ----------
    pca_dims : int
        Descriptors are projected on this many principal axes first.
    exact_search_limit : int
        Above this many target rows the exact search (quadratic time) gives way to an
        inverted-file search (about n^1.5) that finds most but not all exact neighbours.
    max_threads : int
        Threads of the exhaustive search (one BLAS thread each).
    ivf_cells_per_root : int
        Inverted-file cells per sqrt(number of target rows) ...
    ivf_probes : int
        ... and cells searched around each query's own cell.
    decide_ties : bool
        :func:`nearest_descriptor` decides near ties of the BLAS search by distances summed
        in a fixed order, ties to the lowest index, so that its choice does not depend on the
        machine's BLAS kernels (docs/decisions.md#golden-maps); False keeps the search's own
        nearest.
    """

    pca_dims: int = field(default=64, metadata={"range": (1, None)})
    exact_search_limit: int = 60_000
    max_threads: int = field(default=8, metadata={"range": (1, None)})
    ivf_cells_per_root: int = field(default=2, metadata={"range": (1, None)})
    ivf_probes: int = field(default=12, metadata={"range": (1, None)})
    decide_ties: bool = True


def nearest_candidates(
    da: np.ndarray, db: np.ndarray, n: int, config: SearchConfig = SearchConfig()
) -> tuple[np.ndarray, np.ndarray]:
    """The ``n`` rows of ``db`` closest to each row of ``da``: (indices, squared distances).

    Exact brute force in chunks (no n_a x n_b matrix), after a shared PCA that keeps most of
    the variance while making the search several times cheaper.
    """
    return _search(*_projected(da, db, config), n, config)


def nearest_descriptor(
    da: np.ndarray, db: np.ndarray, config: SearchConfig = SearchConfig()
) -> np.ndarray:
    """The nearest row of ``db`` to each row of ``da`` (after the PCA of
    :func:`nearest_candidates`); with ``config.decide_ties``, near ties are decided by distances
    summed in a fixed order (Rust, no fused multiply-add), ties to the lowest index.

    The search's float32 BLAS products round differently on different kernels (OpenBLAS picks
    AVX2 or AVX-512 ones by CPU), so a near tie could fall either way; the projection is made in
    float64 and rounded, and the final comparison is the same on every machine."""
    pa, pb = _projected(da, db, config)
    if not config.decide_ties:
        return _search(pa, pb, 1, config)[0][:, 0].copy()
    if pb.shape[0] <= config.exact_search_limit:
        nb2 = np.einsum("ij,ij->i", pb, pb)
        return nearest_one(pa, pb, nb2, config.max_threads, decide_ties=True)[0][:, 0].copy()
    # The inverted-file search: its few nearest, decided the same way.
    cand = np.sort(_search(pa, pb, IVF_TIE_CANDIDATES, config)[0], axis=1)
    return _core.nearest_among(pa, pb, np.ascontiguousarray(cand, dtype=np.int64))


def _projected(
    da: np.ndarray, db: np.ndarray, config: SearchConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Both descriptor sets (float32, C order) on their shared ``config.pca_dims`` principal
    axes, or as they are when they have no more columns than that."""
    da = np.ascontiguousarray(da, dtype=np.float32)
    db = np.ascontiguousarray(db, dtype=np.float32)
    if da.shape[1] <= config.pca_dims:
        return da, db
    both = np.vstack([da, db])
    mu = both.mean(axis=0)
    sample = both[:: max(1, both.shape[0] // 20000)] - mu
    # Eigenvectors of the small d x d covariance: far cheaper than an SVD of the samples.
    # One cast, then ``x.T @ x`` on a single buffer, which NumPy runs as a symmetric
    # rank-k update (faster than the mixed float64 @ float32 product, same values).
    s64 = sample.astype(np.float64)
    # One BLAS thread: a product can give other bits on two threads than on one, so the map
    # would depend on the process's thread count (a Ray worker runs with one). The covariance
    # too: OpenBLAS's threads synchronise many times in it, and beside other busy processes
    # waiting on each other made it several times slower than one thread.
    with single_threaded_blas():
        cov = s64.T @ s64
        _, vecs = np.linalg.eigh(cov)
        basis = vecs[:, ::-1][:, : config.pca_dims].astype(np.float32).astype(np.float64)
        # In float64, rounded to float32: the same bits whatever the BLAS kernel, short of
        # a value within 1e-16 of a rounding boundary.
        pa, pb = (
            np.ascontiguousarray(((x - mu).astype(np.float64) @ basis).astype(np.float32))
            for x in (da, db)
        )
        return pa, pb


def _search(
    da: np.ndarray, db: np.ndarray, n: int, config: SearchConfig
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_candidates` on rows already projected."""
    n = min(n, db.shape[0])
    if db.shape[0] > config.exact_search_limit:
        return _inverted_file_candidates(da, db, n, config)
    nb2 = np.einsum("ij,ij->i", db, db)
    if n == 1:
        return nearest_one(da, db, nb2, config.max_threads)
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


def _inverted_file_candidates(da: np.ndarray, db: np.ndarray, n: int, config: SearchConfig):
    """Approximate ``n`` nearest rows of ``db`` per row of ``da`` for very large meshes.

    ``db`` is split into cells by k-means (on a sample, fixed seed: the result is
    deterministic); the queries of each cell are compared with the members of the
    ``config.ivf_probes`` cells nearest to it, so each query sees about ``ivf_probes / cells`` of
    ``db``. Memory stays linear: one block of a cell's queries times its candidates at a time.
    """
    n_b = db.shape[0]
    n_cells = max(1, int(config.ivf_cells_per_root * np.sqrt(n_b)))
    rng = np.random.default_rng(0)
    sample = db[rng.choice(n_b, size=min(n_b, 50 * n_cells), replace=False)]
    with warnings.catch_warnings():
        # A cell left empty keeps its centroid and has no members: nothing to tell the user.
        warnings.filterwarnings("ignore", "One of the clusters is empty", UserWarning)
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
    probes, _ = _nearest(centroids, centroids, config.ivf_probes)
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


#: Candidates the inverted-file search hands to :func:`nearest_descriptor`'s tie decision.
IVF_TIE_CANDIDATES = 4

#: Relative width of a near tie in :func:`nearest_one` (``decide_ties``): far above the
#: rounding of a float32 product of a few hundred terms on any BLAS kernel (about 1e-6).
TIE_WIDTH = 1e-5


def nearest_one(
    da: np.ndarray,
    db: np.ndarray,
    nb2: np.ndarray,
    max_threads: int = SearchConfig.max_threads,
    *,
    decide_ties: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """The single nearest row of ``db`` per row of ``da`` (argmin, no partial sort).

    The rows of ``da`` are split between threads that each run single-threaded BLAS: faster
    than one thread, and OpenBLAS's own threads were no faster while they slowed the small
    products around this call in the spectral pass.

    With ``decide_ties``, a row whose nearest is within :data:`TIE_WIDTH` (relative to the
    rows' squared norms) of another candidate is decided among those candidates by distances
    summed in a fixed order (Rust), ties to the lowest index: the BLAS product rounds
    differently on different kernels, this decision does not.
    """
    idx = np.empty((da.shape[0], 1), dtype=np.int64)
    dist = np.empty((da.shape[0], 1), dtype=np.float32)
    step = max(1, 4_000_000 // max(db.shape[0], 1))
    n_threads = max(1, min(os.cpu_count() or 1, max_threads, -(-da.shape[0] // step)))
    bounds = np.linspace(0, da.shape[0], n_threads + 1).astype(np.int64)
    dbt = db.T
    widest = float(nb2.max()) if nb2.size else 0.0
    tied: list[tuple[int, np.ndarray]] = []

    def search(lo: int, hi: int) -> None:
        # One buffer for every chunk's distances, written in place: a fresh array per chunk
        # and operation had the kernel zero new pages each time (gigabytes over a large search).
        buf = np.empty((min(step, hi - lo), db.shape[0]), dtype=np.float32)
        near = np.empty(buf.shape, dtype=bool) if decide_ties else None
        for s in range(lo, hi, step):
            chunk = da[s : min(s + step, hi)]
            d2 = buf[: chunk.shape[0]]
            np.matmul(2.0 * chunk, dbt, out=d2)
            np.subtract(nb2[None, :], d2, out=d2)
            j = np.argmin(d2, axis=1)
            best = d2[np.arange(j.size), j]
            na2 = np.einsum("ij,ij->i", chunk, chunk)
            idx[s : s + j.size, 0] = j
            dist[s : s + j.size, 0] = best + na2
            if near is not None:
                close = near[: chunk.shape[0]]
                np.less_equal(d2, (best + TIE_WIDTH * (na2 + widest))[:, None], out=close)
                for r in np.flatnonzero(np.count_nonzero(close, axis=1) > 1):
                    tied.append((s + int(r), np.flatnonzero(close[r])))

    with single_threaded_blas():
        if n_threads == 1:
            search(0, da.shape[0])
        else:
            with ThreadPoolExecutor(n_threads) as pool:
                list(pool.map(search, bounds[:-1], bounds[1:]))
    if tied:
        rows = np.array([r for r, _ in tied], dtype=np.int64)
        width = max(c.size for _, c in tied)
        # Each row's candidates in ascending order, padded with its first (lowest) one.
        cand = np.array([np.pad(c, (0, width - c.size), mode="edge") for _, c in tied])
        idx[rows, 0] = _core.nearest_among(
            np.ascontiguousarray(da[rows], dtype=np.float32),
            np.ascontiguousarray(db, dtype=np.float32),
            cand.astype(np.int64),
        )
    return idx, np.maximum(dist, 0.0)
