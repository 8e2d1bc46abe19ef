"""Coarse copies of meshes by vertex clustering (Rossignac & Borrel 1993).

Each cell of the Morton grid of :mod:`hope_rs.geometry.sites` keeps one vertex; faces are
relabelled and collapsed ones dropped. The multiscale match and the coarse-seeded eigenbases
use these copies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import Mesh
from .sites import cell_sites, grid_cells

__all__ = ["Coarse", "CoarsenConfig", "coarse_mesh"]


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


def coarse_mesh(mesh: Mesh, config: CoarsenConfig = CoarsenConfig()) -> Coarse | None:
    """Vertex clustering of ``mesh`` on the grid of cells ``config.spacing`` × sqrt(area)
    wide, or ``None`` when it would not leave ``config.min_coarsening`` fine vertices per
    coarse vertex at least.

    Each cell keeps the vertex nearest its centroid; a face keeps its orientation and is
    dropped when two of its corners fall in one cell, or when a face on the same three coarse
    vertices came before it."""
    cells = grid_cells(mesh.vertices, config.spacing * mesh.scale)
    sites, owner = cell_sites(mesh.vertices, cells)
    if mesh.n_vertices < config.min_coarsening * sites.size:
        return None
    f = owner[mesh.faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])]
    if f.shape[0] == 0:
        return None
    _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
    return Coarse(Mesh(mesh.vertices[sites], f[np.sort(first)]), sites, owner)
