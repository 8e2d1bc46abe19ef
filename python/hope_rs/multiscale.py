"""Coarse-to-fine matching for large meshes: HOPE on coarse copies, lifted, then a few fine passes.

A refinement step costs about linearly in the vertex count, and a k-hop ball of a dense mesh
covers a small patch, so dense pairs run every pass of the schedule and take minutes.
``match(..., multiscale=True)`` instead

1. clusters each dense mesh's vertices on a grid of cells at most ``COARSE_SPACING`` ×
   sqrt(area) wide (the Morton grid of :mod:`hope_rs.sites`, whose cells halve until they fit;
   vertex clustering, Rossignac & Borrel 1993: one vertex per cell, faces relabelled, collapsed
   ones dropped): about 14k vertices on a human body whatever the density, 8k on the TOSCA cat;
2. matches the coarse copies with the full method (SHOT computed on the fine mesh at the
   coarse vertices);
3. lifts the coarse map: each fine vertex of A is moved by the local linear map that best
   carries the coarse edges around its cell's vertex onto their images on B, and takes the
   fine vertex of B nearest that point;
4. runs :func:`fine_passes` passes of the usual refinement on the fine meshes (two up to 60k
   vertices, else one).

Both shapes must be dense enough to halve, else :func:`hope_rs.match` takes the default path
(a coarse copy matched against a sparser shape did worse than it). It trades accuracy for time
and is off by default; see docs/decisions.md#multiscale for the measurements and the variants
that did not pay.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import Mesh, unique_edges
from .sites import cell_sites, grid_cells

#: Side of a coarse cell as a fraction of sqrt(area).
COARSE_SPACING = 0.0125
#: A mesh is coarsened only when it has at least this many vertices per coarse vertex.
MIN_COARSENING = 2.0
#: Passes of the refinement schedule on the fine meshes after the lift (see
#: :func:`fine_passes`): FINE_PASSES, or FINE_PASSES_SMALL when neither fine mesh has more than
#: FINE_PASSES_SMALL_VERTICES vertices (a second pass pays below that size and costs too much
#: time above; docs/decisions.md#multiscale).
FINE_PASSES = 1
FINE_PASSES_SMALL = 2
FINE_PASSES_SMALL_VERTICES = 60_000
#: Ridge of the local linear fit, relative to the mean squared edge around the vertex.
LIFT_RIDGE = 1e-3


@dataclass
class Coarse:
    """A coarse copy of a mesh (in its internal numbering): coarse vertex ``j`` is fine vertex
    ``sites[j]``, and fine vertex ``i`` belongs to coarse vertex ``owner[i]``."""

    mesh: Mesh
    sites: np.ndarray
    owner: np.ndarray


def coarse_mesh(mesh: Mesh, spacing: float | None = None) -> Coarse | None:
    """Vertex clustering of ``mesh`` on the grid of cells ``spacing`` × sqrt(area) wide, or
    ``None`` when that would not at least halve the vertex count (see :data:`MIN_COARSENING`).

    Each cell keeps the vertex nearest its centroid; a face keeps its orientation and is
    dropped when two of its corners fall in one cell, or when a face on the same three coarse
    vertices came before it. ``spacing`` defaults to :data:`COARSE_SPACING`."""
    spacing = COARSE_SPACING if spacing is None else spacing
    cells = grid_cells(mesh.vertices, spacing * mesh.scale)
    sites, owner = cell_sites(mesh.vertices, cells)
    if mesh.n_vertices < MIN_COARSENING * sites.size:
        return None
    f = owner[mesh.faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])]
    if f.shape[0] == 0:
        return None
    _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
    return Coarse(Mesh(mesh.vertices[sites], f[np.sort(first)]), sites, owner)


def fine_passes(n_a: int, n_b: int) -> int:
    """Passes of the refinement on fine meshes of ``n_a`` and ``n_b`` vertices after the
    lift (see :data:`FINE_PASSES`)."""
    return FINE_PASSES_SMALL if max(n_a, n_b) <= FINE_PASSES_SMALL_VERTICES else FINE_PASSES


def _edges(faces: np.ndarray) -> np.ndarray:
    """Every edge of ``faces`` in both directions, once each."""
    e = unique_edges(faces)
    return np.concatenate([e, e[:, ::-1]])


def lift_map(
    coarse_a: Mesh,
    coarse_b: Mesh,
    g: np.ndarray,
    points_a: np.ndarray,
    owner_a: np.ndarray,
    points_b: np.ndarray,
) -> np.ndarray:
    """A map of fine vertices from the coarse map ``g`` (coarse A → coarse B vertices).

    Fine vertex ``i`` of A, at ``points_a[i]``, belongs to coarse vertex ``c = owner_a[i]``.
    The linear map ``T_c`` that best carries the coarse edges of the 2-ring of ``c`` onto the
    edges between their images (least squares, with a small ridge so that a degenerate
    neighbourhood shrinks towards zero instead of blowing up) moves ``i`` to
    ``coarse_b.vertices[g[c]] + T_c (points_a[i] - x_c)``, and ``i`` takes the fine vertex of
    B (``points_b``) nearest that point."""
    import scipy.sparse as sp
    from scipy.spatial import cKDTree

    xa, yb = coarse_a.vertices, coarse_b.vertices
    n = xa.shape[0]
    e = _edges(coarse_a.faces)
    da = xa[e[:, 1]] - xa[e[:, 0]]
    db = yb[g[e[:, 1]]] - yb[g[e[:, 0]]]

    def moments(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Sum over each vertex's edges of u v^T, then over its 1-ring: the 2-ring's edges
        (a 1-ring's edges alone are often nearly coplanar, or two)."""
        outer = (u[:, :, None] * v[:, None, :]).reshape(-1, 9)
        own = np.stack([np.bincount(e[:, 0], outer[:, k], minlength=n) for k in range(9)], 1)
        ring = sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
        return (own + ring @ own).reshape(n, 3, 3)

    p, q = moments(da, da), moments(db, da)
    ridge = LIFT_RIDGE * np.trace(p, axis1=1, axis2=2) / 3.0
    # A vertex without edges gets a unit ridge only: its fine vertices go to its image.
    ridge = np.where(ridge > 0, ridge, 1.0)
    t = q @ np.linalg.inv(p + ridge[:, None, None] * np.eye(3))
    target = yb[g][owner_a] + np.einsum("nij,nj->ni", t[owner_a], points_a - xa[owner_a])
    return cKDTree(points_b).query(target)[1].astype(np.int64)


