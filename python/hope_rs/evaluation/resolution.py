"""Mixed-resolution benchmark sets built from the shared data sets (``hope-rs resolution-set``).

Each benchmark pair (A, B) of a source data set (``.vts`` pairs, or an identity set such as
faust_reg) gives one pair per condition, with the ground truth carried over by rule:

* ``sub1``, ``sub2``: B subdivided once / twice (each face into four at its edge midpoints,
  about 4x / 16x the vertices); the original vertices come first, so B's ground truth holds;
* ``dec1k``: A clustered to about 1,000 vertices (uniform-grid vertex clustering, each kept
  vertex a vertex of A; its largest connected component); a ground-truth point of A is
  carried to the nearest kept vertex;

and for each, the same pairs the other way round (``*_rev``: ``match(B', A)`` for
``sub*``, ``match(B, A')`` for ``dec1k``).

The output folder holds one data-set folder per (source, condition) in the ``pairs.txt`` +
``corres/NAME.vts`` layout ``hope-rs bench`` reads. Nothing is random.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.coarsen import coarse_to_count
from ..geometry.mesh import Mesh, load_mesh
from ..geometry.subdivide import subdivide
from .datasets import pairs_of
from .partial import _largest_component, _write_off, _write_vts

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
        c = coarse_to_count(ma, DECIMATED_VERTICES)
        if c is None:
            raise ValueError(f"a mesh of {ma.n_vertices} vertices cannot be clustered to fewer")
        # Clustering leaves isolated vertices and small islands: the largest component only.
        part = _largest_component(c.mesh, np.ones(c.mesh.n_vertices, dtype=bool))
        nearest = cKDTree(part.mesh.vertices).query(ma.vertices[ai])[1]
        return part.mesh, mb, nearest.astype(np.int64), bi
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
    if isinstance(sources, (str, os.PathLike)):
        sources = [sources]
    bad = [c for c in conditions if c not in RESOLUTION_CONDITIONS]
    if bad:
        raise ValueError(
            f"unknown condition {', '.join(bad)}; the conditions are "
            f"{', '.join(RESOLUTION_CONDITIONS)}"
        )
    jobs = [(Path(src), pairs_of(src)[:max_pairs]) for src in sources]
    out = Path(out)
    written = []
    for src, pairs in jobs:
        for cond in conditions:
            names = [f"{src.name}_{cond}", f"{src.name}_{cond}_rev"]
            # Written to scratch folders, moved into place once complete.
            scratch = [out / f".{n}.tmp" for n in names]
            try:
                _write_condition(pairs, cond, scratch)
                for tmp, n in zip(scratch, names):
                    if (out / n).exists():
                        shutil.rmtree(out / n)
                    tmp.rename(out / n)
                    written.append(out / n)
            finally:
                for tmp in scratch:
                    shutil.rmtree(tmp, ignore_errors=True)
    return written


def _write_condition(pairs, cond: str, folders: list[Path]) -> None:
    """The pairs of one condition into ``folders`` (forward, then reverse)."""
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
                _write_off(d / f"{name}.off", mesh)
                _write_vts(d / "corres" / f"{name}.vts", idx)
        lines.append((na, nb))
    (folders[0] / "pairs.txt").write_text("".join(f"{x} {y}\n" for x, y in lines))
    (folders[1] / "pairs.txt").write_text("".join(f"{y} {x}\n" for x, y in lines))


def add_parser(sub) -> None:
    """Register ``hope-rs resolution-set``."""
    p = sub.add_parser(
        "resolution-set",
        help="write mixed-resolution benchmark sets (subdivided, decimated) for hope-rs bench",
        description="Subdivided and decimated copies of the pairs of data sets, with their "
        "ground truth, in the layout hope-rs bench reads. "
        + "; ".join(f"{k}: {v}" for k, v in RESOLUTION_CONDITIONS.items()),
    )
    p.add_argument("out", help="output folder (created)")
    p.add_argument(
        "--from", dest="sources", required=True,
        help="comma-separated data-set folders (e.g. DATA/faust_r,DATA/faust_reg)",
    )  # fmt: skip
    p.add_argument("--conditions", default=",".join(RESOLUTION_CONDITIONS), help="comma-separated")
    p.add_argument("--max-pairs", type=int, default=3, help="first N pairs of each set (default 3)")
    p.set_defaults(func=cmd_resolution_set)


def cmd_resolution_set(args) -> int:
    if args.max_pairs < 1:
        raise ValueError(f"--max-pairs must be at least 1, got {args.max_pairs}")
    written = write_resolution_sets(
        [s.strip() for s in args.sources.split(",") if s.strip()], args.out,
        conditions=[c.strip() for c in args.conditions.split(",")], max_pairs=args.max_pairs,
    )  # fmt: skip
    print(
        f"{len(written)} data sets written to {args.out}; run: hope-rs bench {args.out} --out RESULTS"
    )
    return 0
