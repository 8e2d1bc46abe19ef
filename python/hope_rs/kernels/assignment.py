"""Exact linear assignment on sparse (or dense) costs with the Rust auction solver."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .. import _core


def auction_assignment(cost, *, maximize: bool = True) -> np.ndarray:
    """Optimal one-to-one assignment of rows to columns.

    Parameters
    ----------
    cost : scipy.sparse matrix or (n_rows, n_cols) array_like
        Sparse: stored entries are the allowed pairs (an explicit 0 is allowed), missing entries
        are forbidden. Dense: every pair is allowed. Values must be finite; integer costs are
        solved exactly, float costs on a fine integer grid (see Notes).
    maximize : bool, default True
        Maximise the total (HOPE's overlap counts) instead of minimising it.

    Returns
    -------
    numpy.ndarray
        int64 array of length ``n_rows``: the column assigned to each row, or -1 for rows left
        unassigned (only when ``n_rows > n_cols``). Every row of the smaller side is assigned and
        every column is used at most once.

    Raises
    ------
    ValueError
        If the cost holds NaN/inf, or no assignment covers the smaller side within the pattern.

    Notes
    -----
    Epsilon-scaling auction (Bertsekas) on costs multiplied by ``n + 1``, ending at epsilon = 1,
    which makes integer solutions exactly optimal. Float costs are first rounded to a grid of
    ``max|cost| / S`` with ``S`` as large as 64-bit prices allow (about ``2**62 / n**2``); the
    total is then optimal up to ``n * max|cost| / S``.
    """
    if isinstance(maximize, (np.ndarray, list)) or not isinstance(maximize, (bool, np.bool_)):
        raise TypeError("maximize must be a bool")
    if sp.issparse(cost):
        m = sp.csr_matrix(cost)
        if m.ndim != 2:
            raise ValueError(f"cost must be 2-D, got shape {m.shape}")
        n_rows, n_cols = m.shape
        try:
            return _solve(m.indptr, m.indices, m.data, n_rows, n_cols, maximize)
        except _core.DuplicateEntries:
            # scipy's convention: duplicates add up. Looked for by the solver's own parallel
            # scan, which costs nothing extra, rather than by scipy's canonical-format check up
            # front.
            m = m.copy()
            m.sum_duplicates()
            return _solve(m.indptr, m.indices, m.data, n_rows, n_cols, maximize)
    else:
        a = np.asarray(cost)
        if a.ndim != 2:
            raise ValueError(
                f"cost must be a 2-D array or a scipy.sparse matrix, got shape {a.shape}"
            )
        n_rows, n_cols = a.shape
        data = a.reshape(-1)
        indptr = np.arange(0, n_rows * n_cols + 1, max(n_cols, 1), dtype=np.int64)
        if n_cols == 0:
            indptr = np.zeros(n_rows + 1, dtype=np.int64)
        indices = np.tile(np.arange(n_cols, dtype=np.int32), n_rows)
    return _solve(indptr, indices, data, n_rows, n_cols, maximize)


def _solve(indptr, indices, data, n_rows: int, n_cols: int, maximize) -> np.ndarray:
    if data.dtype == bool:
        data = data.astype(np.int64)
    if not (np.issubdtype(data.dtype, np.integer) or np.issubdtype(data.dtype, np.floating)):
        raise TypeError(f"cost must hold integer or float values, got dtype {data.dtype}")
    indptr = np.ascontiguousarray(indptr, dtype=np.int64)
    if n_cols > np.iinfo(np.int32).max:
        raise ValueError(f"at most {np.iinfo(np.int32).max} columns are supported, got {n_cols}")
    indices = np.ascontiguousarray(indices, dtype=np.int32)
    if np.issubdtype(data.dtype, np.integer):
        if data.dtype == np.uint64 and data.size and data.max() > np.iinfo(np.int64).max:
            raise ValueError("cost values exceed the int64 range")
        return _core.auction_assignment_int(
            indptr,
            indices,
            np.ascontiguousarray(data, dtype=np.int64),
            n_rows,
            n_cols,
            bool(maximize),
        )
    data = np.ascontiguousarray(data, dtype=np.float64)
    if not np.all(np.isfinite(data)):
        raise ValueError(
            "cost contains NaN or infinite values; forbid a pair by leaving it out of a sparse cost"
        )
    return _core.auction_assignment_float(indptr, indices, data, n_rows, n_cols, bool(maximize))
