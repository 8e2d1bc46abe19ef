"""Benchmark sets with a perturbed target built from a ``.vts`` data set (``hope-rs perturb-set``).

Each benchmark pair (A, B) of a source data set gives one pair per condition, A unchanged and
B perturbed, the ground truth carried over:

* ``noise02``, ``noise05``: B with Gaussian noise of 0.2% / 0.5% of its sqrt(area) added to
  every coordinate of every vertex (a generator seeded by the pair's index: the same set every
  time). The vertices keep their numbering.
* ``shortcuts``: B with topological shortcuts, as where a hand touches a thigh in a scan:
  up to ``MAX_WELDS`` welds, each merging two vertices closer than ``WELD_SPACE`` sqrt(area)
  in space but farther than ``WELD_SURFACE`` sqrt(area) along the surface (edge-graph
  geodesics) into one at their midpoint. Pairs whose B has fewer than ``MIN_WELDS`` such welds
  are left out.
* ``reversed``: the pair matched the other way (B as A, A as B), both unchanged: the same
  shapes with the roles swapped, pairs no setting was chosen on.

A welded B has fewer vertices than the clean one: ``origin/NAME.vts`` gives, per vertex of the
welded mesh, its 1-based vertex on the clean B, ``welds/NAME.txt`` the welded vertex pairs of
the clean B (1-based, one pair a line), and ``clean/NAME.off`` the clean B. A map onto the
welded B is scored on the clean B (:func:`clean_errors`), a welded vertex counting as either
of its two.

Welds are chosen by rule, not drawn: ``CANDIDATES`` farthest-point samples of B (seeded at the
vertex nearest the centroid), each with its spatially nearest vertex among those far enough
along the surface; the closest such pairs first, a weld skipped when one of its vertices lies
within ``WELD_SPACE`` sqrt(area) of an earlier weld's.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from ..geometry.mesh import Mesh, load_mesh
from .derived_sets import (
    add_set_parser,
    run_set_command,
    set_jobs,
    write_off,
    write_sets,
    write_vts,
)
from .evaluate import geodesic_errors, load_vts
from .partial import edge_graph

__all__ = [
    "PERTURBATIONS",
    "Welded",
    "add_noise",
    "clean_errors",
    "read_clean",
    "shortcut_errors",
    "weld_shortcuts",
    "write_perturbed_sets",
]

#: Condition name → what it does to B (see the module notes).
PERTURBATIONS = {
    "noise02": "B with Gaussian vertex noise of 0.2% of sqrt(area)",
    "noise05": "B with Gaussian vertex noise of 0.5% of sqrt(area)",
    "shortcuts": "B with 3-10 topological shortcuts (welds; a pair whose B takes fewer than 3 "
    "is left out)",
    "reversed": "the pair matched the other way (B as A, A as B)",
}

#: Most welds per shape, and the fewest for a pair to be kept.
MAX_WELDS, MIN_WELDS = 10, 3
#: A weld's two vertices: at most this far apart in space, at least ``WELD_SURFACE`` apart
#: along the surface (sqrt(area) units).
WELD_SPACE, WELD_SURFACE = 0.1, 0.3
#: Farthest-point samples of B that are tried as one end of a weld.
CANDIDATES = 400


def add_noise(mesh: Mesh, level: float, seed: int) -> Mesh:
    """``mesh`` with Gaussian noise of standard deviation ``level * sqrt(area)`` added to each
    coordinate (``numpy.random.default_rng(seed)``)."""
    rng = np.random.default_rng(seed)
    v = mesh.vertices + rng.normal(0.0, level * mesh.scale, size=mesh.vertices.shape)
    return Mesh(v, mesh.faces)


class Welded:
    """A mesh with some vertex pairs welded into one.

    Attributes
    ----------
    mesh : Mesh
        The welded mesh (each pair's second vertex removed, its faces moved onto the first, the
        first at the pair's midpoint).
    origin : (n_welded,) int64 ndarray
        Per vertex of ``mesh``, its vertex on the clean mesh (for a weld, the pair's first).
    welds : (m, 2) int64 ndarray
        The welded pairs of the clean mesh.
    """

    def __init__(self, mesh: Mesh, welds: np.ndarray):
        welds = np.asarray(welds, dtype=np.int64).reshape(-1, 2)
        n = mesh.n_vertices
        into = np.arange(n)
        into[welds[:, 1]] = welds[:, 0]
        v = mesh.vertices.copy()
        v[welds[:, 0]] = 0.5 * (v[welds[:, 0]] + v[welds[:, 1]])
        keep = np.ones(n, dtype=bool)
        keep[welds[:, 1]] = False
        self.origin = np.flatnonzero(keep).astype(np.int64)
        new = np.full(n, -1, dtype=np.int64)
        new[self.origin] = np.arange(self.origin.size)
        self.mesh = Mesh(v[self.origin], new[into[mesh.faces]])
        self.welds = welds
        #: Per clean vertex, its vertex on the welded mesh.
        self.inverse = new[into]


def weld_shortcuts(mesh: Mesh) -> Welded:
    """The welds of ``mesh`` by the module's rule (possibly none)."""
    s = mesh.scale
    g = edge_graph(mesh)
    start = int(np.argmin(np.linalg.norm(mesh.vertices - mesh.vertices.mean(0), axis=1)))
    dist = dijkstra(g, indices=start)
    picked: list[int] = []
    for _ in range(min(CANDIDATES, mesh.n_vertices)):
        v = int(np.argmax(np.where(np.isfinite(dist), dist, -1.0)))
        picked.append(v)
        dist = np.minimum(dist, dijkstra(g, indices=v))
    samples = np.array(picked, dtype=np.int64)
    geo = dijkstra(g, indices=samples, limit=WELD_SURFACE * s)  # inf beyond the limit
    tree = cKDTree(mesh.vertices)
    cand = []
    for row, v in enumerate(samples):
        near = np.array(tree.query_ball_point(mesh.vertices[v], WELD_SPACE * s), dtype=np.int64)
        near = near[~np.isfinite(geo[row, near])]
        if near.size:
            d = np.linalg.norm(mesh.vertices[near] - mesh.vertices[v], axis=1)
            k = int(np.argmin(d))
            cand.append((float(d[k]), int(v), int(near[k])))
    cand.sort()
    chosen: list[tuple[int, int]] = []
    for _, i, j in cand:
        if len(chosen) == MAX_WELDS:
            break
        used = np.array([x for w in chosen for x in w], dtype=np.int64)
        if used.size:
            p = mesh.vertices[[i, j]]
            gap = np.linalg.norm(p[:, None, :] - mesh.vertices[used][None, :, :], axis=2)
            if gap.min() < WELD_SPACE * s:
                continue
        chosen.append((i, j))
    return Welded(mesh, np.array(chosen, dtype=np.int64))


def clean_errors(
    clean_b: Mesh, welded_map, origin, welds, a_idx, b_idx, *, method: str = "surface"
) -> np.ndarray:
    """Errors (÷ sqrt(area) of the clean B) of a map onto a welded B, on the clean B: each
    matched vertex read through ``origin`` (0-based), a weld's vertex counting as whichever
    of its two clean vertices is nearer the true match. ``b_idx``: the true matches on the
    clean B; one on a weld (as ``origin`` reads a welded ground truth: the weld's first
    vertex) counts as either of its two as well."""
    m = np.asarray(origin, dtype=np.int64)[np.asarray(welded_map, dtype=np.int64)]
    a_idx, b_idx = np.asarray(a_idx, dtype=np.int64), np.asarray(b_idx, dtype=np.int64)
    e = geodesic_errors(clean_b, m, a_idx=a_idx, b_idx=b_idx, method=method)
    welds = np.asarray(welds, dtype=np.int64).reshape(-1, 2)
    if not welds.size:
        return e
    # Each clean vertex's weld partner (itself when not welded), both ways.
    other = np.arange(clean_b.n_vertices)
    other[welds[:, 0]], other[welds[:, 1]] = welds[:, 1], welds[:, 0]
    src = m[a_idx]
    for swap_src, swap_dst in ((True, False), (False, True), (True, True)):
        s2 = other[src] if swap_src else src
        d2 = other[b_idx] if swap_dst else b_idx
        use = np.flatnonzero((s2 != src) | (d2 != b_idx))
        if use.size:
            # s2 is indexed by the scored pair, so the pairs in ``use`` are its own indices.
            e2 = geodesic_errors(clean_b, s2, a_idx=use, b_idx=d2[use], method=method)
            e[use] = np.minimum(e[use], e2)
    return e


def shortcut_errors(
    folder, name: str, welded_map, a_idx, b_idx, *, method: str = "surface"
) -> np.ndarray | None:
    """:func:`clean_errors` of a map onto the shape ``name`` of a ``shortcuts`` set in
    ``folder`` (``b_idx``: the ground truth on the welded shape, as its ``.vts`` gives it), or
    ``None`` when that shape is not welded."""
    clean = read_clean(folder, name)
    if clean is None:
        return None
    mesh, origin, welds = clean
    bi = origin[np.asarray(b_idx, dtype=np.int64)]
    return clean_errors(mesh, welded_map, origin, welds, a_idx, bi, method=method)


def _perturb(cond: str, mesh_b: Mesh, i: int) -> tuple[Mesh, Welded | None]:
    if cond == "reversed":
        return mesh_b, None
    if cond == "noise02":
        return add_noise(mesh_b, 0.002, i), None
    if cond == "noise05":
        return add_noise(mesh_b, 0.005, i), None
    if cond == "shortcuts":
        w = weld_shortcuts(mesh_b)
        return w.mesh, w
    raise ValueError(
        f"unknown perturbation {cond!r}; the perturbations are {', '.join(PERTURBATIONS)}"
    )


def write_perturbed_sets(
    sources, out, *, conditions=tuple(PERTURBATIONS), max_pairs: int | None = None
) -> list[Path]:
    """Write the perturbed sets of each ``.vts`` data-set folder in ``sources`` to ``out``, one
    subfolder ``SOURCE_CONDITION`` per set (see the module notes; a set without a pair is not
    written); returns the folders written.
    ``max_pairs``: the first pairs of each ``pairs.txt`` only."""
    jobs = set_jobs(
        sources, conditions, PERTURBATIONS, max_pairs,
        what="perturbation", vts_needed="use a set with .vts pairs",
    )  # fmt: skip
    return write_sets(
        out, jobs, conditions, lambda src, c: [f"{src.name}_{c}"],
        lambda pairs, c, folders: _write_set(pairs, c, folders[0]) > 0,
    )  # fmt: skip


def _write_set(pairs, cond: str, d: Path) -> int:
    """Writes the pairs of one condition into ``d``; returns how many were kept."""
    shutil.rmtree(d, ignore_errors=True)
    (d / "corres").mkdir(parents=True)
    if cond == "shortcuts":
        for sub in ("origin", "welds", "clean"):
            (d / sub).mkdir()
    lines = []
    for i, pair in enumerate(pairs):
        pa, pb_path = pair.a, pair.b
        ma, mb = load_mesh(pa), load_mesh(pb_path)
        ai, bi = pair.ground_truth(ma.n_vertices, mb.n_vertices)
        if cond == "reversed":
            pa, pb_path, ma, mb, ai, bi = pb_path, pa, mb, ma, bi, ai
        pb, welded = _perturb(cond, mb, i)
        if welded is not None and len(welded.welds) < MIN_WELDS:
            continue
        suffix = "" if cond == "reversed" else f"_{cond}"
        na, nb = f"{i:02d}_{pa.stem}", f"{i:02d}_{pb_path.stem}{suffix}"
        write_off(d / f"{na}.off", ma)
        write_vts(d / "corres" / f"{na}.vts", ai)
        write_off(d / f"{nb}.off", pb)
        if welded is None:
            write_vts(d / "corres" / f"{nb}.vts", bi)
        else:
            # The true match on the welded mesh; scoring reads the clean B (clean_errors).
            write_vts(d / "corres" / f"{nb}.vts", welded.inverse[bi])
            write_vts(d / "origin" / f"{nb}.vts", welded.origin)
            write_off(d / "clean" / f"{nb}.off", mb)
            (d / "welds" / f"{nb}.txt").write_text(
                "".join(f"{x + 1} {y + 1}\n" for x, y in welded.welds)
            )
        lines.append((na, nb))
    (d / "pairs.txt").write_text("".join(f"{x} {y}\n" for x, y in lines))
    return len(lines)


def read_clean(folder, name: str) -> tuple[Mesh, np.ndarray, np.ndarray] | None:
    """``(clean B, origin, welds)`` (0-based) of a welded shape of a ``shortcuts`` set, or
    ``None`` for a shape that is not welded."""
    folder = Path(folder)
    path = folder / "clean" / f"{name}.off"
    if not path.exists():
        return None
    origin = load_vts(folder / "origin" / f"{name}.vts")
    text = (folder / "welds" / f"{name}.txt").read_text().split()
    welds = np.array(text, dtype=np.int64).reshape(-1, 2) - 1
    return load_mesh(path), origin, welds


def add_parser(sub) -> None:
    """Register ``hope-rs perturb-set``."""
    add_set_parser(
        sub, "perturb-set",
        help="write perturbed-target benchmark sets (noise, shortcuts) for hope-rs bench",
        description="The pairs of .vts data sets with B perturbed, ground truth carried over, "
        "in the layout hope-rs bench reads. ",
        conditions=PERTURBATIONS,
        sources_help=".vts data-set folders (e.g. DATA/faust_r,DATA/tosca_r)",
        max_pairs=None, func=cmd_perturb_set,
    )  # fmt: skip


def cmd_perturb_set(args) -> int:
    shortcuts = "shortcuts" in (c.strip() for c in args.conditions.split(","))
    note = (
        " (a shortcuts set is scored on the clean B by hope_rs.evaluation.perturbed.clean_errors)"
        if shortcuts
        else ""
    )
    return run_set_command(args, write_perturbed_sets, note=note)
