"""NumPy/SciPy front ends of the three Rust kernels of HOPE."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .. import _core
from .._validate import as_faces, as_index_map, as_mask


def khop_neighbourhoods(faces, k: int, *, n_vertices: int | None = None) -> sp.csr_matrix:
    """Vertices within ``k`` edges of each vertex of a triangle mesh.

    Parameters
    ----------
    faces : (M, 3) array_like of int
        Triangles as 0-based vertex indices.
    k : int
        Hop radius, ``0 <= k <= 255``.
    n_vertices : int, optional
        Number of vertices, from ``faces.max() + 1`` (the default) to ``2**31 - 1``. Vertices
        in no face are isolated.

    Returns
    -------
    scipy.sparse.csr_matrix
        ``(n, n)`` uint8 pattern; row ``v`` holds every vertex within ``k`` edges of ``v``
        (``v`` included), column indices sorted.

    Raises
    ------
    ValueError
        On malformed faces or a vertex count out of that range.
    MemoryError
        When the pattern of ``n_vertices`` vertices cannot fit in the machine's memory.
    """
    k = _as_count(k, "k", upper=255)
    if n_vertices is not None:
        n_vertices = _as_count(n_vertices, "n_vertices")
    faces = as_faces(faces, n_vertices)
    if n_vertices is None:
        if faces.size == 0:
            raise ValueError("faces is empty; pass n_vertices to get isolated vertices")
        n_vertices = int(faces.max()) + 1
    indptr, indices, data = _core.khop_neighbourhoods(faces, k, n_vertices)
    return sp.csr_matrix((data, indices, indptr), shape=(n_vertices, n_vertices))


def overlap_cost(
    nbrs_a, nbrs_b, f, witnesses, *, top_k: int | None = None, keep=None
) -> sp.csr_matrix:
    """HOPE's overlap count ``K[p, q] = #{witness v : v in N_a(p), f[v] in N_b(q)}``.

    Parameters
    ----------
    nbrs_a, nbrs_b : scipy.sparse matrix
        Square neighbourhood patterns of shapes A (n_a x n_a) and B (n_b x n_b), e.g. from
        :func:`khop_neighbourhoods`. Stored entries count as members whatever their value.
    f : (n_a,) array_like of int
        Current map, ``f[v]`` is the vertex of B matched to vertex ``v`` of A.
    witnesses : (n_a,) bool array or array of vertex indices
        Trusted matches; only they vote.
    top_k : int, optional
        Keep only the ``top_k`` largest counts of each row (ties: smaller column first), which
        bounds time and memory when most vertices are witnesses.
    keep : (n_a,) array_like of int, optional
        A column each row always keeps (stored even when its count is 0), typically the current
        match, so that a full assignment remains possible.

    Returns
    -------
    scipy.sparse.csr_matrix
        ``(n_a, n_b)`` uint32 counts, only nonzero entries (plus ``keep``) stored, columns sorted.
    """
    a = _pattern(nbrs_a, "nbrs_a")
    b = _pattern(nbrs_b, "nbrs_b")
    n_a, n_b = a.shape[0], b.shape[0]
    f = as_index_map(f, n_a, n_b, name="f")
    w = as_mask(witnesses, n_a)
    if top_k is not None:
        top_k = _as_count(top_k, "top_k", lower=1)
    if keep is not None:
        keep = as_index_map(keep, n_a, n_b, name="keep")
    indptr, indices, data = _core.overlap_cost_csr(
        a.indptr.astype(np.int64), a.indices.astype(np.int32, copy=False), n_a,
        b.indptr.astype(np.int64), b.indices.astype(np.int32, copy=False), n_b,
        f, w, top_k, keep,
    )  # fmt: skip
    return sp.csr_matrix((data, indices, indptr), shape=(n_a, n_b))


def _pattern(m, name: str) -> sp.csr_matrix:
    if not sp.issparse(m):
        raise TypeError(f"{name} must be a scipy.sparse matrix, got {type(m).__name__}")
    if m.shape[0] != m.shape[1]:
        raise ValueError(f"{name} must be square (vertices x vertices), got shape {m.shape}")
    m = sp.csr_matrix(m)
    try:
        # Before scipy's own routines read it: a malformed index array corrupts their memory.
        m.check_format(full_check=True)
    except ValueError as err:
        raise ValueError(f"{name} is not a valid sparse matrix: {err}") from None
    m.sum_duplicates()
    return m


def _as_count(x, name: str, *, lower: int = 0, upper: int | None = None) -> int:
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {type(x).__name__}")
    x = int(x)
    if x < lower or (upper is not None and x > upper):
        bound = f"[{lower}, {upper}]" if upper is not None else f">= {lower}"
        raise ValueError(f"{name} must be {bound}, got {x}")
    return x
