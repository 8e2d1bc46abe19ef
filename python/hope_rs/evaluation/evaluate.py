"""Scoring maps against ground truth: geodesic errors and the figures papers report.

Two distances are available (``method=``):

* ``"graph"`` — shortest paths along B's edges (Rust Dijkstra, searched only until the target is
  settled). Fast; overestimates surface geodesics by a few percent (up to ~8% on a regular grid).
* ``"surface"`` — geodesic paths on the surface by edge flipping (Sharp & Crane, "You Can Find
  Geodesic Paths in Triangle Meshes by Just Flipping Edges", SIGGRAPH Asia 2020), through
  potpourri3d's ``EdgeFlipGeodesicSolver``. Each path starts from the edge-graph shortest path and
  is straightened until it is a locally shortest surface geodesic: exact on flat or developable
  regions (checked against Euclidean distance on a flat grid in the tests) and never longer than
  the graph distance. One path per wrongly matched scored vertex, so there is no n x n matrix and
  no all-vertices solve: the cost grows with the number and length of the errors only.

Either way an exact match scores exactly 0.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import trapezoid

from .. import _core
from .._validate import as_index_map
from ..geometry.map_io import parse_index
from ..geometry.mesh import Mesh, as_mesh, unique_edges
from ..shape import Shape

#: Thresholds of the standard "% correspondences within geodesic error" curve.
MAX_ERROR = 0.25
#: Upper end of the short curve (and its AUC) that recent papers report.
MAX_ERROR_SHORT = 0.10
#: Points on each curve.
CURVE_POINTS = 101
GEODESIC_METHODS = ("graph", "surface")


def load_vts(path: str | os.PathLike) -> np.ndarray:
    """Read a ``.vts`` correspondence file (one 1-based vertex index per line; ``#`` starts a
    comment, blank lines are skipped) as 0-based.

    Raises
    ------
    ValueError
        A one-line message naming the file (and the line, for a bad one): unreadable, empty,
        or a line that is not one vertex index >= 1.
    """
    name = os.fspath(path)
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else e
        raise ValueError(f"cannot read {name!r} as a .vts file: {why}") from None
    rule = "a .vts file has one 1-based vertex index a line"
    idx = []
    for n, line in enumerate(text.split("\n"), 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        shown = line.strip()[:80]
        if len(words) != 1:
            raise ValueError(f"{name}:{n}: {shown!r} has {len(words)} values; {rule}")
        try:
            value = parse_index(words[0])
        except OverflowError:
            raise ValueError(f"{name}:{n}: vertex index {shown!r} is too large") from None
        if value is None:
            raise ValueError(f"{name}:{n}: cannot read {shown!r} as a vertex index; {rule}")
        if value < 1:
            raise ValueError(f"{name}:{n}: index {value} is below 1; .vts files are 1-based")
        idx.append(value - 1)
    if not idx:
        raise ValueError(f"{name!r} has no vertex indices; {rule}")
    return np.array(idx, dtype=np.int64)


def _mesh_and_shape(b) -> tuple[Mesh, Shape | None]:
    shape_b = b if isinstance(b, Shape) else None
    mesh_b = b.mesh if shape_b is not None else as_mesh(b, "b")
    return mesh_b, shape_b


def _graph_distances(mesh: Mesh, shape: Shape | None, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Edge-graph distances between vertices ``u[i]`` and ``v[i]`` of ``mesh`` (unscaled), on
    the graph ``shape`` already holds (in its internal numbering) when there is one."""
    if shape is None:
        return _core.MeshGraph(mesh.vertices, mesh.faces, 0).pair_distances(u, v)
    # The shape's graph is in its internal units, 4**scale_exponent times the mesh's (exact).
    d = shape.graph.pair_distances(shape.rank[u], shape.rank[v])
    return np.ldexp(d, -2 * shape.scale_exponent) if shape.scale_exponent else d


def surface_distances(mesh: Mesh, sources, targets) -> np.ndarray:
    """Surface geodesic length from ``sources[i]`` to ``targets[i]`` on ``mesh`` (unscaled).

    Edge-flip geodesic paths (see the module notes); pairs in different connected components
    get ``inf``. Needs the ``potpourri3d`` package (``pip install hope-rs[eval]``).
    """
    try:
        import potpourri3d as pp3d
    except ImportError:
        raise ValueError(
            "method='surface' needs potpourri3d: pip install potpourri3d "
            "(or use method='graph' for edge-graph distances)"
        ) from None
    src = np.asarray(sources, dtype=np.int64)
    dst = np.asarray(targets, dtype=np.int64)
    graph = _core.MeshGraph(mesh.vertices, mesh.faces, 0)
    out = graph.pair_distances(src, dst)  # upper bound, and inf across components
    todo = np.flatnonzero(np.isfinite(out) & (src != dst))
    if todo.size == 0:
        return out
    solver = pp3d.EdgeFlipGeodesicSolver(mesh.vertices, mesh.faces)
    for i in todo:
        path = solver.find_geodesic_path(int(src[i]), int(dst[i]))
        length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
        out[i] = min(out[i], length)
    return out


