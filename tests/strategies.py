"""Shrinkable Hypothesis strategies shared by the property tests.

Every random choice is drawn from Hypothesis (never a seed handed to a NumPy generator), so a
failing case shrinks towards the identity permutation, zero angles and the smallest sizes.
"""

import numpy as np
import scipy.sparse as sp
from hypothesis import assume
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from meshes import bumped, isometric_copy, sphere_points

# Largest n drawn as one st.permutations(range(n)): Hypothesis gives up on an example after
# about 8 KB of drawn data, which a permutation of a few thousand items exceeds.
FULL_PERMUTATION = 1000


@st.composite
def permutations(draw, n: int) -> np.ndarray:
    """A permutation of ``range(n)`` as an int64 array.

    Up to ``FULL_PERMUTATION`` items any permutation can be drawn. Above it, the items are cut
    into ``FULL_PERMUTATION`` runs of consecutive indices, the runs are shuffled by a drawn
    permutation, and the result goes through a drawn affine shuffle ``i -> (a i + b) mod n``
    (``a`` prime to ``n``), which scatters the neighbours of every run. Both parts shrink to
    the identity.
    """
    if n <= FULL_PERMUTATION:
        return np.array(draw(st.permutations(range(n))), dtype=np.int64)
    runs = np.array_split(np.arange(n), FULL_PERMUTATION)
    order = draw(st.permutations(range(FULL_PERMUTATION)))
    blocks = np.concatenate([runs[i] for i in order])
    a = draw(st.integers(1, n - 1).filter(lambda a: np.gcd(a, n) == 1))
    b = draw(st.integers(0, n - 1))
    return blocks[(a * np.arange(n) + b) % n]


@st.composite
def rotations(draw) -> np.ndarray:
    """A proper rotation (det +1) from three drawn Euler angles (radians)."""
    x, y, z = (draw(st.floats(-np.pi, np.pi)) for _ in range(3))
    cx, sx, cy, sy, cz, sz = np.cos(x), np.sin(x), np.cos(y), np.sin(y), np.cos(z), np.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


# The bump field that bumpy_surfaces shrinks to: no symmetry, so every vertex can be told apart.
BASE_FIELD = np.array(
    [
        [0.13, -1.25, 0.64],
        [0.10, -0.54, 0.36],
        [1.30, 0.95, -0.70],
        [-1.27, -0.62, 0.04],
        [-2.33, -0.22, -1.25],
        [-0.73, -0.54, -0.32],
    ]
)


