"""Scoring maps against ground truth: geodesic errors and the figures papers report."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from . import _core
from ._validate import as_index_map
from .mesh import Mesh
from .shape import Shape


def load_vts(path: str | os.PathLike) -> np.ndarray:
    """Read a ``.vts`` correspondence file (one 1-based vertex index per line) as 0-based."""
    try:
        rows = np.loadtxt(path, dtype=np.int64, ndmin=2)
    except (OSError, ValueError) as e:
        raise ValueError(f"cannot read {os.fspath(path)!r} as a .vts file: {e}") from None
    idx = rows[:, 0] - 1
    if idx.size and idx.min() < 0:
        raise ValueError(f"{os.fspath(path)!r} holds an index below 1; .vts files are 1-based")
    return idx


def geodesic_errors(b, mapping, *, a_idx=None, b_idx=None) -> np.ndarray:
    """Geodesic error of each scored correspondence, divided by sqrt(area) of B.

    ``error_i = d_B(mapping[a_idx[i]], b_idx[i]) / sqrt(area(B))``; with no indices given,
    the ground truth is the identity (vertex i of A ↔ vertex i of B).

    Distances are shortest paths on B's edge graph, searched from each mapped vertex only until
    its ground-truth vertex is reached (no n x n matrix); they overestimate surface geodesics by a
    few percent, and exact (error 0) matches are exact either way.
    """
    shape_b = b if isinstance(b, Shape) else None
    mesh_b = b.mesh if shape_b is not None else b
    if not isinstance(mesh_b, Mesh):
        raise TypeError("b must be a hope_rs.Mesh or hope_rs.Shape")
    mapping = np.asarray(mapping)
    n_a = mapping.shape[0] if mapping.ndim == 1 else -1
    mapping = as_index_map(mapping, n_a, mesh_b.n_vertices, name="map")
    if a_idx is None:
        a_idx = np.arange(min(n_a, mesh_b.n_vertices))
    if b_idx is None:
        b_idx = a_idx
    a_idx = as_index_map(a_idx, len(a_idx), n_a, name="a_idx")
    b_idx = as_index_map(b_idx, len(a_idx), mesh_b.n_vertices, name="b_idx")
    src = mapping[a_idx]
    err = np.zeros(a_idx.size)
    wrong = np.flatnonzero(src != b_idx)
    if wrong.size:
        graph = (
            shape_b.graph
            if shape_b is not None
            else _core.MeshGraph(mesh_b.vertices, mesh_b.faces, 0)
        )
        err[wrong] = graph.pair_distances(src[wrong], b_idx[wrong]) / mesh_b.scale
    return err


@dataclass
class Score:
    """Summary figures of one map."""

    exact: float  #: fraction with error 0
    mean: float  #: mean normalised geodesic error
    auc: float  #: area under the % within error curve on [0, 0.25], normalised to 1

    def __str__(self) -> str:
        return f"exact {100 * self.exact:.1f}%, mean error {self.mean:.4f}, AUC {self.auc:.3f}"


def score(errors: np.ndarray, *, max_error: float = 0.25) -> Score:
    """Fraction exactly right, mean error and curve AUC of an array of geodesic errors."""
    e = np.asarray(errors, dtype=np.float64)
    t = np.linspace(0.0, max_error, 101)
    curve = (e[None, :] <= t[:, None]).mean(axis=1)
    auc = (
        float(np.trapezoid(curve, t) / max_error)
        if hasattr(np, "trapezoid")
        else float(np.trapz(curve, t) / max_error)
    )
    finite = np.where(np.isfinite(e), e, 1.0)
    return Score(float(np.mean(e == 0)), float(finite.mean()), auc)
