"""Mixed-resolution benchmark sets built from the shared data sets (``hope-rs resolution-set``).

Each benchmark pair (A, B) of a source data set (``.vts`` pairs, or an identity set such as
faust_reg) gives one pair per condition, with the ground truth carried over by rule:

* ``sub1``, ``sub2``: B subdivided once / twice (each face into four at its edge midpoints,
  about 4x / 16x the vertices); the original vertices come first, so B's ground truth holds;
* ``dec1k``: A clustered to about 1,000 vertices (the sites of a uniform grid, every other
  vertex merged into the site nearest it along the surface by edge collapses that keep a
  manifold: :mod:`hope_rs.geometry.collapse`); each kept vertex is a vertex of A, and the
  ground truth is the lines whose point of A is kept (exact, nothing carried to a neighbour);

and for each, the same pairs the other way round (``*_rev``: ``match(B', A)`` for
``sub*``, ``match(B, A')`` for ``dec1k``).

The output folder holds one data-set folder per (source, condition) in the ``pairs.txt`` +
``corres/NAME.vts`` layout ``hope-rs bench`` reads. Nothing is random.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from ..geometry.collapse import collapse_to_count
from ..geometry.mesh import Mesh, load_mesh
from ..geometry.subdivide import subdivide
from .derived_sets import (
    add_set_parser,
    run_set_command,
    set_jobs,
    write_off,
    write_sets,
    write_vts,
)
from .partial import _largest_component

__all__ = ["RESOLUTION_CONDITIONS", "write_resolution_sets"]

#: Condition name -> what it changes (see the module notes).
RESOLUTION_CONDITIONS = {
    "sub1": "B subdivided once (about 4x its vertices)",
    "sub2": "B subdivided twice (about 16x its vertices)",
    "dec1k": "A clustered to about 1,000 vertices",
}

#: Vertex count of the ``dec1k`` condition's clustered A.
DECIMATED_VERTICES = 1000


def _condition(cond: str, ma: Mesh, mb: Mesh, ai: np.ndarray, bi: np.ndarray):
    """(A', B', ground truth of A', of B') of one pair under ``cond``."""
    if cond in ("sub1", "sub2"):
        return ma, subdivide(mb, int(cond[-1])), ai, bi
    if cond == "dec1k":
        c = collapse_to_count(ma, DECIMATED_VERTICES)
        if c is None:
            raise ValueError(
                f"a mesh of {ma.n_vertices} vertices cannot be clustered to about "
                f"{DECIMATED_VERTICES} with faces left"
            )
        # An input of several pieces keeps its largest only.
        part = _largest_component(c.mesh, np.ones(c.mesh.n_vertices, dtype=bool))
        on_part = np.full(ma.n_vertices, -1, dtype=np.int64)
        on_part[c.sites[part.origin]] = np.arange(part.origin.size)
        keep = on_part[ai] >= 0
        return part.mesh, mb, on_part[ai[keep]], bi[keep]
    raise ValueError(
        f"unknown resolution condition {cond!r}; the conditions are "
        f"{', '.join(RESOLUTION_CONDITIONS)}"
    )


def write_resolution_sets(
    sources, out, *, conditions=tuple(RESOLUTION_CONDITIONS), max_pairs: int | None = 3
) -> list[Path]:
    """Write the mixed-resolution sets of each data-set folder in ``sources`` to ``out`` (see
    the module notes); returns the data-set folders written (``SOURCE_CONDITION`` and
    ``SOURCE_CONDITION_rev`` each). ``max_pairs``: the first pairs of each source only."""
    jobs = set_jobs(sources, conditions, RESOLUTION_CONDITIONS, max_pairs)
    return write_sets(
        out, jobs, conditions, lambda src, c: [f"{src.name}_{c}", f"{src.name}_{c}_rev"],
        _write_condition,
    )  # fmt: skip


def _write_condition(pairs, cond: str, folders: list[Path]) -> bool:
    """The pairs of one condition into ``folders`` (forward, then reverse); True: every pair
    is kept."""
    for d in folders:
        shutil.rmtree(d, ignore_errors=True)
        (d / "corres").mkdir(parents=True)
    lines = []
    for i, pair in enumerate(pairs):
        ma, mb = load_mesh(pair.a), load_mesh(pair.b)
        # Every vertex of an identity set is scored (no subsample).
        ai, bi = pair.ground_truth(ma.n_vertices, mb.n_vertices, max_points=None)
        pa, pb, ia, ib = _condition(cond, ma, mb, ai, bi)
        na = f"{i:02d}_{pair.a.stem}" + ("_dec1k" if cond == "dec1k" else "")
        nb = f"{i:02d}_{pair.b.stem}" + ("" if cond == "dec1k" else f"_{cond}")
        for d in folders:
            for name, mesh, idx in ((na, pa, ia), (nb, pb, ib)):
                write_off(d / f"{name}.off", mesh)
                write_vts(d / "corres" / f"{name}.vts", idx)
        lines.append((na, nb))
    (folders[0] / "pairs.txt").write_text("".join(f"{x} {y}\n" for x, y in lines))
    (folders[1] / "pairs.txt").write_text("".join(f"{y} {x}\n" for x, y in lines))
    return True


def add_parser(sub) -> None:
    """Register ``hope-rs resolution-set``."""
    add_set_parser(
        sub, "resolution-set",
        help="write mixed-resolution benchmark sets (subdivided, decimated) for hope-rs bench",
        description="Subdivided and decimated copies of the pairs of data sets, with their "
        "ground truth, in the layout hope-rs bench reads. ",
        conditions=RESOLUTION_CONDITIONS,
        sources_help="data-set folders (e.g. DATA/faust_r,DATA/faust_reg)",
        max_pairs=3, func=cmd_resolution_set,
    )  # fmt: skip


def cmd_resolution_set(args) -> int:
    return run_set_command(args, write_resolution_sets)
