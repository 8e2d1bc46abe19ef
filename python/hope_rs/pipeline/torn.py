"""Which regions of A a map tears off the rest.

A right map is continuous: the two ends of an edge of A land near each other on B. A map that
carries a region to the wrong place while keeping its orientation and its 2-rings (a head
shifted along the neck, a leg onto the leg beside it) tears that region off along a seam
whose edges land far apart. The edges of A whose ends land farther apart on B (in space, so
that a topological shortcut of B does not tear a right map) than ``OrientConfig.tear_length``
· sqrt(area) of B, or on coarse meshes ``OrientConfig.tear_edges`` mean edge lengths of A or
B (the longer), are cut, except those with an end on A's boundary (a part's rim lands
loosely, and a narrow strip beside a hole would tear a right map's limb off; so a region torn
off that reaches the boundary stays joined to the core through it, unseen); in each
component of A's mesh the piece with the largest area is its core, and the other pieces of
at least ``OrientConfig.min_torn`` of A's area are torn off. A right map tears nothing off:
its widest edges span a few edges.

Used by the "orient" stage (:mod:`hope_rs.pipeline.orientation_repair`): a trigger, a term
of the cost it minimises, and the core its ``"torn"`` hypothesis re-places the rest from
(:func:`replaced`).
"""

from __future__ import annotations

import numpy as np

from ..geometry.mesh import boundary_edges, vertex_components
from ..shape import Shape
from .anchors import anchor_step
from .config import RepairConfig
from .partial import mean_edge

__all__ = ["TornRegions", "replaced"]


class TornRegions:
    """The regions of A that maps onto B tear off (see the module notes), with what depends
    on the shapes alone computed once.

    Parameters
    ----------
    a, b : Shape
        The shapes (internal numbering).
    length : float
        ``OrientConfig.tear_length``: an edge of A is cut when its ends land farther apart
        than this many sqrt(area) of B ...
    edges : float
        ... and than ``OrientConfig.tear_edges`` mean edge lengths of A or of B, the longer
        (each in its shape's sqrt(area)): a coarse mesh's right map spans longer edges.
    min_share : float
        ``OrientConfig.min_torn``: the least share of A's area a piece must cover to count as
        torn off (scattered vertices landing apart are the noise of a right map).
    """

    def __init__(self, a: Shape, b: Shape, length: float, edges: float, min_share: float):
        self.edges = a.edges
        self.n = a.n_vertices
        faces = a.internal.faces
        area = np.bincount(faces.ravel(), np.repeat(a.internal.face_areas, 3), minlength=self.n)
        #: Each vertex's share of A's area (a third of its faces'; a Shape has a positive area).
        self.area = area / area.sum()
        #: Per vertex of A, its component of A's mesh.
        self.mesh_part = vertex_components(self.n, self.edges)
        #: The edges of A with an end on its boundary, never cut: a part's rim vertices,
        #: their 2-rings incomplete, land loosely, and a narrow strip beside a hole would
        #: tear a limb off a right map.
        rim = np.zeros(self.n, dtype=bool)
        rim[boundary_edges(faces).ravel()] = True
        self.on_rim = rim[self.edges].any(axis=1)
        self._points_b = b.points
        # Each shape's mean edge in its own sqrt(area) (a Shape has edges and a positive area).
        longest = max(mean_edge(a) / a.scale, mean_edge(b) / b.scale)
        #: The image length beyond which an edge is cut, in B's coordinates.
        self.max_length = max(float(length), float(edges) * longest) * b.scale
        self.min_share = float(min_share)

    def pieces(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(core, torn)``, bool per vertex of A under the map ``f`` (internal numbering):
        the core pieces (the largest of each mesh component) and the pieces torn off
        (the others of at least ``min_share`` of A's area)."""
        e, pb = self.edges, self._points_b
        f = np.asarray(f)
        kept = np.linalg.norm(pb[f[e[:, 0]]] - pb[f[e[:, 1]]], axis=1) <= self.max_length
        kept |= self.on_rim
        label = vertex_components(self.n, e[kept])
        size = np.bincount(label, self.area)
        # Per mesh component, its largest piece (ties to the lowest label).
        part = np.zeros(size.size, dtype=np.int64)
        part[label] = self.mesh_part
        order = np.lexsort((-size, part))  # by mesh component, largest piece first
        first = np.ones(order.size, dtype=bool)
        first[1:] = part[order[1:]] != part[order[:-1]]
        is_core = np.zeros(size.size, dtype=bool)
        is_core[order[first]] = True
        core = is_core[label]
        torn = ~core & (size[label] >= self.min_share)
        return core, torn

    def share(self, f: np.ndarray) -> float:
        """The share of A's area that ``f`` tears off (see :meth:`pieces`), in [0, 1)."""
        return float(self.area[self.pieces(f)[1]].sum())


def replaced(
    a: Shape, b: Shape, f: np.ndarray, torn: TornRegions, config: RepairConfig = RepairConfig()
) -> np.ndarray | None:
    """``f`` (internal numbering) with the vertices off the core of each mesh component of A
    that has a piece torn off placed by their geodesic distances to anchors in that
    component's core (:func:`~hope_rs.pipeline.anchors.anchor_step`), the other components
    as they are; ``None`` when nothing is torn off or no such core has 4 vertices. One
    component at a time: the anchors' distances do not reach across components."""
    core, off = torn.pieces(f)
    g = np.asarray(f).copy()
    moved = False
    for part in np.unique(torn.mesh_part[off]):
        inside = torn.mesh_part == part
        if (core & inside).sum() < 4:
            continue
        placed = anchor_step(a, b, f, core & inside, config=config)
        change = inside & ~core
        g[change] = placed[change]
        moved = True
    return g if moved else None