def geodesic_errors(b, mapping, *, a_idx=None, b_idx=None, method: str = "graph") -> np.ndarray:
    """Geodesic error of each scored correspondence, divided by sqrt(area) of B.

    ``error_i = d_B(mapping[a_idx[i]], b_idx[i]) / sqrt(area(B))``; with no indices given,
    the ground truth is the identity (vertex i of A ↔ vertex i of B; A and B of one vertex
    count).

    Parameters
    ----------
    b : Mesh or Shape
        The target shape.
    mapping : (n_a,) array_like of int
        ``mapping[i]`` is the vertex of B matched to vertex i of A.
    a_idx, b_idx : array_like of int, optional
        Scored ground-truth pairs (0-based); only these are scored, so pass a subsample to score
        a large identity pair quickly. ``b_idx`` defaults to ``a_idx`` and needs it.
    method : {"graph", "surface"}
        ``"graph"``: edge-graph shortest paths (fast, a few percent long). ``"surface"``: edge-flip
        surface geodesics (near-exact, used by ``hope-rs bench``; needs potpourri3d). Distances
        are computed only between the scored pairs, never as an n x n matrix.

    Returns
    -------
    (len(a_idx),) float64
        ``inf`` where the matched vertex lies on another piece of B than the true one (no path
        joins them); :func:`score` counts such an error as 1.
    """
    if method not in GEODESIC_METHODS:
        raise ValueError(f"method must be one of {GEODESIC_METHODS}, got {method!r}")
    mesh_b, shape_b = _mesh_and_shape(b)
    mapping = np.asarray(mapping)
    if mapping.ndim != 1:
        raise ValueError(
            f"map must be a 1-D array (one vertex of B per vertex of A), got shape {mapping.shape}"
        )
    n_a = mapping.shape[0]
    mapping = as_index_map(mapping, n_a, mesh_b.n_vertices, name="map")
    if a_idx is None and b_idx is not None:
        raise ValueError("b_idx needs a_idx: pass the scored vertices of A beside their truths")
    if a_idx is None:
        if n_a != mesh_b.n_vertices:
            raise ValueError(
                f"without a_idx and b_idx the ground truth is the identity, which needs A and B "
                f"of one vertex count (the map has {n_a}, B {mesh_b.n_vertices}); pass the "
                "scored pairs as a_idx and b_idx"
            )
        a_idx = np.arange(n_a)
    if b_idx is None:
        b_idx = a_idx
    a_idx = as_index_map(a_idx, len(a_idx), n_a, name="a_idx")
    b_idx = as_index_map(b_idx, len(a_idx), mesh_b.n_vertices, name="b_idx")
    src = mapping[a_idx]
    err = np.zeros(a_idx.size)
    wrong = np.flatnonzero(src != b_idx)
    if wrong.size == 0:
        return err
    if method == "surface":
        err[wrong] = surface_distances(mesh_b, src[wrong], b_idx[wrong]) / mesh_b.scale
    else:
        err[wrong] = _graph_distances(mesh_b, shape_b, src[wrong], b_idx[wrong]) / mesh_b.scale
    return err


def _trapezoid(y: np.ndarray, x: np.ndarray) -> float:
    return float(trapezoid(y, x))  # scipy's: numpy < 2 names it trapz, numpy 2 trapezoid


def error_curve(
    errors, *, max_error: float = MAX_ERROR, n: int = CURVE_POINTS
) -> tuple[np.ndarray, np.ndarray]:
    """The "% correspondences within geodesic error e" curve: thresholds ``(n,)`` from 0 to
    ``max_error`` and the fraction (0..1) of errors at or below each."""
    e = np.asarray(errors, dtype=np.float64).ravel()
    if not (np.isfinite(max_error) and max_error > 0):
        raise ValueError(f"max_error must be a positive number, got {max_error}")
    t = np.linspace(0.0, max_error, n)
    if e.size == 0:
        return t, np.full(n, np.nan)
    return t, np.searchsorted(np.sort(e), t, side="right") / e.size


def curve_auc(errors, *, max_error: float = MAX_ERROR) -> float:
    """Area under :func:`error_curve` on ``[0, max_error]``, divided by ``max_error`` (so 1 is
    perfect)."""
    t, c = error_curve(errors, max_error=max_error)
    return _trapezoid(c, t) / max_error


@dataclass
class Score:
    """Summary figures of one map (or of the pooled errors of several)."""

    exact: float  #: fraction with error 0
    mean: float  #: mean normalised geodesic error (unreachable pairs count as 1)
    auc: float  #: area under the % within error curve on [0, 0.25], normalised to 1
    auc_010: float = float("nan")  #: the same on [0, 0.10], as recent papers report

    @property
    def mean_x100(self) -> float:
        """Mean error ×100, the unit most papers' tables use."""
        return 100.0 * self.mean

    def __str__(self) -> str:
        return (
            f"exact {100 * self.exact:.1f}%, mean error {self.mean:.4f} (x100 {self.mean_x100:.2f}),"
            f" AUC {self.auc:.3f}, AUC@0.10 {self.auc_010:.3f}"
        )


