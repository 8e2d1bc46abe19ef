"""Finishing rounds for shapes that share most of their triangulation.

Where A and B are one triangulation in two poses (FAUST registrations, the TOSCA cat) or a part
of one, the true map sends faces onto faces. HOPE's k-hop overlaps cannot see an error of a few
edges where a pose stretches the surface: there HOPE's map drifts smoothly by a few edges, a
drift that the overlaps of drifted witnesses reproduce.

Each round takes as handles the vertices whose faces all map onto faces of B (with their
orientation) and whose image no other vertex shares, deforms A as rigidly as possible (ARAP,
Sorkine and Alexa 2007) so that the handles sit on their images, moves every other vertex to
the vertex of B nearest its deformed position, and then runs a few HOPE steps at a fixed hop
radius with every vertex voting, which pull the moved vertices onto a one-to-one map. Rounds
repeat while the handle patches that can seed the growth grow. Last,
:func:`hope_rs.growth.grow` rebuilds the map from its trusted patches outward. See
docs/decisions.md#shared-faces and docs/decisions.md#growth for the variants measured.

Shapes without shared faces (independently remeshed shapes have few handles) do not qualify
(see :data:`MIN_HANDLES`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from . import _core
from ._blas import with_single_threaded_blas
from .growth import grow
from .handles import face_handles, large_patches
from .refine import assign_by_overlap
from .shape import Shape

#: Larger shapes are not finished (not measured there).
MAX_VERTICES = 60_000
#: Rounds run only while at least this share of A's vertices are handles.
MIN_HANDLES = 0.2
#: At most this many rounds. They stop earlier once the share of A's vertices in handle
#: patches large enough to seed the growth (:func:`~hope_rs.handles.seed_handles`) grows by
#: less than :data:`MIN_GROWTH`: the rounds are there to seed it
#: (docs/decisions.md#shared-faces).
ROUNDS = 10
MIN_GROWTH = 0.01
#: HOPE steps after each round's snapping, and their hop radius.
STEPS = 3
STEP_K = 5
#: ARAP's alternations of per-vertex rotations and the global solve.
ARAP_ITERATIONS = 5
#: Weight of a pull towards each free vertex's current image, relative to its edges (which
#: have weight 1): keeps the solve well posed on a component without handles.
ANCHOR_WEIGHT = 1e-3


def applies(a: Shape, b: Shape) -> bool:
    """Whether the finishing rounds may run on these shapes (both at most
    :data:`MAX_VERTICES` vertices)."""
    return max(a.n_vertices, b.n_vertices) <= MAX_VERTICES


def qualifies(a: Shape, b: Shape, f: np.ndarray) -> bool:
    """Whether the map ``f`` (internal numbering) has at least :data:`MIN_HANDLES` of A's
    vertices as handles (see :func:`face_handles`)."""
    return bool(face_handles(a, b, f).mean() >= MIN_HANDLES)


def arap_to_handles(
    points: np.ndarray, edges: np.ndarray, start: np.ndarray, handles: np.ndarray
) -> np.ndarray:
    """Positions of A's vertices after deforming ``points`` as rigidly as possible (uniform
    edge weights) with the ``handles`` held at ``start``; ``start`` also seeds the rotations
    and weakly anchors the free vertices (:data:`ANCHOR_WEIGHT`)."""
    return _Arap(points, edges).fit(start, handles)


class _Arap:
    """The parts of :func:`arap_to_handles` that depend on the mesh alone, built once for all
    the rounds of a finish."""

    def __init__(self, points: np.ndarray, edges: np.ndarray):
        n = self.n = len(points)
        i = self.i = np.concatenate([edges[:, 0], edges[:, 1]])  # every edge both ways
        j = self.j = np.concatenate([edges[:, 1], edges[:, 0]])
        w = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
        self.lap = (sp.diags(np.asarray(w.sum(axis=1)).ravel()) - w).tocsr()
        # Sums over each vertex's edges as one sparse product (faster than np.add.at).
        self.per_vertex = sp.csr_matrix(
            (np.ones(len(i)), (i, np.arange(len(i)))), shape=(n, len(i))
        )
        self.ex = points[i] - points[j]

    def fit(self, start: np.ndarray, handles: np.ndarray) -> np.ndarray:
        i, j, ex, per_vertex = self.i, self.j, self.ex, self.per_vertex
        free = ~handles
        lff = (self.lap[free][:, free] + ANCHOR_WEIGHT * sp.eye(int(free.sum()))).tocsc()
        lfh = self.lap[free][:, handles]
        solve = sla.splu(lff).solve
        y = np.array(start, dtype=np.float64)
        for _ in range(ARAP_ITERATIONS):
            ey = y[i] - y[j]
            cov = per_vertex @ (ex[:, :, None] * ey[:, None, :]).reshape(-1, 9)
            rot = _core.closest_rotations(cov.reshape(self.n, 3, 3))
            rhs = per_vertex @ (0.5 * np.einsum("nij,nj->ni", rot[i] + rot[j], ex))
            rhs = rhs[free] - lfh @ y[handles] + ANCHOR_WEIGHT * start[free]
            y[free] = np.column_stack([solve(np.ascontiguousarray(rhs[:, c])) for c in range(3)])
        return y


# SuperLU's solves call BLAS; one thread keeps their bits, and so the map, the same whatever
# the process's thread count (a Ray worker runs with one).
@with_single_threaded_blas
def finish(a: Shape, b: Shape, f: np.ndarray, *, rounds: int = ROUNDS) -> tuple[np.ndarray, int]:
    """The map after the finishing rounds and, if any ran, the growth from their trusted
    patches (:func:`hope_rs.growth.grow`), in the internal numbering; and how many rounds ran."""
    from scipy.spatial import cKDTree

    f = np.asarray(f, dtype=np.int64)
    n_a = a.n_vertices
    k = min(STEP_K, a.k_max, b.k_max)
    every = np.ones(n_a, dtype=bool)
    arap = tree = None  # built by the first round that runs
    last = 0.0
    done = 0
    for _ in range(rounds):
        handles = face_handles(a, b, f)
        seeded = large_patches(a, handles).mean()
        if handles.mean() < MIN_HANDLES or seeded < last + MIN_GROWTH or handles.all():
            break
        last = seeded
        if arap is None:
            # In B's units, so that a scaled copy deforms by rotations alone.
            arap = _Arap(a.points * (b.scale / a.scale), a.edges)
            tree = cKDTree(b.points)
        g = tree.query(arap.fit(b.points[f], handles))[1].astype(np.int64)
        g[handles] = f[handles]
        for _ in range(STEPS):
            g = assign_by_overlap(a, b, k, g, every)
        f = g
        done += 1
    if done:
        f = grow(a, b, f)
    return f, done