def _level(shape, kind: str | None):
    """(Coarse, coarse Shape) of ``shape`` (which must be dense enough to coarsen), with SHOT
    descriptors when ``kind`` is "shot"; the coarse Shape computes other kinds itself."""
    from .descriptors import shot_at

    level = shape.coarse_level()
    if level is None:
        raise ValueError("the shape is not dense enough to coarsen (see coarse_mesh)")
    if kind == "shot" and not level[1].has_descriptors("shot"):
        # On the fine mesh, at the coarse vertices: the coarse surface would describe coarser.
        level[1].set_descriptors("shot", shot_at(shape.internal, level[0].sites))
    return level


def coarse_start(a, b, init, **options):
    """The start of a multiscale match of the shapes ``a`` and ``b`` (both dense enough to
    coarsen): HOPE on their coarse copies, lifted to the fine vertices. ``init`` is a descriptor kind or a map in ``a``'s and
    ``b``'s internal numbering; ``options`` go to :func:`hope_rs.match` on the coarse copies.
    Returns the coarse :class:`~hope_rs.MatchResult` (coarse vertex ``j`` of each shape is
    the ``j``-th vertex of its :class:`Coarse`) and the lifted map (internal numbering)."""
    from .matching import match

    kind = init if isinstance(init, str) else None
    (ca, csa), (cb, csb) = _level(a, kind), _level(b, kind)
    if kind is None:
        init = cb.owner[np.asarray(init)[ca.sites]]
    res = match(csa, csb, init=init, **options)
    return res, lift_map(ca.mesh, cb.mesh, res.map, a.points, ca.owner, b.points)
