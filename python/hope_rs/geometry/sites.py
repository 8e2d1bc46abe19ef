"""Descriptor sites on dense meshes: one vertex per cell of a grid fixed by the SHOT radius.

SHOT describes a vertex by the points within a radius that is a fixed fraction of the shape
(0.1 sqrt(area)), so its support holds a fixed fraction of all vertices and computing it at
every vertex costs n², a large share of a dense match. A descriptor over that support
barely changes across a distance far below the radius, though. On a mesh denser than a grid
of cells of side ``SiteConfig.spacing`` × radius, SHOT is therefore computed at one vertex per
occupied cell (its *site*, with every vertex of the mesh still voting in its support), and the
other vertices of the cell share it; the initial map searches between sites only.

Wider cells left a worse start, so the spacing stays at a sixteenth of the radius
(docs/decisions.md#descriptors); meshes with fewer than two vertices per cell (the usual
benchmark shapes) keep one descriptor per vertex.

The grid is the Morton grid of :mod:`hope_rs.geometry.numbering`: cells are aligned with the bounding
box, so the sites depend on the geometry only, not on the numbering.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import Mesh
from .numbering import MORTON_BITS, morton_codes


@dataclass(frozen=True)
class SiteConfig:
    """Settings of :func:`shot_sites` (docs/decisions.md#descriptors).

    Attributes
    ----------
    spacing : float
        Side of a site cell as a fraction of the SHOT support radius.
    min_vertices_per_site : float
        Sites are used only when the mesh has at least this many vertices per occupied cell
        on average: below it the saving is small and every vertex keeps its own descriptor.
    """

    spacing: float = 1 / 16
    min_vertices_per_site: float = 2.0


def grid_cells(vertices: np.ndarray, side: float) -> np.ndarray:
    """Cell id of each vertex on the Morton grid whose cells are at most ``side`` wide (ids are
    Morton codes with the finer bits dropped, so they sort like the cells along the curve)."""
    v = np.asarray(vertices, dtype=np.float64)
    codes = morton_codes(v)
    if v.shape[0] == 0:
        return codes
    span = float((v.max(axis=0) - v.min(axis=0)).max())
    if not (span > 0 and side > 0):
        return codes
    level = int(np.clip(np.ceil(np.log2(span / side)), 0, MORTON_BITS))
    return codes >> np.uint64(3 * (MORTON_BITS - level))


def cell_sites(vertices: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One site per cell, the member nearest the cell's centroid (ties: the lowest index):
    (``sites``, ``owner``) with ``sites[owner[i]]`` the site of vertex ``i``; sites are in
    the order of their cells' ids."""
    ids, owner = np.unique(cells, return_inverse=True)
    return _sites_of(np.asarray(vertices, dtype=np.float64), owner.reshape(-1), ids.size), owner


def owner_means(v: np.ndarray, owner: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(the mean of the points ``v`` of each of ``n`` groups, point ``i`` in group
    ``owner[i]``; whether each group has a point): an empty group's mean is not a number."""
    count = np.bincount(owner, minlength=n).astype(np.float64)
    sums = np.stack([np.bincount(owner, weights=v[:, d], minlength=n) for d in range(3)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return sums / count[:, None], count > 0


def nearest_members(v: np.ndarray, owner: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Of each group that has points, the point nearest its centre (ties: the lowest index),
    in the order of the groups' ids: point ``i`` of ``v`` is in group ``owner[i]``, whose
    centre is ``centre[owner[i]]``."""
    d2 = ((v - centre[owner]) ** 2).sum(axis=1)
    by_group = np.lexsort((np.arange(v.shape[0]), d2, owner))
    first = np.r_[True, owner[by_group][1:] != owner[by_group][:-1]]
    return by_group[first]


def _sites_of(v: np.ndarray, owner: np.ndarray, n_cells: int) -> np.ndarray:
    """The site of each of ``n_cells`` cells, vertex ``i`` being in cell ``owner[i]``."""
    return nearest_members(v, owner, owner_means(v, owner, n_cells)[0])


def shot_sites(
    mesh: Mesh, radius: float, config: SiteConfig = SiteConfig()
) -> tuple[np.ndarray, np.ndarray] | None:
    """(``sites``, ``owner``) of :func:`cell_sites` for SHOT of support ``radius`` (relative to
    sqrt(area)) on ``mesh``, or ``None`` when the mesh is not dense enough for them to pay."""
    n = mesh.n_vertices
    if n == 0:
        return None
    cells = grid_cells(mesh.vertices, config.spacing * radius * mesh.scale)
    ids, owner = np.unique(cells, return_inverse=True)
    if n < config.min_vertices_per_site * ids.size:
        return None
    owner = owner.reshape(-1)
    return _sites_of(mesh.vertices, owner, ids.size), owner
