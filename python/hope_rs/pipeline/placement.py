"""Placement starts: a part matched again from each of several regions of the whole.

A part's descriptor start can put it on a region of the whole that looks alike but is not its
counterpart: the front half of a quadruped's body on the hind half (two legs on a trunk),
turned end to end. Such a map keeps its orientation, so nothing that measures turned-over
triangles sees it, and no change of the part's scale moves it off there. The partial stage
then also starts the part's match from each of several regions of the whole
(:func:`placement_regions`, each smaller than the part's counterpart): each vertex of the
part takes its nearest descriptor among the region's vertices only (:func:`region_start`),
and the refinement grows the map from there over the whole shape. A region within the part's
counterpart gives the map of highest confidence.
"""

from __future__ import annotations

import numpy as np

from ..kernels.search import SearchConfig
from ..shape import Shape
from .initial import initial_map

__all__ = ["placement_regions", "region_start"]


def placement_regions(b: Shape, share: float, n: int) -> list[np.ndarray]:
    """``n`` regions of ``b`` (internal numbering), each the vertices nearest (along edges)
    one of ``n`` centres spread over the surface (each centre the vertex farthest from
    those before it, the first the farthest from vertex 0): the fewest such vertices holding
    ``share`` of its area."""
    everything = np.arange(b.n_vertices, dtype=np.int64)
    first = _farthest(b.graph.distance_fields(np.zeros(1, dtype=np.int64))[0])
    _, fields = b.graph.farthest_fields(everything, first, n, b.scale)
    area = b.internal.vertex_areas
    limit = min(max(share, 0.0), 1.0) * area.sum()
    regions = []
    for d in fields:
        order = np.argsort(d, kind="stable")
        held = np.cumsum(area[order])
        regions.append(np.sort(order[: int(np.searchsorted(held, limit)) + 1]))
    return regions


def region_start(
    a: Shape, b: Shape, region: np.ndarray, kind: str, search: SearchConfig = SearchConfig()
) -> np.ndarray:
    """The map A → B (internal numbering) sending each vertex of ``a`` to the vertex of
    ``region`` (vertices of ``b``) whose ``kind`` descriptor is nearest its own."""
    da, db = a.internal_descriptors(kind), b.internal_descriptors(kind)
    return region[initial_map(da, db[region], search=search)]


def _farthest(d: np.ndarray) -> int:
    """The vertex of largest finite distance (another component's vertices are not reached;
    ties: the lowest vertex)."""
    return int(np.argmax(np.where(np.isfinite(d), d, -1.0)))
