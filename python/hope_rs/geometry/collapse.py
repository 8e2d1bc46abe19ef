"""Vertex clustering by edge collapses: a coarse copy that stays a valid triangle mesh.

Plain vertex clustering (:mod:`hope_rs.geometry.coarsen`) relabels faces at once, which can
glue a cell's faces into non-manifold edges (three or more faces), turn faces over and open
holes. Here each vertex is instead merged into its cluster's site one half-edge collapse at a
time, along the shortest-path tree from the site (farthest vertices first), and a collapse is
made only when it keeps the mesh a manifold (the link condition of Dey et al. 1999, the
boundary kept) and turns no face over. A vertex whose collapses are all refused stays, so the
result can have a few vertices more than the sites. Each kept vertex is a vertex of the input,
and the genus and orientation of the input are kept.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from .. import _core
from .coarsen import Coarse, uniform_cells_for_count
from .mesh import Mesh, unique_edges
from .sites import cell_sites

__all__ = ["collapse_to_count", "collapse_to_sites", "shortest_path_tree"]


def shortest_path_tree(mesh: Mesh, sites: np.ndarray) -> tuple[np.ndarray, ...]:
    """Multi-source Dijkstra along ``mesh``'s edges (lengths) from ``sites``: each vertex's
    distance to its nearest site (``inf`` when none reaches it), its predecessor on the path
    and that site (negative when there is none)."""
    n = mesh.n_vertices
    e = unique_edges(mesh.faces)
    w = np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)
    graph = sp.csr_matrix((np.maximum(w, 1e-300), (e[:, 0], e[:, 1])), shape=(n, n))
    return dijkstra(graph, directed=False, indices=sites, min_only=True, return_predecessors=True)


def collapse_to_sites(mesh: Mesh, sites: np.ndarray) -> Coarse | None:
    """Merge every vertex of ``mesh`` into the vertex of ``sites`` nearest it along the edge
    graph, by manifold-keeping half-edge collapses (see the module notes; in the Rust core).
    A vertex no site reaches, or whose collapses are refused, is kept. ``None`` when no face
    is left (each component merged into fewer than three sites)."""
    dist, pred, source = shortest_path_tree(mesh, sites)
    f = np.asarray(mesh.faces, dtype=np.int64)
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])]  # no area
    kept, owner, faces = _core.collapse_to_sites(
        np.asarray(mesh.vertices, dtype=np.float64),
        f,
        np.asarray(sites, dtype=np.int64),
        dist,
        pred.astype(np.int64),
        source.astype(np.int64),
    )
    if len(faces) == 0:
        return None
    return Coarse(Mesh(mesh.vertices[kept], faces), kept, owner)


def collapse_to_count(mesh: Mesh, n_target: int, *, tolerance: float = 0.05) -> Coarse | None:
    """A manifold coarse copy of ``mesh`` with about ``n_target`` vertices: the sites of
    :func:`hope_rs.geometry.coarsen.coarse_to_count`'s uniform grid (``tolerance``: see
    :func:`~hope_rs.geometry.coarsen.uniform_cells_for_count`), every other vertex merged
    into its site by :func:`collapse_to_sites`; ``None`` when ``mesh`` has no more than
    ``n_target`` vertices or no face is left."""
    cells = uniform_cells_for_count(mesh, n_target, tolerance=tolerance)
    if cells is None:
        return None
    sites, _ = cell_sites(mesh.vertices, cells)
    return collapse_to_sites(mesh, sites)
