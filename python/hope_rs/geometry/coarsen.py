"""Coarse copies of meshes by vertex clustering (Rossignac & Borrel 1993).

Each cell of the Morton grid of :mod:`hope_rs.geometry.sites` keeps one vertex; faces are
relabelled and collapsed ones dropped. The multiscale match and the coarse-seeded eigenbases
use these copies. :func:`coarse_to_count` clusters on a uniform grid whose side is chosen for a
vertex count; the match at a common resolution takes that grid's sites but merges the other
vertices by manifold-keeping edge collapses (:mod:`hope_rs.geometry.collapse`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from .mesh import Mesh, unique_edges, unique_rows
from .sites import cell_sites, grid_cells

__all__ = ["Coarse", "CoarsenConfig", "coarse_mesh", "coarse_to_count", "uniform_cells_for_count"]


@dataclass(frozen=True)
class CoarsenConfig:
    """Settings of :func:`coarse_mesh` (docs/decisions.md#multiscale).

    Attributes
    ----------
    spacing : float
        Side of a cell as a fraction of sqrt(area): about 14k vertices on a human body
        whatever its density, 8k on the TOSCA cat.
    min_coarsening : float
        A mesh is coarsened only when it has at least this many vertices per coarse vertex.
    """

    spacing: float = 0.0125
    min_coarsening: float = 2.0


@dataclass
class Coarse:
    """A coarse copy of a mesh (in its internal numbering): coarse vertex ``j`` is fine vertex
    ``sites[j]``, and fine vertex ``i`` belongs to coarse vertex ``owner[i]``."""

    mesh: Mesh
    sites: np.ndarray
    owner: np.ndarray


def _clustered(mesh: Mesh, cells: np.ndarray) -> Coarse | None:
    """The vertex clustering of ``mesh`` by the cell ids ``cells`` (one per vertex), or
    ``None`` when every face collapses."""
    sites, owner = cell_sites(mesh.vertices, cells)
    f = owner[mesh.faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])]
    if f.shape[0] == 0:
        return None
    _, first = unique_rows(np.sort(f, axis=1), return_index=True)
    return Coarse(Mesh(mesh.vertices[sites], f[np.sort(first)]), sites, owner)


def _uniform_cells(vertices: np.ndarray, side: float) -> np.ndarray:
    """Cell id of each vertex on the axis-aligned grid of cubes ``side`` wide."""
    q = np.floor((vertices - vertices.min(axis=0)) / side).astype(np.int64)
    dims = q.max(axis=0) + 1
    return (q[:, 0] * dims[1] + q[:, 1]) * dims[2] + q[:, 2]


def uniform_cells_for_count(
    mesh: Mesh, n_target: int, *, tolerance: float = 0.05, max_tries: int = 8
) -> np.ndarray | None:
    """Cell id of each vertex on the uniform grid whose cube side leaves about ``n_target``
    occupied cells (within ``tolerance`` of it, or the nearest of ``max_tries`` sides tried);
    ``None`` when ``mesh`` has no more than ``n_target`` vertices.

    On a surface the count of occupied cells goes as side^-2, so each try rescales the side
    by the square root of the count's ratio to the target."""
    n = mesh.n_vertices
    if n <= n_target or n_target < 4:
        return None
    v = np.asarray(mesh.vertices, dtype=np.float64)
    side = mesh.scale / np.sqrt(n_target)
    best, best_gap = None, np.inf
    for _ in range(max_tries):
        cells = _uniform_cells(v, side)
        count = np.unique(cells).size
        gap = abs(count / n_target - 1.0)
        if gap < best_gap:
            best, best_gap = cells, gap
        if gap <= tolerance:
            break
        side *= np.sqrt(count / n_target)
    assert best is not None  # max_tries >= 1: the first try is the best so far
    return best


def coarse_to_count(
    mesh: Mesh, n_target: int, *, tolerance: float = 0.05, max_tries: int = 8
) -> Coarse | None:
    """Vertex clustering of ``mesh`` on a uniform grid whose cube side is chosen so that
    about ``n_target`` vertices remain (:func:`uniform_cells_for_count`), each grid site then
    owning the vertices nearest it along the surface; ``None`` when ``mesh`` has no more than
    ``n_target`` vertices. The result can have non-manifold edges; see
    :mod:`hope_rs.geometry.collapse` for a coarse copy that stays a manifold."""
    cells = uniform_cells_for_count(mesh, n_target, tolerance=tolerance, max_tries=max_tries)
    if cells is None:
        return None
    return _clustered(mesh, _surface_cells(mesh, cells))


def _surface_cells(mesh: Mesh, cells: np.ndarray) -> np.ndarray:
    """Each vertex relabelled with the grid site nearest it along the edge graph (the sites
    of ``cells``; a vertex no site reaches keeps its cell): a grid cell can hold two sheets
    of the surface that touch in space (fingers, a thigh against the other), which
    clustering would glue together."""
    sites, _ = cell_sites(mesh.vertices, cells)
    e = unique_edges(mesh.faces)
    w = np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)
    n = mesh.n_vertices
    graph = sp.csr_matrix((np.maximum(w, 1e-300), (e[:, 0], e[:, 1])), shape=(n, n))
    dist, _, source = dijkstra(
        graph, directed=False, indices=sites, min_only=True, return_predecessors=True
    )
    reached = np.isfinite(dist)
    out = cells.copy()
    out[reached] = cells[source[reached]]
    return out


def coarse_mesh(mesh: Mesh, config: CoarsenConfig = CoarsenConfig()) -> Coarse | None:
    """Vertex clustering of ``mesh`` on the grid of cells ``config.spacing`` × sqrt(area)
    wide, or ``None`` when it would not leave ``config.min_coarsening`` fine vertices per
    coarse vertex at least.

    Each cell keeps the vertex nearest its centroid; a face keeps its orientation and is
    dropped when two of its corners fall in one cell, or when a face on the same three coarse
    vertices came before it."""
    cells = grid_cells(mesh.vertices, config.spacing * mesh.scale)
    if mesh.n_vertices < config.min_coarsening * np.unique(cells).size:
        return None
    return _clustered(mesh, cells)
