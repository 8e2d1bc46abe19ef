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

from .coarsen import Coarse, uniform_cells_for_count
from .mesh import Mesh, unique_edges
from .sites import cell_sites

__all__ = ["collapse_to_count", "collapse_to_sites"]


class _Collapser:
    """A triangle mesh under half-edge collapses: faces, the faces of each vertex, and the
    vertex each removed vertex was merged into."""

    def __init__(self, mesh: Mesh):
        self.v = np.asarray(mesh.vertices, dtype=np.float64)
        self.f = np.array(mesh.faces, dtype=np.int64)
        self.face_alive = np.ones(len(self.f), dtype=bool)
        self.vfaces: list[set[int]] = [set() for _ in range(len(self.v))]
        for i, face in enumerate(self.f.tolist()):
            for x in face:
                self.vfaces[x].add(i)
        self.merged_into = np.arange(len(self.v))

    def _neighbours(self, u: int) -> set[int]:
        out: set[int] = set()
        for i in self.vfaces[u]:
            out.update(self.f[i].tolist())
        out.discard(u)
        return out

    def _on_boundary(self, u: int) -> bool:
        """Whether an edge at ``u`` lies on one face only."""
        count: dict[int, int] = {}
        for i in self.vfaces[u]:
            for x in self.f[i].tolist():
                if x != u:
                    count[x] = count.get(x, 0) + 1
        return any(c == 1 for c in count.values())

    def _normal(self, a: int, b: int, c: int) -> np.ndarray:
        return np.cross(self.v[b] - self.v[a], self.v[c] - self.v[a])

    def can_collapse(self, u: int, w: int) -> bool:
        """Whether removing ``u`` into its neighbour ``w`` keeps a manifold with no face
        turned over or flattened."""
        shared = [i for i in self.vfaces[u] if i in self.vfaces[w]]
        if not shared:
            return False  # not an edge
        opposite = {x for i in shared for x in self.f[i].tolist() if x not in (u, w)}
        # Link condition: the only common neighbours of u and w are the edge's opposite
        # corners (otherwise the collapse makes a non-manifold edge or a duplicate face).
        if self._neighbours(u) & self._neighbours(w) != opposite:
            return False
        # The boundary keeps its shape: a boundary vertex moves only along a boundary edge.
        if len(shared) != 1 and self._on_boundary(u):
            return False
        for i in self.vfaces[u]:
            if i in shared:
                continue
            face = self.f[i].tolist()
            before = self._normal(*face)
            after = self._normal(*[w if x == u else x for x in face])
            # No face turns over or collapses to a line.
            if np.dot(before, after) <= 0.0 or not np.any(after):
                return False
        return True

    def collapse(self, u: int, w: int) -> None:
        """Remove ``u`` into ``w`` (checked by :meth:`can_collapse`)."""
        for i in list(self.vfaces[u]):
            face = self.f[i]
            if i in self.vfaces[w]:  # a face of the edge (u, w): it collapses
                self.face_alive[i] = False
                for x in face.tolist():
                    self.vfaces[x].discard(i)
            else:
                face[face == u] = w
                self.vfaces[w].add(i)
        self.vfaces[u] = set()
        self.merged_into[u] = w

    def result(self, alive: np.ndarray) -> Coarse:
        """The collapsed mesh in compact numbering, the input vertex of each coarse vertex and
        the coarse vertex each input vertex was merged into."""
        sites = np.flatnonzero(alive)
        index = np.full(len(self.v), -1, dtype=np.int64)
        index[sites] = np.arange(sites.size)
        root = self.merged_into.copy()
        while True:  # follow merge chains to a kept vertex
            nxt = root[root]
            if np.array_equal(nxt, root):
                break
            root = nxt
        faces = index[self.f[self.face_alive]]
        return Coarse(Mesh(self.v[sites], faces), sites, index[root])


def collapse_to_sites(mesh: Mesh, sites: np.ndarray) -> Coarse:
    """Merge every vertex of ``mesh`` into the vertex of ``sites`` nearest it along the edge
    graph, by manifold-keeping half-edge collapses (see the module notes). A vertex no site
    reaches, or whose collapses are refused, is kept."""
    n = mesh.n_vertices
    e = unique_edges(mesh.faces)
    w = np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)
    graph = sp.csr_matrix((np.maximum(w, 1e-300), (e[:, 0], e[:, 1])), shape=(n, n))
    dist, pred, source = dijkstra(
        graph, directed=False, indices=sites, min_only=True, return_predecessors=True
    )
    c = _Collapser(mesh)
    alive = np.ones(n, dtype=bool)
    is_site = np.zeros(n, dtype=bool)
    is_site[sites] = True
    # Farthest first: every vertex whose path to the site runs through u is merged before u.
    order = [int(u) for u in np.argsort(-dist, kind="stable") if np.isfinite(dist[u])]
    order = [u for u in order if not is_site[u]]
    for u in order:
        if c.can_collapse(u, int(pred[u])):
            c.collapse(u, int(pred[u]))
            alive[u] = False
    # Vertices refused on the tree: merge into another neighbour of the same site, nearest
    # that site first, until no more can go.
    changed = True
    while changed:
        changed = False
        for u in order:
            if not alive[u]:
                continue
            cands = [x for x in c._neighbours(u) if source[x] == source[u]]
            for x in sorted(cands, key=lambda x: dist[x]):
                if dist[x] < dist[u] and c.can_collapse(u, x):
                    c.collapse(u, x)
                    alive[u], changed = False, True
                    break
    return c.result(alive)


def collapse_to_count(mesh: Mesh, n_target: int, *, tolerance: float = 0.05) -> Coarse | None:
    """A manifold coarse copy of ``mesh`` with about ``n_target`` vertices: the sites of
    :func:`hope_rs.geometry.coarsen.coarse_to_count`'s uniform grid (``tolerance``: see
    :func:`~hope_rs.geometry.coarsen.uniform_cells_for_count`), every other vertex merged
    into its site by :func:`collapse_to_sites`; ``None`` when ``mesh`` has no more than
    ``n_target`` vertices."""
    cells = uniform_cells_for_count(mesh, n_target, tolerance=tolerance)
    if cells is None:
        return None
    sites, _ = cell_sites(mesh.vertices, cells)
    return collapse_to_sites(mesh, sites)
