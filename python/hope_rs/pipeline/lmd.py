"""Local map distortion (LMD) and the witnesses it selects."""

from __future__ import annotations

import numpy as np

from .. import _core
from .._validate import as_index_map
from ..shape import Shape
from .config import RefineConfig

# The witness rule (``RefineConfig.min_consistent``): a 2-ring neighbour r of p is consistent
# when |d_A(p, r) - d_B(f(p), f(r))| is below p's tolerance (distances scaled by sqrt(area)):
# 1.25 times the geometric mean of A's mean edge length and the local edge length at p and
# f(p); p is a witness when at least that share of its 2-ring is consistent. A share rather
# than the mean distortion keeps witnesses available when much of the map is wrong
# (docs/decisions.md#lmd).


def local_map_distortion(a: Shape, b: Shape, f) -> tuple[np.ndarray, np.ndarray]:
    """Distortion of the map ``f`` (A → B) over the 2-ring of each vertex of A.

    For vertex p and each r in its 2-ring, the edge-graph geodesic d_A(p, r) is compared with
    d_B(f(p), f(r)), both divided by sqrt(area) of their shape, so scale does not matter.

    Returns
    -------
    mean : (n_a,) float32
        Mean |difference| over the 2-ring, in units of A's mean edge length.
    consistent : (n_a,) float32
        Fraction of the 2-ring whose difference is below p's tolerance: 1.25 times the geometric
        mean of A's mean edge length and the mean of the edge lengths at p (on A) and at f(p)
        (on B). One global edge length spans several local edges where a mesh is fine (the
        TOSCA cat's edges run from 0.12 to 2.3 times their mean), and slid maps passed there.

    Notes
    -----
    Geodesics are Dijkstra distances on the edge graph, computed locally (each search stops
    once the 2-ring images are settled, or beyond the 2-ring's radius plus two edges). They
    overestimate surface distance by a few percent, but the comparison is local and relative,
    so that bias cancels between the shapes while the cost stays linear in the vertex count.
    """
    f = as_index_map(f, a.n_vertices, b.n_vertices, name="f")
    return _core.local_map_distortion_graphs(a.graph, b.graph, f, a.scale, b.scale)


def witnesses(
    a: Shape, b: Shape, f, *, min_consistent: float = RefineConfig.min_consistent
) -> np.ndarray:
    """Boolean mask of the vertices whose match under ``f`` is trusted: at least
    ``min_consistent`` of their 2-ring keeps its geodesic distance (see ``RefineConfig.min_consistent``)."""
    _, consistent = local_map_distortion(a, b, f)
    return consistent >= min_consistent


class LmdTracker:
    """LMD of a sequence of maps between the same two shapes, as in a refinement loop.

    Each call remembers its map and result; the next call recomputes only the vertices whose
    2-ring (themselves included) maps differently, which gives exactly the values of
    :func:`local_map_distortion` at a fraction of its cost once the steps move few vertices.
    """

    def __init__(self, a: Shape, b: Shape):
        self.a, self.b = a, b
        self._last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def local_map_distortion(self, f) -> tuple[np.ndarray, np.ndarray]:
        """Same as :func:`local_map_distortion` for ``f``."""
        a, b = self.a, self.b
        f = np.array(as_index_map(f, a.n_vertices, b.n_vertices, name="f"), dtype=np.int64)
        mean, consistent = _core.local_map_distortion_graphs(
            a.graph, b.graph, f, a.scale, b.scale, self._last
        )
        self._last = (f, mean, consistent)
        return mean, consistent

    def witnesses(self, f, *, min_consistent: float = RefineConfig.min_consistent) -> np.ndarray:
        """Same as :func:`witnesses` for ``f``."""
        return self.local_map_distortion(f)[1] >= min_consistent