@st.composite
def bumpy_surfaces(draw, min_n: int, max_n: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed bumpy surface of ``min_n`` to ``max_n`` vertices (vertices, outward faces): the
    sphere's points spread evenly, turned by a drawn rotation, then bent by ``BASE_FIELD``
    plus a drawn change of up to 0.5 per frequency (see :func:`meshes.bumped`)."""
    n = draw(st.integers(min_n, max_n), label="n")
    rot = draw(rotations(), label="turn")
    delta = draw(arrays(np.float64, (6, 3), elements=st.floats(-0.5, 0.5), fill=st.nothing()))
    return bumped(sphere_points(n) @ rot.T, BASE_FIELD + delta)


@st.composite
def isometric_copies(draw, v: np.ndarray, f: np.ndarray):
    """B = the mesh (v, f) relabelled, rotated, scaled by [0.5, 2] and shifted by up to 10 along
    each axis; returns B and the true map A -> B."""
    perm = draw(permutations(v.shape[0]), label="perm")
    rot = draw(rotations(), label="rot")
    scale = draw(st.floats(0.5, 2.0), label="scale")
    shift = draw(arrays(np.float64, 3, elements=st.floats(-10, 10)), label="shift")
    return isometric_copy(v, f, perm, rot, scale, shift)


@st.composite
def half_corrupted(draw, truth: np.ndarray) -> np.ndarray:
    """``truth`` (a one-to-one map) with half of its vertices sent to wrong partners.

    A drawn permutation ``q`` of the vertices picks the wrong half, ``q[:n // 2]``; the j-th of
    them takes the true image of vertex ``q[n // 2 + j // 2]``. Every wrong image is so taken
    twice, and also by the vertex it truly belongs to: duplicates, as random partners give.
    """
    n = truth.size
    q = draw(permutations(n), label="corruption")
    half = n // 2
    f = truth.copy()
    f[q[:half]] = truth[q[half + np.arange(half) // 2]]
    return f


@st.composite
def renumberings(draw, n_vertices: int, n_faces: int):
    """Arguments of :func:`meshes.renumber`: a vertex relabelling, a face order and a rotation
    (0, 1 or 2 places) of each face's corners."""
    perm = draw(permutations(n_vertices), label="perm")
    face_order = draw(permutations(n_faces), label="face_order")
    turn = draw(arrays(np.int64, n_faces, elements=st.integers(0, 2)), label="turn")
    return perm, face_order, turn


@st.composite
def maps(draw, n_a: int, n_b: int) -> np.ndarray:
    """A map of ``n_a`` vertices into ``range(n_b)`` (any, duplicates allowed)."""
    return draw(arrays(np.int64, n_a, elements=st.integers(0, n_b - 1)))


@st.composite
def dense_costs(draw, max_rows: int = 12, max_cols: int = 12) -> np.ndarray:
    """A dense cost matrix: small integers (many ties), wide integers, or floats over six
    orders of magnitude. Every entry is drawn (no fill value)."""
    shape = (draw(st.integers(1, max_rows)), draw(st.integers(1, max_cols)))
    kind = draw(st.sampled_from(["int-ties", "int-wide", "float"]))
    if kind == "int-ties":
        return draw(arrays(np.int64, shape, elements=st.integers(0, 2), fill=st.nothing()))
    if kind == "int-wide":
        wide = st.integers(-(10**6), 10**6 - 1)
        return draw(arrays(np.int64, shape, elements=wide, fill=st.nothing()))
    c = draw(arrays(np.float64, shape, elements=st.floats(-3, 3), fill=st.nothing()))
    return c * 10 ** draw(st.floats(-3, 3))


@st.composite
def sparse_costs(draw, max_rows: int = 25, max_cols: int = 30) -> sp.csr_matrix:
    """A sparse cost matrix in CSR form with at least as many columns as rows, or its
    transpose. A hidden one-to-one pattern keeps most instances feasible; row 0 may be given a
    single allowed column. Values are small integers (ties) or floats in [-5, 5]."""
    n_rows = draw(st.integers(1, max_rows))
    n_cols = draw(st.integers(n_rows, max_cols))
    # Sparse patterns (drawn entries scattered over a False fill) or dense ones (every entry
    # drawn, about half of them set).
    fill = st.just(False) if draw(st.booleans()) else st.nothing()
    mask = draw(arrays(np.bool_, (n_rows, n_cols), fill=fill), label="pattern")
    hidden = draw(permutations(n_cols), label="hidden")[:n_rows]
    mask[np.arange(n_rows), hidden] = True
    if draw(st.booleans()):
        mask[0] = False
        mask[0, draw(st.integers(0, n_cols - 1))] = True
    r, c = np.nonzero(mask)
    # Every value is drawn (no fill value): ties come from the small integers only.
    if draw(st.booleans()):
        vals = draw(arrays(np.int64, r.size, elements=st.integers(0, 3), fill=st.nothing()))
    else:
        vals = draw(arrays(np.float64, r.size, elements=st.floats(-5, 5), fill=st.nothing()))
    m = sp.csr_matrix((vals, (r, c)), shape=mask.shape)
    return m.T.tocsr() if draw(st.booleans()) else m


@st.composite
def symmetric_patterns(draw, n: int) -> sp.csr_matrix:
    """A symmetric 0/1 pattern of an n x n matrix (uint8) with its diagonal set, like a k-hop
    neighbourhood. Drawn entries scatter over a fill value, so patterns range from the
    diagonal alone to nearly full."""
    m = draw(arrays(np.bool_, (n, n)))
    m = m | m.T | np.eye(n, dtype=bool)
    return sp.csr_matrix(m.astype(np.uint8))


@st.composite
def generic_points(draw, n: int, bound: float = 10.0) -> np.ndarray:
    """``n`` points in the cube [-bound, bound]^3 whose pairwise distances are all different
    (by more than a relative 1e-9), so that nearest-first choices have no ties."""
    p = draw(arrays(np.float64, (n, 3), elements=st.floats(-bound, bound), fill=st.nothing()))
    d = np.sort(np.linalg.norm(p[:, None] - p[None], axis=2)[np.triu_indices(n, 1)])
    assume(d.size == 0 or (d[0] > 0 and np.all(np.diff(d) > 1e-9 * d[-1])))
    return p


__all__ = [
    "bumpy_surfaces",
    "dense_costs",
    "generic_points",
    "half_corrupted",
    "isometric_copies",
    "maps",
    "permutations",
    "renumberings",
    "rotations",
    "sparse_costs",
    "symmetric_patterns",
]
