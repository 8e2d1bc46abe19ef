"""Vertices that no face uses, and small loose pieces: left out of the match, given a map
afterwards.

A mesh may carry vertices in no face (a part cut out of a scan with the removed faces'
vertices kept, points left over from cleaning), and a scan may carry loose pieces of a few
triangles (debris). Neither has a surface to match by: a piece of debris has long open
edges for its size, no place in the body's spectrum and nothing to correspond to, and a few
of them would make a closed body count as a part, fill the spectral basis with their own
constant functions and send body vertices onto them. So the pair is matched on the vertices
of the pieces that matter (:func:`referenced`): each piece (connected component) holding
less than ``MatchConfig.min_piece`` of a mesh's area is left out, however many there are
(never its largest piece, and only when that holds at least half the area: a mesh of many
pieces is not debris around a body), and so are the vertices in no face.
Before that, a surface split along seams (texture or normal seams, every edge of a triangle
soup: boundary edges lying exactly on other edges) is closed, and one stored twice (a
double-sided export) made one: the copies of a vertex there are welded to its first copy
(:func:`~hope_rs.geometry.mesh.seam_welds`), so the other copies are left out as vertices in
no face.
The result is expanded to the meshes' own numbering (:meth:`Referenced.expand`): a left-out
vertex of B is never a target, a welded copy on A takes its first copy's image and
confidence, and another left-out vertex of A takes the image of the nearest (in space) kept
vertex of A, with confidence 0.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.mesh import Mesh, face_pieces, seam_welds, unique_rows
from .landmarks import check_landmarks
from .result import MatchResult

__all__ = ["Referenced", "body_vertices", "referenced"]


def _index(keep: np.ndarray | None, n: int) -> np.ndarray:
    """Per vertex of a mesh of ``n`` vertices, its index among ``keep`` (-1: not kept;
    ``None``: every vertex kept)."""
    out = np.full(n, -1, dtype=np.int64)
    kept = np.arange(n) if keep is None else keep
    out[kept] = np.arange(kept.size)
    return out


def _nearest(points: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """Index of the point nearest each query. Where the squared distances overflow (a vertex
    beyond 1e154), the largest coordinate difference decides instead of the Euclidean
    distance, since the k-d tree finds no Euclidean neighbour there."""
    tree = cKDTree(points)
    near = tree.query(queries)[1]
    far = near == len(points)
    if far.any():
        near[far] = tree.query(queries[far], p=np.inf)[1]
    return near


def _loose(mesh: Mesh, min_piece: float) -> np.ndarray:
    """Bool per face: in a piece (faces joined across edges two faces share,
    :func:`~hope_rs.geometry.mesh.face_pieces`: a loose piece, or a fin or flap hanging off
    the surface by an edge of three faces) holding less than ``min_piece`` of the mesh's
    area. The largest piece always stays, and nothing goes when it holds less than half the
    area."""
    faces = mesh.faces
    piece = face_pieces(faces)
    if min_piece <= 0.0 or piece.min() == piece.max():
        return np.zeros(len(faces), dtype=bool)
    # A face listed twice (double-sided on the same vertices) counts once.
    _, once = unique_rows(np.sort(faces, axis=1), return_index=True)
    area = np.bincount(piece[once], mesh.face_areas[once], minlength=piece.max() + 1)
    if area.max() < 0.5 * area.sum():  # no body for the pieces to be debris around
        return np.zeros(len(faces), dtype=bool)
    small = (area < min_piece * area.sum()) & (area < area.max())
    return small[piece]


def body_vertices(mesh: Mesh, min_piece: float) -> np.ndarray:
    """Bool per vertex: used by a face outside the small loose pieces (:func:`_loose`), its
    seams welded first, or welded to such a vertex: the vertices a match gives a map."""
    weld = seam_welds(mesh)
    welded = Mesh(mesh.vertices, weld[mesh.faces])
    return _used(mesh.n_vertices, welded.faces[~_loose(welded, min_piece)])[weld]


def _used(n: int, faces: np.ndarray) -> np.ndarray:
    """Bool per vertex of ``n``: used by one of ``faces``."""
    used = np.zeros(n, dtype=bool)
    used[faces.ravel()] = True
    return used


@dataclasses.dataclass(frozen=True)
class _Compact:
    """A mesh without the vertices a match leaves out (:func:`_compact`)."""

    mesh: Mesh
    keep: np.ndarray  # the vertices kept, in the input numbering
    weld: np.ndarray | None  # per vertex, the copy it is welded to (``None``: none welded)
    loose: int  # how many vertices of small loose pieces went


def _compact(mesh: Mesh, min_piece: float) -> _Compact | None:
    """``mesh`` with its seams welded (:func:`~hope_rs.geometry.mesh.seam_welds`), without
    its small loose pieces (:func:`_loose`) and the vertices no face uses; ``None`` when it
    keeps every vertex."""
    weld = seam_welds(mesh)
    welded = bool((weld != np.arange(mesh.n_vertices)).any())
    if welded:
        mesh = Mesh(mesh.vertices, weld[mesh.faces])
    loose = _loose(mesh, min_piece)
    faces = mesh.faces[~loose]
    used = _used(mesh.n_vertices, faces)  # the pieces found once, not again by body_vertices
    if used.all():
        return None
    in_loose = _used(mesh.n_vertices, mesh.faces[loose])
    keep = np.flatnonzero(used)
    return _Compact(
        Mesh(mesh.vertices[keep], _index(keep, mesh.n_vertices)[faces]),
        keep,
        weld if welded else None,
        int((in_loose & ~used).sum()),
    )


@dataclasses.dataclass(frozen=True)
class Referenced:
    """Where the vertices of A and B that faces use sit in the meshes' own numbering:
    ``keep_a[j]`` is vertex ``j`` of the compact A (``None``: every vertex of A)."""

    n_a: int
    n_b: int
    keep_a: np.ndarray | None
    keep_b: np.ndarray | None
    points_a: np.ndarray  # A's vertices, to give its unused ones the nearest used one's image
    points_b: np.ndarray
    #: The compact meshes (``None``: that mesh as it was).
    mesh_a: Mesh | None = None
    mesh_b: Mesh | None = None
    #: How many vertices of A and of B were in small loose pieces.
    loose: tuple[int, int] = (0, 0)
    #: Per vertex of A and of B, the copy it is welded to along a seam (``None``: none).
    weld_a: np.ndarray | None = None
    weld_b: np.ndarray | None = None

    def note(self) -> str:
        """What was left out, for the shapes' log line ("" when nothing)."""
        parts = []
        for name, keep, n, loose, weld in (
            ("A", self.keep_a, self.n_a, self.loose[0], self.weld_a),
            ("B", self.keep_b, self.n_b, self.loose[1], self.weld_b),
        ):
            if keep is None:
                continue
            welded = 0 if weld is None else int(np.sum(weld != np.arange(n)))
            if welded:
                parts.append(f"{welded} of {name}'s vertices welded to their copies along seams")
            if loose:
                parts.append(f"{loose} of {name}'s vertices in small loose pieces left out")
            if n - keep.size > loose + welded:
                parts.append(
                    f"{n - keep.size - loose - welded} of {name}'s vertices in no face left out"
                )
        return "; ".join(parts)

    def init_in(self, init: np.ndarray) -> np.ndarray:
        """A given initial map in the compact numbering: a vertex of A in no face is dropped,
        an image in no face moves to the nearest vertex of B that faces use."""
        f = init if self.keep_a is None else init[self.keep_a]
        if self.weld_b is not None:
            f = self.weld_b[f]
        idx = _index(self.keep_b, self.n_b)[f]
        off = idx < 0
        if off.any():
            assert self.keep_b is not None  # only B's unused vertices have no index
            idx[off] = _nearest(self.points_b[self.keep_b], self.points_b[f[off]])
        return idx

    def landmarks_in(self, landmarks: np.ndarray | None) -> np.ndarray | None:
        """Landmarks in the compact numbering; one on a vertex left out is refused."""
        if landmarks is None:
            return None
        out = landmarks.copy()
        for col, keep, n, name, weld in (
            (0, self.keep_a, self.n_a, "A", self.weld_a),
            (1, self.keep_b, self.n_b, "B", self.weld_b),
        ):
            if keep is None:
                continue
            given = landmarks[:, col] if weld is None else weld[landmarks[:, col]]
            mapped = _index(keep, n)[given]
            if (mapped < 0).any():
                v = int(landmarks[np.argmax(mapped < 0), col])
                raise ValueError(
                    f"landmark vertex {v} of {name} is in no face (give a vertex of the "
                    "surface) or in a small loose piece left out of the match (give a vertex "
                    "of the surface, or keep every piece with MatchConfig(min_piece=0))"
                )
            out[:, col] = mapped
        if self.weld_a is not None or self.weld_b is not None:
            # Copies of one vertex (welded along a seam) given different partners contradict.
            for col, name in ((0, "A"), (1, "B")):
                order = np.lexsort((out[:, 1 - col], out[:, col]))
                key, other = out[order, col], out[order, 1 - col]
                clash = np.flatnonzero((key[1:] == key[:-1]) & (other[1:] != other[:-1]))
                if clash.size:
                    i, j = order[clash[0]], order[clash[0] + 1]
                    raise ValueError(
                        f"landmarks {landmarks[i].tolist()} and {landmarks[j].tolist()} pair "
                        f"copies of one vertex of {name} (welded along a seam) with different "
                        "vertices; give one of them"
                    )
            checked = check_landmarks(out, None, None)  # rows now given twice count once
            assert checked is not None
            out = checked
        return out

    def _map_out(self, f: np.ndarray) -> np.ndarray:
        """A compact map in the meshes' own numbering."""
        g = f if self.keep_b is None else self.keep_b[f]
        if self.keep_a is None:
            return g.astype(np.int64)
        out = np.empty(self.n_a, dtype=np.int64)
        out[self.keep_a] = g
        unused = np.setdiff1d(np.arange(self.n_a), self.keep_a, assume_unique=True)
        out[unused] = g[_nearest(self.points_a[self.keep_a], self.points_a[unused])]
        if self.weld_a is not None:
            out = out[self.weld_a]  # a welded copy: its first copy's image
        return out

    def expand(self, res: MatchResult, landmarks: np.ndarray | None = None) -> MatchResult:
        """``res`` (of the compact shapes) in the meshes' own numbering; each of the caller's
        ``landmarks`` (meshes' numbering) keeps its own vertex of B where the map sends its
        vertex of A to a welded copy of it (the same point: the compact shapes know one)."""
        conf = res.confidence
        if conf is not None and self.keep_a is not None:
            full = np.zeros(self.n_a)
            full[self.keep_a] = conf
            conf = full if self.weld_a is None else full[self.weld_a]

        def out(g: np.ndarray) -> np.ndarray:
            f = self._map_out(g)
            if landmarks is not None and len(landmarks) and self.weld_b is not None:
                la, lb = landmarks[:, 0], landmarks[:, 1]
                same = self.weld_b[f[la]] == self.weld_b[lb]
                f[la[same]] = lb[same]
            return f

        return dataclasses.replace(
            res,
            map=out(res.map),
            init_map=out(res.init_map),
            hope_map=None if res.hope_map is None else out(res.hope_map),
            confidence=conf,
        )


def referenced(ma: Mesh, mb: Mesh, min_piece: float = 0.0) -> Referenced | None:
    """The two meshes without their vertices in no face and their smallest loose pieces
    (together under ``min_piece`` of the area, ``MatchConfig.min_piece``) (``mesh_a``,
    ``mesh_b``) and how to carry maps between the numberings; ``None`` when nothing is left
    out."""
    ca, cb = _compact(ma, min_piece), _compact(mb, min_piece)
    if ca is None and cb is None:
        return None
    return Referenced(
        ma.n_vertices,
        mb.n_vertices,
        None if ca is None else ca.keep,
        None if cb is None else cb.keep,
        ma.vertices,
        mb.vertices,
        None if ca is None else ca.mesh,
        None if cb is None else cb.mesh,
        (0 if ca is None else ca.loose, 0 if cb is None else cb.loose),
        None if ca is None else ca.weld,
        None if cb is None else cb.weld,
    )
