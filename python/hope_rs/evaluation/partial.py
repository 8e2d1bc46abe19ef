"""Partial-shape benchmark sets built from a ``.vts`` data set (``hope-rs partial-set``).

Each benchmark pair (A, B) of a source data set (see :mod:`hope_rs.evaluation.datasets`)
gives one pair per condition; the cut shape is a part of the original mesh (the faces whose
three corners are kept, then its largest connected component), so the ground truth carries
over through its vertex map. Conditions:

* ``cut30``, ``cut50``: A cut by a plane that removes 30% / 50% of its vertices;
* ``holes``: 3–5 geodesic discs punched out of A, each of ``hole_area`` of its area;
* ``cut_both``: A and B each cut by a plane removing 30% of their vertices, with opposite
  normals (the two parts overlap only partly);

and for every condition with a whole B, the same pairs the other way round (``*_rev``:
``match(whole, part)``), scored on the vertices of the whole that have a counterpart.

Everything is chosen by rule, not drawn at random: the plane normal of pair i is
:func:`plane_normal` (i), its offset the vertex quantile that removes the wanted share; the
hole centres are farthest-point samples of the shape seeded at the vertex nearest its centroid,
after the first ``skip`` samples (they land on extremities, which would make the holes cuts).

The output folder holds one data-set folder per (source, condition), in the ``pairs.txt`` +
``corres/NAME.vts`` layout ``hope-rs bench`` reads, plus ``origin/NAME.vts``: for a cut mesh,
line j is the 1-based vertex of the original mesh its vertex j came from.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from ..geometry.mesh import Mesh, boundary_edges, load_mesh, unique_edges, vertex_components
from .derived_sets import (
    add_set_parser,
    run_set_command,
    set_jobs,
    write_off,
    write_sets,
    write_vts,
)

__all__ = [
    "CONDITIONS",
    "Part",
    "cut_by_plane",
    "edge_graph",
    "hole_centres",
    "plane_normal",
    "punch_holes",
    "submesh",
    "write_partial_sets",
]

#: Condition name → what it removes (see the module notes).
CONDITIONS = {
    "cut30": "A cut by a plane removing 30% of its vertices",
    "cut50": "A cut by a plane removing 50% of its vertices",
    "holes": "3-5 geodesic discs punched out of A",
    "cut_both": "A and B each cut by a plane removing 30% (opposite normals)",
}


@dataclass(frozen=True)
class Part:
    """A part of a mesh: the part itself and, per vertex, the original vertex it came from."""

    mesh: Mesh
    origin: np.ndarray  #: (n_part,) int64, 0-based vertex of the original mesh

    def inverse(self, n_original: int) -> np.ndarray:
        """Per original vertex, its vertex on the part, or -1 when it was removed."""
        inv = np.full(n_original, -1, dtype=np.int64)
        inv[self.origin] = np.arange(self.origin.size)
        return inv


def submesh(mesh: Mesh, keep: np.ndarray) -> Part:
    """The faces of ``mesh`` with all three corners in ``keep`` (a boolean mask), reduced to
    their largest connected component (ties: the one with the lowest vertex); vertices where
    two boundary loops would touch are removed too, so that a part of a manifold mesh is a
    manifold mesh with boundary."""
    keep = np.array(keep, dtype=bool)
    while True:
        part = _largest_component(mesh, keep)
        ends = np.bincount(
            boundary_edges(part.mesh.faces).reshape(-1), minlength=part.mesh.n_vertices
        )
        pinched = ends > 2
        if not pinched.any():
            return part
        keep[part.origin[pinched]] = False


def _largest_component(mesh: Mesh, keep: np.ndarray) -> Part:
    faces = mesh.faces[keep[mesh.faces].all(axis=1)]
    if faces.shape[0] == 0:
        raise ValueError("the cut removes every face of the mesh")
    n = mesh.n_vertices
    label = vertex_components(n, unique_edges(faces))
    used = np.zeros(n, dtype=bool)
    used[faces.reshape(-1)] = True
    sizes = np.bincount(label[used], minlength=label.max() + 1)
    best = int(np.argmax(sizes))  # argmax takes the first of equal sizes: the lowest label
    faces = faces[label[faces[:, 0]] == best]
    origin = np.unique(faces.reshape(-1))
    new = np.full(n, -1, dtype=np.int64)
    new[origin] = np.arange(origin.size)
    return Part(Mesh(mesh.vertices[origin], new[faces]), origin.astype(np.int64))


def plane_normal(i: int) -> np.ndarray:
    """The cut-plane normal of pair ``i``: azimuth ``i * 67.5°`` about the y axis (so 8 pairs
    see 8 different directions, both sides of each shape included), tilted ±30° from the
    horizontal plane on alternate pairs."""
    az = np.deg2rad(67.5 * i)
    el = np.deg2rad(30.0 if i % 2 else -30.0)
    return np.array([np.cos(el) * np.cos(az), np.sin(el), np.cos(el) * np.sin(az)])


def cut_by_plane(mesh: Mesh, normal, fraction: float) -> Part:
    """``mesh`` without the ``fraction`` of its vertices farthest along ``normal``."""
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"the cut fraction must be in (0, 1), got {fraction}")
    h = mesh.vertices @ np.asarray(normal, dtype=np.float64)
    order = np.argsort(h, kind="stable")
    keep = np.zeros(mesh.n_vertices, dtype=bool)
    keep[order[: round((1.0 - fraction) * mesh.n_vertices)]] = True
    return submesh(mesh, keep)


def edge_graph(mesh: Mesh):
    """The edge graph of ``mesh`` (symmetric CSR, edge lengths in the mesh's units)."""
    f = mesh.faces
    rows = f[:, [0, 1, 2]].reshape(-1)
    cols = f[:, [1, 2, 0]].reshape(-1)
    w = np.linalg.norm(mesh.vertices[rows] - mesh.vertices[cols], axis=1)
    n = mesh.n_vertices
    g = coo_matrix((w, (rows, cols)), shape=(n, n)).tocsr()
    return g.maximum(g.T)


def hole_centres(mesh: Mesh, n_holes: int, *, skip: int = 5) -> np.ndarray:
    """``n_holes`` farthest-point samples (edge-graph geodesics) seeded at the vertex nearest
    the centroid, after the first ``skip`` samples."""
    g = edge_graph(mesh)
    start = int(np.argmin(np.linalg.norm(mesh.vertices - mesh.vertices.mean(0), axis=1)))
    dist = dijkstra(g, indices=start)
    picked = []
    for _ in range(skip + n_holes):
        far = np.where(np.isfinite(dist), dist, -1.0)
        v = int(np.argmax(far))
        picked.append(v)
        dist = np.minimum(dist, dijkstra(g, indices=v))
    return np.array(picked[skip:], dtype=np.int64)


def punch_holes(mesh: Mesh, n_holes: int, hole_area: float = 0.03) -> Part:
    """``mesh`` without ``n_holes`` geodesic discs (:func:`hole_centres`), each of radius
    ``sqrt(hole_area * area / pi)`` (a flat disc of ``hole_area`` of the surface)."""
    centres = hole_centres(mesh, n_holes)
    radius = np.sqrt(hole_area * mesh.area / np.pi)
    d = dijkstra(edge_graph(mesh), indices=centres, limit=radius).min(axis=0)
    return submesh(mesh, ~(d <= radius))


def _condition(name: str, mesh_a: Mesh, mesh_b: Mesh, i: int) -> tuple[Part | None, Part | None]:
    if name == "cut30":
        return cut_by_plane(mesh_a, plane_normal(i), 0.3), None
    if name == "cut50":
        return cut_by_plane(mesh_a, plane_normal(i), 0.5), None
    if name == "holes":
        return punch_holes(mesh_a, 3 + i % 3), None
    if name == "cut_both":
        n = plane_normal(i)
        return cut_by_plane(mesh_a, n, 0.3), cut_by_plane(mesh_b, -n, 0.3)
    raise ValueError(
        f"unknown partial condition {name!r}; the conditions are {', '.join(CONDITIONS)}"
    )


def write_partial_sets(
    sources, out, *, conditions=tuple(CONDITIONS), max_pairs: int | None = 8, reverse: bool = True
) -> list[Path]:
    """Write the partial benchmark sets of each ``.vts`` data-set folder in ``sources`` to
    ``out`` (see the module notes); returns the data-set folders written.

    Parameters
    ----------
    sources : path or list of paths
        Data-set folders with ``pairs.txt`` and ``corres/*.vts``.
    out : path
        Created if missing; one subfolder ``SOURCE_CONDITION`` (and ``..._rev``) per set.
    conditions : sequence of str
        Keys of :data:`CONDITIONS`.
    max_pairs : int or None
        The first pairs of each ``pairs.txt`` only.
    reverse : bool
        Also write the whole → part sets (not for ``cut_both``, which is symmetric).
    """
    jobs = set_jobs(
        sources, conditions, CONDITIONS, max_pairs, vts_needed="partial sets need .vts pairs"
    )

    def names(src: Path, cond: str) -> list[str]:
        rev = [f"{src.name}_{cond}_rev"] if reverse and cond != "cut_both" else []
        return [f"{src.name}_{cond}", *rev]

    return write_sets(out, jobs, conditions, names, _write_condition)


def _write_condition(pairs, cond: str, folders: list[Path]) -> bool:
    """The pairs of one condition into ``folders`` (the forward set, then the reverse one);
    True: every pair is kept."""
    for d in folders:
        shutil.rmtree(d, ignore_errors=True)
        (d / "corres").mkdir(parents=True)
        (d / "origin").mkdir()
    lines = []
    for i, pair in enumerate(pairs):
        ma, mb = load_mesh(pair.a), load_mesh(pair.b)
        ai, bi = pair.ground_truth(ma.n_vertices, mb.n_vertices)
        pa, pb = _condition(cond, ma, mb, i)
        na = f"{i:02d}_{pair.a.stem}_{cond}"
        nb = f"{i:02d}_{pair.b.stem}" + (f"_{cond}" if pb is not None else "")
        ia = pa.inverse(ma.n_vertices)[ai] if pa is not None else ai
        ib = pb.inverse(mb.n_vertices)[bi] if pb is not None else bi
        ok = (ia >= 0) & (ib >= 0)
        parts = {
            name: (part.mesh if part is not None else mesh, part, idx[ok])
            for name, mesh, part, idx in ((na, ma, pa, ia), (nb, mb, pb, ib))
        }
        for d in folders:
            for name, (mesh, part, idx) in parts.items():
                write_off(d / f"{name}.off", mesh)
                write_vts(d / "corres" / f"{name}.vts", idx)
                if part is not None:
                    write_vts(d / "origin" / f"{name}.vts", part.origin)
        lines.append((na, nb))
    (folders[0] / "pairs.txt").write_text("".join(f"{x} {y}\n" for x, y in lines))
    if len(folders) > 1:
        (folders[1] / "pairs.txt").write_text("".join(f"{y} {x}\n" for x, y in lines))
    return True


def add_parser(sub) -> None:
    """Register ``hope-rs partial-set``."""
    p = add_set_parser(
        sub, "partial-set",
        help="write partial-shape benchmark sets (cuts, holes) for hope-rs bench",
        description="Cuts and holes of the pairs of .vts data sets, with their ground truth, "
        "in the layout hope-rs bench reads. ",
        conditions=CONDITIONS,
        sources_help=".vts data-set folders (e.g. DATA/faust_r,DATA/tosca_r)",
        max_pairs=8, func=cmd_partial_set,
    )  # fmt: skip
    p.add_argument("--no-reverse", action="store_true", help="skip the whole -> part sets")


def cmd_partial_set(args) -> int:
    return run_set_command(args, write_partial_sets, reverse=not args.no_reverse)
