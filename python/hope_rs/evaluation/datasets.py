"""Data-set adapters: the pairs of a folder of meshes and the ground truth of each pair.

A data set is a folder of meshes with one of two kinds of ground truth:

* ``.vts`` landmarks: ``pairs.txt`` lists one ``SOURCE TARGET`` pair of mesh names per line and
  ``corres/NAME.vts`` holds one 1-based vertex index per line; line i of the source's file and
  line i of the target's file are corresponding vertices (the FAUST/TOSCA remeshed convention).
* identity: no ``pairs.txt`` and every mesh has the same vertex count; vertex i of one mesh
  corresponds to vertex i of every other, and every unordered pair of meshes is a pair.
"""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..geometry.mesh import load_mesh
from .evaluate import load_vts

MESH_SUFFIXES = (".off", ".obj", ".ply")
#: Identity pairs larger than this are scored on an evenly spaced subsample of this many
#: vertices (one surface geodesic per wrong vertex would otherwise dominate the run time).
MAX_IDENTITY_POINTS = 7000

#: How a data-set folder lists pairs, for the messages of commands that found none.
GIVE_PAIRS = (
    "give it a pairs.txt of 'SOURCE TARGET' lines, or two or more meshes with one vertex count "
    "(identity ground truth)"
)


@dataclass(frozen=True)
class Pair:
    """One benchmark pair: source mesh A, target mesh B and where their ground truth is."""

    dataset: str
    a: Path
    b: Path
    a_vts: Path | None = None  #: None for identity ground truth
    b_vts: Path | None = None

    @property
    def name(self) -> str:
        return f"{self.a.stem}->{self.b.stem}"

    def ground_truth(
        self, n_a: int, n_b: int, *, max_points: int | None = MAX_IDENTITY_POINTS
    ) -> tuple[np.ndarray, np.ndarray]:
        """Scored correspondences ``(a_idx, b_idx)`` (0-based) for meshes of n_a and n_b vertices.

        For identity ground truth with more than ``max_points`` vertices, an evenly spaced
        subsample of ``max_points`` vertices (always the same ones) is returned.
        """
        if self.a_vts is None:
            if n_a != n_b:
                raise ValueError(
                    f"{self.name}: identity ground truth needs equal vertex counts, got {n_a} and "
                    f"{n_b}; give pairs.txt and corres/*.vts files for this data set"
                )
            idx = np.arange(n_a)
            if max_points is not None and n_a > max_points:
                idx = np.unique(np.linspace(0, n_a - 1, max_points).round().astype(np.int64))
            return idx, idx
        assert self.b_vts is not None  # given with a_vts
        ai, bi = load_vts(self.a_vts), load_vts(self.b_vts)
        if ai.size != bi.size:
            raise ValueError(
                f"{self.name}: {self.a_vts.name} has {ai.size} landmarks but {self.b_vts.name} "
                f"has {bi.size}; line i of both files must be the same landmark"
            )
        for idx, n, path in ((ai, n_a, self.a_vts), (bi, n_b, self.b_vts)):
            if idx.size and idx.max() >= n:
                raise ValueError(
                    f"{path} refers to vertex {idx.max() + 1} (1-based) but its mesh has only {n} "
                    "vertices; is it the .vts file of this mesh?"
                )
        return ai, bi


def _meshes(folder: Path) -> dict[str, Path]:
    return {p.stem: p for p in sorted(folder.iterdir()) if p.suffix.lower() in MESH_SUFFIXES}


def _vertex_count(path: Path) -> int:
    if path.suffix.lower() == ".off":  # the header says it; no need to parse the whole file
        with open(path) as fh:
            tokens: list[str] = []
            for line in fh:
                tokens += line.split("#", 1)[0].split()
                if len(tokens) >= 2:
                    break
        try:
            return int(tokens[1])  # "OFF" (or "COFF", "NOFF") then the vertex count
        except (IndexError, ValueError):
            raise ValueError(f"cannot read the OFF header of {str(path)!r}") from None
    return load_mesh(path).n_vertices


def pairs_of(folder: str | os.PathLike) -> list[Pair]:
    """Every benchmark pair of a data-set folder (see the module notes for the two layouts).

    Raises
    ------
    ValueError
        If the folder has no meshes, ``pairs.txt`` names a missing mesh or ``.vts`` file, or a
        folder without ``pairs.txt`` has meshes of different vertex counts.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"data set {str(folder)!r} is not a folder")
    meshes = _meshes(folder)
    if not meshes:
        raise ValueError(f"no meshes ({', '.join(MESH_SUFFIXES)}) in {str(folder)!r}")
    listing = folder / "pairs.txt"
    if not listing.exists():
        counts = {name: _vertex_count(p) for name, p in meshes.items()}
        if len(set(counts.values())) > 1:
            raise ValueError(
                f"{str(folder)!r} has no pairs.txt and its meshes have different vertex counts "
                f"({min(counts.values())}..{max(counts.values())}), so identity ground truth "
                "cannot apply; add pairs.txt (one 'SOURCE TARGET' per line) and corres/NAME.vts"
            )
        return [
            Pair(folder.name, meshes[a], meshes[b]) for a, b in itertools.combinations(meshes, 2)
        ]
    out = []
    for n, line in enumerate(listing.read_text().splitlines(), 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        if len(words) != 2:
            raise ValueError(f"{listing}:{n}: expected 'SOURCE TARGET', got {line.strip()!r}")
        for w in words:
            if w not in meshes:
                raise ValueError(f"{listing}:{n}: no mesh named {w!r} in {str(folder)!r}")
        vts = []
        for w in words:
            v = folder / "corres" / f"{w}.vts"
            if not v.exists():
                raise ValueError(f"{listing}:{n}: ground truth {str(v)!r} is missing")
            vts.append(v)
        out.append(Pair(folder.name, meshes[words[0]], meshes[words[1]], *vts))
    return out


def datasets_in(root: str | os.PathLike) -> list[Path]:
    """The data-set folders of ``root``: ``root`` itself if it holds meshes, else its
    subfolders that do (sorted by name)."""
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"{str(root)!r} is not a folder of data sets")
    if _meshes(root):
        return [root]
    found = [d for d in sorted(root.iterdir()) if d.is_dir() and _meshes(d)]
    if not found:
        raise ValueError(f"no meshes in {str(root)!r} or its subfolders")
    return found
