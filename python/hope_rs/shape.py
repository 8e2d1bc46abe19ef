"""Per-shape precomputation reused across every pair a shape takes part in."""

from __future__ import annotations

import numpy as np

from . import _core
from .descriptors import descriptors as _descriptors
from .mesh import Mesh

K_MAX = 8


class Shape:
    """A mesh with its k-hop neighbourhoods (up to ``k_max``) and cached descriptors.

    Build one per mesh and pass it to :func:`hope_rs.match` as often as you like: the
    neighbourhoods and descriptors are computed once.

    Parameters
    ----------
    mesh : Mesh or (vertices, faces)
    k_max : int, keyword-only
        Largest hop radius the refinement may use.
    """

    def __init__(self, mesh, *, k_max: int = K_MAX):
        if not isinstance(mesh, Mesh):
            if isinstance(mesh, (tuple, list)) and len(mesh) == 2:
                mesh = Mesh(*mesh)
            else:
                raise TypeError("Shape needs a hope_rs.Mesh or a (vertices, faces) pair")
        if (
            isinstance(k_max, bool)
            or not isinstance(k_max, (int, np.integer))
            or not 2 <= k_max <= 64
        ):
            raise ValueError(f"k_max must be an integer in [2, 64], got {k_max!r}")
        self.mesh = mesh
        self.k_max = int(k_max)
        self.scale = mesh.scale
        self.graph = _core.MeshGraph(mesh.vertices, mesh.faces, self.k_max)
        self._descriptors: dict[str, np.ndarray] = {}

    @property
    def n_vertices(self) -> int:
        return self.mesh.n_vertices

    def descriptors(self, kind: str = "shot") -> np.ndarray:
        """Descriptors of ``kind`` ("shot", "wks", "hks"), computed once and cached."""
        if kind not in self._descriptors:
            self._descriptors[kind] = _descriptors(self.mesh, kind)
        return self._descriptors[kind]

    def __repr__(self) -> str:
        return f"Shape(n_vertices={self.n_vertices}, k_max={self.k_max})"
