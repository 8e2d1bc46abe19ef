"""Which of A's triangles a map turns over on B.

A triangle of A (internal numbering, oriented outward) is turned over when the triangle of its
corners' images winds against B's outward vertex normals there (their sum). A region carried
onto a swapped branch or a mirror image can keep its distances and its 2-rings, but its
triangles land on B wound the other way; on remeshed pairs a right map turns a few percent of
the area over, where the two triangulations disagree.

Which side of an open surface is outward is a guess (:mod:`hope_rs.geometry.orientation`):
a concave part can come out inward, and a right map onto it would then turn everything over.
So the triangles are grouped by their component of A and the component of B their first
corner lands in, and in a group with either component open the smaller of the turned and the
kept sides counts as turned. A component counts as open when its boundary is longer than
:data:`OPEN_BOUNDARY` (:func:`open_components`): a pinhole or a few missing triangles leave
its enclosed volume, and so its outward side, as sure as on a closed surface.

Used by the pair-level quality (:func:`hope_rs.pipeline.confidence.flipped_share`) and by the
refinement's witnesses when ``RefineConfig.max_turned`` is set (a part's matches).
"""

from __future__ import annotations

import numpy as np

from ..geometry.mesh import boundary_edge_lengths, vertex_components
from ..geometry.normals import face_normals, vertex_normal_sums
from ..shape import Shape
from .config import PartialConfig

__all__ = [
    "OPEN_BOUNDARY",
    "TurnedFaces",
    "face_normals",
    "is_open",
    "open_components",
    "vertex_normals",
]

#: A surface is open when its boundary (edges of one face) is longer than this, in units of
#: its own sqrt(area): the partial stage's longest boundary of a whole
#: (``PartialConfig.max_whole_boundary``). A shorter one (a pinhole, a few missing triangles)
#: leaves the outward side as sure as on a closed surface, and the spectrum nearly unchanged.
OPEN_BOUNDARY = PartialConfig.max_whole_boundary


def vertex_normals(s: Shape) -> np.ndarray:
    """(n, 3) area-weighted sums of the normals of each vertex's faces (internal numbering)."""
    return vertex_normal_sums(s.internal.vertices, s.internal.faces)


def open_components(s: Shape) -> tuple[np.ndarray, np.ndarray]:
    """(component of each vertex, int64; whether each component is open: its edges of one
    face longer than :data:`OPEN_BOUNDARY` in all, in units of the shape's own sqrt(area))
    of the internal mesh, components linked through its edges."""
    comp = vertex_components(s.n_vertices, s.edges)
    b, lengths = boundary_edge_lengths(s.internal.vertices, s.internal.faces)
    length = np.bincount(comp[b[:, 0]], weights=lengths, minlength=int(comp.max()) + 1)
    return comp, length > OPEN_BOUNDARY * s.internal.scale


def is_open(s: Shape) -> bool:
    """Whether a component of ``s`` is open (:func:`open_components`)."""
    return bool(open_components(s)[1].any())


class TurnedFaces:
    """The triangles of A that maps onto B turn over (see the module notes), with what depends
    on the shapes alone computed once.

    Parameters
    ----------
    a, b : Shape
        The shapes (a view at another scale reads the same mesh).
    among : (n_a,) bool ndarray, optional
        The vertices of A (internal numbering) whose triangles count: the triangles with all
        three corners in it.
    """

    def __init__(self, a: Shape, b: Shape, among: np.ndarray | None = None):
        faces, area = a.internal.faces, a.internal.face_areas
        if among is not None:
            keep = np.asarray(among, dtype=bool)[faces].all(axis=1)
            faces, area = faces[keep], area[keep]
        self.faces = faces
        self.n_a = a.n_vertices
        #: Each triangle's area on A.
        self.area = area
        self._points_b = b.internal.vertices
        self._normals_b = vertex_normals(b)
        self._comp_a, self._open_a = open_components(a)
        self._comp_b, self._open_b = open_components(b)

    def __call__(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(turned, counted)``, bool per triangle of :attr:`faces`, under the map ``f``
        (internal numbering): triangles whose image is degenerate (two corners on one vertex,
        or a zero area) are not counted, and count as neither turned nor kept."""
        image = np.asarray(f)[self.faces]
        side = np.einsum(
            "ij,ij->i",
            face_normals(self._points_b, image),
            self._normals_b[image].sum(axis=1),
        )
        counted = (side != 0.0) & (image[:, 0] != image[:, 1]) & (image[:, 1] != image[:, 2])
        counted &= image[:, 2] != image[:, 0]
        over = counted & (side < 0.0)
        if over.any():
            width = self._comp_b.max() + 1
            key = self._comp_a[self.faces[:, 0]] * width + self._comp_b[image[:, 0]]
            group, index = np.unique(key, return_inverse=True)
            area = self.area * counted
            turned_area = np.bincount(index, area * over, minlength=group.size)
            kept_area = np.bincount(index, area, minlength=group.size) - turned_area
            either_open = self._open_a[group // width] | self._open_b[group % width]
            # In an open group the smaller side is the turned one.
            swap = (either_open & (turned_area > kept_area))[index]
            over = np.where(swap, counted & ~over, over)
        return over, counted

    def share(self, f: np.ndarray) -> float:
        """The share of the counted triangles' area that ``f`` turns over, in [0, 1]; 0 when
        no triangle counts."""
        over, counted = self(f)
        total = float((self.area * counted).sum())
        return float((self.area * over).sum() / total) if total > 0.0 else 0.0

    def vertex_shares(self, f: np.ndarray) -> np.ndarray:
        """Per vertex of A, the share of the area of its triangles that ``f`` turns over (0
        for a vertex without counted triangles)."""
        over, _ = self(f)
        corners = self.faces.ravel()
        total = np.bincount(corners, np.repeat(self.area, 3), minlength=self.n_a)
        turned = np.bincount(corners, np.repeat(self.area * over, 3), minlength=self.n_a)
        return turned / np.maximum(total, np.finfo(float).tiny)

    def vertices(self, f: np.ndarray, max_share: float) -> np.ndarray:
        """Bool per vertex of A: more than ``max_share`` of the area of its triangles is turned
        over by ``f``. In a group with an open component that is the smaller side: a map that
        turns most of such a group over marks the side it keeps."""
        over, _ = self(f)
        corners = self.faces.ravel()
        total = np.bincount(corners, np.repeat(self.area, 3), minlength=self.n_a)
        turned = np.bincount(corners, np.repeat(self.area * over, 3), minlength=self.n_a)
        return turned > max_share * total