def score(errors: np.ndarray, *, max_error: float = MAX_ERROR) -> Score:
    """Fraction exactly right, mean error and curve AUCs (0..max_error and 0..0.10) of an array
    of geodesic errors (each figure NaN for an empty array; a NaN error is refused, an inf one
    counts as 1)."""
    e = np.asarray(errors, dtype=np.float64)
    if e.ndim != 1:
        raise ValueError(f"errors must be a 1-D array, got shape {e.shape}")
    if e.size == 0:  # nothing scored
        return Score(math.nan, math.nan, math.nan, math.nan)
    if np.isnan(e).any():
        raise ValueError("errors hold NaN; an error is a distance >= 0 (inf: unreachable)")
    if (e < 0).any():
        raise ValueError(f"errors are distances, >= 0; got {e.min()}")
    finite = np.where(np.isfinite(e), e, 1.0)
    return Score(
        float(np.mean(e == 0)),
        float(finite.mean()),
        curve_auc(e, max_error=max_error),
        curve_auc(e, max_error=MAX_ERROR_SHORT),
    )


@dataclass
class Smoothness:
    """How continuous a map is, independent of ground truth."""

    edge_stretch: float  #: mean of d_B(f(u), f(v)) / |uv| over A's edges, both in sqrt(area) units
    coverage: float  #: fraction of B's vertices that some vertex of A maps to

    def __str__(self) -> str:
        return f"edge stretch {self.edge_stretch:.2f}, coverage {100 * self.coverage:.1f}%"


def smoothness(a, b, mapping) -> Smoothness:
    """Edge stretch and coverage of ``mapping`` (A → B).

    For each edge (u, v) of A, the edge-graph geodesic between ``mapping[u]`` and ``mapping[v]``
    on B is divided by the edge's length, both normalised by sqrt(area) of their shape. A smooth
    map of equal-density meshes stretches edges by about 1; jumps (a limb mapped to the wrong side)
    give long mapped edges and raise the mean. Edges mapped onto one vertex count as 0, so read
    it together with ``coverage``, the fraction of B's vertices hit.
    """
    mesh_a, _ = _mesh_and_shape(a)
    mesh_b, shape_b = _mesh_and_shape(b)
    f = as_index_map(mapping, mesh_a.n_vertices, mesh_b.n_vertices, name="map")
    edges = unique_edges(mesh_a.faces)
    length = np.linalg.norm(mesh_a.vertices[edges[:, 0]] - mesh_a.vertices[edges[:, 1]], axis=1)
    keep = length > 0
    edges, length = edges[keep], length[keep] / mesh_a.scale
    mapped = _graph_distances(mesh_b, shape_b, f[edges[:, 0]], f[edges[:, 1]]) / mesh_b.scale
    ratio = np.where(np.isfinite(mapped), mapped, 1.0) / length
    coverage = np.unique(f).size / mesh_b.n_vertices
    return Smoothness(float(ratio.mean()), float(coverage))


def confidence_auroc(confidence, errors, *, wrong_above: float = 0.05) -> float:
    """How well a per-vertex ``confidence`` ranks right matches above wrong ones: the area
    under the ROC curve, i.e. the chance that a right match (``errors <= wrong_above``,
    sqrt(area) units) has a higher confidence than a wrong one (ties count half).

    Parameters
    ----------
    confidence, errors : (n,) array_like
        The confidence and the geodesic error of the same scored vertices (e.g.
        ``res.confidence[a_idx]`` and :func:`geodesic_errors` at ``a_idx``).
    wrong_above : float

    Returns
    -------
    float
        In [0, 1]; 0.5 for a confidence that tells nothing. NaN when every match is right, or
        every match wrong. NaN in either argument is refused.
    """
    c, e = np.asarray(confidence, dtype=np.float64), np.asarray(errors, dtype=np.float64)
    right = e <= wrong_above
    if c.shape != right.shape:
        raise ValueError(f"confidence {c.shape} and errors {right.shape} must have one shape")
    for name, values in (("confidence", c), ("errors", e)):
        if np.isnan(values).any():
            i = int(np.flatnonzero(np.isnan(values))[0])
            raise ValueError(f"{name} holds NaN (at index {i}); pass numbers, inf for unreachable")
    pos, neg = c[right], np.sort(c[~right])
    if pos.size == 0 or neg.size == 0:
        return float("nan")
    below = np.searchsorted(neg, pos, side="left")
    ties = np.searchsorted(neg, pos, side="right") - below
    return float((below + 0.5 * ties).sum() / (pos.size * neg.size))
