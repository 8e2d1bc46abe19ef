"""Triangle meshes: validated arrays, and loading from OFF/OBJ/PLY/STL without reordering.

The readers are strict: a file is read whole, its counts must agree with its body, and any
problem is reported in one line naming the file and, where there is one, the line (``cannot read
'x.off': line 12: expected 3 coordinates, got 2``), before any matching work starts.

STL stores a soup of separate triangles, with no shared vertices and no vertex order, so its
exactly coincident corners are merged (first appearance first): vertex indices of an STL mesh
refer to that merged mesh. OFF, OBJ and PLY keep the file's vertex order, which ground-truth
correspondences index into; vertices they duplicate at one position are kept apart (where
that splits the surface along a seam, for texture coordinates or normals, :func:`~hope_rs.match`
welds the copies for the match and answers in the file's numbering; ``merge_duplicates=True``
merges them in the mesh, renumbering it).
"""

from __future__ import annotations

import os
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .._validate import as_faces, as_vertices
from .orientation import manifold_pairs
from .readers import READERS, LineError, fan, one_line

__all__ = [
    "SAFE_COORDINATES",
    "SUPPORTED_FORMATS",
    "Mesh",
    "as_mesh",
    "boundary_edge_lengths",
    "boundary_edges",
    "face_pieces",
    "load_mesh",
    "merge_coincident_vertices",
    "parse_mesh",
    "read_mesh_file",
    "scale_exponent",
    "seam_edges",
    "seam_welds",
    "unique_edges",
    "unique_rows",
    "vertex_components",
]

#: File extensions :func:`load_mesh` reads.
SUPPORTED_FORMATS = tuple(READERS)

#: Default of :func:`scale_exponent`'s ``safe``: meshes whose largest coordinate magnitude lies
#: in this range are used at their own scale, so that their maps do not change at all.
SAFE_COORDINATES = (2.0**-20, 2.0**40)


class Mesh:
    """A triangle mesh given by ``vertices`` (N, 3) and ``faces`` (M, 3, 0-based).

    Vertex order is kept exactly as given: ground-truth correspondences index into it.
    Degenerate faces, duplicate or unreferenced vertices and several components are allowed
    (:func:`~hope_rs.match` leaves vertices in no face out of the match: never a target on
    B, on A the image of the nearest vertex faces use, with confidence 0);
    so is any face orientation (:class:`~hope_rs.Shape` orients its own copy, see
    :mod:`hope_rs.geometry.orientation`). The arrays are copied: the mesh holds read-only copies, and
    later changes to the caller's arrays do not reach it.

    Parameters
    ----------
    vertices : (N, 3) array_like of float
        Finite coordinates.
    faces : (M, 3) array_like of int
        At least one triangle; indices in ``[0, N)``.
    """

    def __init__(self, vertices, faces):
        v = as_vertices(vertices, copy=True)
        if v.shape[0] == 0:
            raise ValueError("the mesh has no vertices")
        f = as_faces(faces, v.shape[0], copy=True)
        if f.shape[0] == 0:
            raise ValueError("the mesh has no faces; HOPE needs a triangle mesh, not a point cloud")
        v.flags.writeable = False
        f.flags.writeable = False
        self.vertices = v
        self.faces = f

    def __reduce__(self):
        # Built again by the constructor: an unpickled mesh holds read-only copies too.
        return (Mesh, (self.vertices, self.faces))

    def __repr__(self) -> str:
        return f"Mesh(n_vertices={self.n_vertices}, n_faces={self.n_faces})"

    @property
    def n_vertices(self) -> int:
        return self.vertices.shape[0]

    @property
    def n_faces(self) -> int:
        return self.faces.shape[0]

    @cached_property
    def face_areas(self) -> np.ndarray:
        """Area of each triangle."""
        p = self.vertices[self.faces]
        return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)

    @cached_property
    def area(self) -> float:
        """Total surface area."""
        return float(self.face_areas.sum())

    @cached_property
    def scale(self) -> float:
        """``sqrt(area)``, the unit every scale-free quantity of the package is measured in."""
        s = float(np.sqrt(self.area))
        if not (s > 0 and np.isfinite(s)):
            what = "zero" if not s > 0 else "an overflowing"
            raise ValueError(
                f"the mesh has {what} surface area (all faces are degenerate, or the "
                "coordinates are too small or large for double precision: rescale the mesh)"
            )
        return s

    @cached_property
    def vertex_areas(self) -> np.ndarray:
        """Barycentric (one third of incident face area) area of each vertex."""
        out = np.zeros(self.n_vertices)
        np.add.at(out, self.faces.reshape(-1), np.repeat(self.face_areas / 3.0, 3))
        return out


def as_mesh(x, name: str = "mesh") -> Mesh:
    """``x`` as a :class:`Mesh`: a Mesh itself, a ``(vertices, faces)`` pair, a mesh file's
    path (read by :func:`load_mesh`), or any object with ``vertices`` and ``faces`` (such as
    ``trimesh.Trimesh``, used as stored: trimesh's processing is not applied again) or
    ``vertices`` and ``triangles`` (such as ``open3d.geometry.TriangleMesh``). A
    ``trimesh.Scene`` of one mesh placed once (as a ``.glb`` file loads) is that mesh, placed
    as the scene places it. Polygons of more than three corners (an (M, k) array, or a list
    of index lists of mixed lengths) are fan-triangulated, as the file readers do; the
    vertices keep their numbering.

    Raises
    ------
    TypeError
        If ``x`` is none of these (the message says what to pass instead).
    ValueError
        If the arrays do not make a valid mesh.
    """
    if isinstance(x, Mesh):
        return x
    if isinstance(x, (str, os.PathLike)):
        return load_mesh(x)
    if isinstance(x, (tuple, list)) and len(x) == 2:
        return Mesh(x[0], _triangles(x[1], name))
    geometry = getattr(x, "geometry", None)
    if isinstance(geometry, dict) and hasattr(x, "dump"):  # a trimesh.Scene
        if len(geometry) != 1:
            raise TypeError(
                f"{name} is a scene of {len(geometry)} meshes (as a .glb or multi-object file "
                "loads in trimesh); pass one of them (scene.geometry[key], placed as stored) or "
                "all as one mesh (trimesh.load(path, force='mesh'))"
            )
        # One mesh placed at several nodes is as many bodies as placements.
        placed = len(x.graph.nodes_geometry) if hasattr(x, "graph") else 1
        if placed > 1:
            raise TypeError(
                f"{name} is a scene placing its one mesh at {placed} nodes (so {placed} "
                "bodies); pass the mesh (next(iter(scene.geometry.values())), placed as "
                "stored) or all placements as one mesh (scene.to_geometry())"
            )
        whole = x.to_geometry() if hasattr(x, "to_geometry") else x.dump(concatenate=True)
        return as_mesh(whole, name)
    for faces in ("faces", "triangles"):
        if hasattr(x, "vertices") and hasattr(x, faces):
            return Mesh(np.asarray(x.vertices), _triangles(np.asarray(getattr(x, faces)), name))
    raise TypeError(
        f"{name} must be a hope_rs.Mesh, a (vertices, faces) pair, a mesh file's path or an "
        f"object with .vertices and .faces (such as trimesh.Trimesh), got {type(x).__name__}"
    )


def _triangles(faces, name: str):
    """``faces`` with polygons of more than three corners fan-triangulated (corner 0 with each
    pair of consecutive others), each face's triangles in its place; anything else as given,
    for :class:`Mesh` to check."""
    if isinstance(faces, (list, tuple)) and faces:
        sizes = {len(f) if hasattr(f, "__len__") else -1 for f in faces}
        if -1 not in sizes and len(sizes) > 1:  # polygons of mixed sizes
            if min(sizes) < 3:
                raise ValueError(f"{name}: a face has {min(sizes)} corners; faces need 3 or more")
            return np.concatenate([_triangles(np.asarray([f]), name) for f in faces])
    arr = faces if isinstance(faces, np.ndarray) else None
    if arr is None:
        try:
            arr = np.asarray(faces)
        except (ValueError, TypeError):
            return faces
    if arr.ndim != 2 or arr.shape[1] <= 3:
        return faces
    return fan(arr)


def _face_edges(faces: np.ndarray) -> np.ndarray:
    """The three edges of every face as ``(low, high)`` rows, an edge once per face."""
    f = np.asarray(faces)
    return np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)


def _edge_counts(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct ``(low, high)`` face edges, sorted, and how many faces hold each.

    Each edge is one int64 key ``low * n + high`` (n above every index), whose sorted order is
    the rows' lexicographic order: a 1-D sort, many times faster than ``np.unique(axis=0)``."""
    e = _face_edges(faces)
    if e.size == 0 or e.min() < 0:
        u, count = np.unique(e, axis=0, return_counts=True)
        return u, count
    n = int(e.max()) + 1
    e64 = e.astype(np.int64, copy=False)
    keys, count = np.unique(e64[:, 0] * n + e64[:, 1], return_counts=True)
    return np.stack([keys // n, keys % n], axis=1).astype(e.dtype, copy=False), count


def unique_rows(rows: np.ndarray, **returns) -> tuple:
    """``np.unique(rows, axis=0, **returns)`` for an (m, c) array of non-negative integers,
    through one int64 key per row when the keys fit (their sorted order is the rows'
    lexicographic order, and np.unique sorts stably when it returns indices): the same
    result, from a 1-D sort many times faster. Always a tuple, the distinct rows first."""
    r = np.asarray(rows)
    m, c = r.shape
    n = int(r.max()) + 1 if r.size else 1
    if r.size == 0 or r.min() < 0 or c * (n - 1).bit_length() > 63:
        out = np.unique(r, axis=0, **returns)
        return out if isinstance(out, tuple) else (out,)
    key = r[:, 0].astype(np.int64)
    for j in range(1, c):
        key = key * n + r[:, j].astype(np.int64)
    first = returns.get("return_index", False)
    keys, *rest = np.unique(
        key, return_index=True, **{k: v for k, v in returns.items() if k != "return_index"}
    )
    index = rest[0]
    distinct = r[index]
    out = [distinct]
    if first:
        out.append(index)
    out += rest[1:]
    return tuple(out)


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """The undirected edges of ``faces``, each once as ``(low, high)``, sorted."""
    return _edge_counts(faces)[0]


def vertex_components(n: int, edges: np.ndarray) -> np.ndarray:
    """Component label (int64) per vertex of the graph of ``n`` vertices and ``edges``
    ((m, 2) vertex pairs); a vertex in no edge is a component of its own."""
    graph = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1].astype(np.int64)


def face_pieces(faces: np.ndarray) -> np.ndarray:
    """Piece label (int64) per face: faces are joined across an edge that exactly two distinct
    faces share, so a flap or fin hanging off a surface by an edge of three or more faces (or
    by a vertex) is a piece of its own; a face listed again on the same vertices is in its
    first listing's piece."""
    f = np.sort(np.asarray(faces, dtype=np.int64), axis=1)
    if len(f) == 0:
        return np.zeros(0, dtype=np.int64)
    distinct, which = unique_rows(f, return_inverse=True)
    m = len(distinct)
    # A face with a repeated corner has no surface and shares nothing: it is a piece alone
    # (its edge would count as a third face on the edge it lies on).
    on = np.flatnonzero((distinct[:, 0] != distinct[:, 1]) & (distinct[:, 1] != distinct[:, 2]))
    a, b, _ = manifold_pairs(distinct[on], np.ones(on.size, dtype=bool))
    graph = sp.coo_matrix((np.ones(a.size), (on[a], on[b])), shape=(m, m))
    return connected_components(graph, directed=False)[1].astype(np.int64)[which.reshape(-1)]


def boundary_edges(faces: np.ndarray) -> np.ndarray:
    """The edges of one face only (a surface's boundary), each once as ``(low, high)``, sorted."""
    u, count = _edge_counts(faces)
    return u[count == 1]


def boundary_edge_lengths(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(edges, lengths)``: :func:`boundary_edges` of ``faces`` and their lengths."""
    b = boundary_edges(faces)
    return b, np.linalg.norm(vertices[b[:, 0]] - vertices[b[:, 1]], axis=1)


def scale_exponent(vertices: np.ndarray, *, safe: tuple[float, float] = SAFE_COORDINATES) -> int:
    """The ``k`` for which ``vertices * 4**k`` is the copy a :class:`~hope_rs.Shape` works on.

    Multiplying by a power of 4 is exact in floating point and commutes with ``+ - * /`` and
    ``sqrt``, so matching the scaled copy gives the map of a mesh of ordinary size. ``k = 0``
    when the largest coordinate magnitude lies in ``safe`` (the mesh is used as given);
    otherwise ``k`` brings it into ``[1, 4)``. Scaling a mesh by any power of 4 outside
    ``safe`` therefore gives the map of the same mesh scaled into ``[1, 4)``.
    """
    v = np.asarray(vertices, dtype=np.float64)
    top = float(np.max(np.abs(v))) if v.size else 0.0
    if top == 0.0 or not np.isfinite(top) or safe[0] <= top <= safe[1]:
        return 0
    e = np.frexp(top)[1]  # top = m * 2**e with m in [0.5, 1): top in [1, 4) iff e in {1, 2}
    return -((int(e) - 1) // 2)


def merge_coincident_vertices(
    vertices: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices at exactly the same position (``-0.0`` equals ``0.0``), keeping the first
    appearance of each position and that order: returns the new vertices and faces."""
    v = np.asarray(vertices, dtype=np.float64) + 0.0  # turns -0.0 into 0.0
    new_id, keep = _coincident_ids(v)
    return v[keep], new_id[np.asarray(faces, dtype=np.int64)]


def _coincident_ids(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the merged id of each vertex, the vertex kept for each merged id), first appearance
    first."""
    _, first, inverse = np.unique(v, axis=0, return_index=True, return_inverse=True)
    by_first = np.argsort(first, kind="stable")
    new_id = np.empty_like(by_first)
    new_id[by_first] = np.arange(by_first.size)
    return new_id[inverse.reshape(-1)], first[by_first]


def _seams(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The unique edges of ``mesh`` that lie exactly on another edge (their two ends at the
    other's two positions) where that splits or doubles the surface: a boundary edge (a
    seam), or an edge of another connected piece (a second copy of the surface); as a bool
    per edge, with the unique edges, and per vertex its position's id and per id the first
    vertex there (:func:`_coincident_ids`). ``None`` when no two vertices coincide."""
    new_id, keep = _coincident_ids(mesh.vertices + 0.0)
    if keep.size == mesh.n_vertices:
        return None
    edges, count = _edge_counts(mesh.faces)
    proper = edges[:, 0] != edges[:, 1]
    edges, count = edges[proper], count[proper]
    if edges.size == 0:
        return None
    merged = np.sort(new_id[edges], axis=1)
    _, where, merged_count = unique_rows(merged, return_inverse=True, return_counts=True)
    where = where.reshape(-1)
    piece = vertex_components(mesh.n_vertices, edges)[edges[:, 0]]
    low = np.full(merged_count.size, piece.max() + 1)
    high = np.full(merged_count.size, -1)
    np.minimum.at(low, where, piece)
    np.maximum.at(high, where, piece)
    # An edge of length 0 lies on nothing: its ends are one position.
    shared = (merged_count[where] > 1) & (merged[:, 0] != merged[:, 1])
    return shared & ((count == 1) | (low[where] != high[where])), edges, new_id, keep


def seam_edges(mesh: Mesh) -> int:
    """How many edges of ``mesh`` lie exactly on another edge where that splits the surface
    (a boundary edge: texture or normal seams, every edge of a triangle soup) or stores it
    twice (an edge of another piece: a double-sided export with each face reversed on its
    own copies of the vertices), although merging the coincident vertices would make it one
    surface."""
    seams = _seams(mesh)
    return 0 if seams is None else int(seams[0].sum())


def seam_welds(mesh: Mesh) -> np.ndarray:
    """Per vertex of ``mesh``, the vertex it is welded to (itself when none): the ends of the
    edges of :func:`seam_edges` at one position are welded to the first of them in the
    numbering, which closes seams and makes a surface stored twice one; other vertices at
    that position (in no face, or of a piece touching there) and coincident vertices
    elsewhere (a surface touching itself at a point, or folded onto itself within one
    piece) stay apart."""
    out = np.arange(mesh.n_vertices)
    seams = _seams(mesh)
    if seams is None or not seams[0].any():
        return out
    seam, edges, new_id, keep = seams
    ends = np.unique(edges[seam].ravel())
    first = np.full(keep.size, mesh.n_vertices)
    np.minimum.at(first, new_id[ends], ends)
    out[ends] = first[new_id[ends]]
    return out


def load_mesh(path: str | os.PathLike, *, merge_duplicates: bool | None = None) -> Mesh:
    """Load a triangle mesh from OFF, OBJ, PLY, STL or GLB, keeping the file's vertex order.

    Polygons with more than three corners are fan-triangulated. OFF may be any of its ASCII
    variants (``OFF``, ``COFF``, ``NOFF``, ``STOFF``...: colours, normals and texture
    coordinates are skipped), PLY ASCII or binary, STL ASCII or binary; a binary glTF
    (``.glb``) is read by trimesh, every mesh of its scene placed as the scene places it.

    Parameters
    ----------
    path : str or path-like
    merge_duplicates : bool or None, keyword-only
        Merge vertices at exactly the same position (first appearance first, see
        :func:`merge_coincident_vertices`). ``None`` (default): for STL only, which stores
        every triangle separately and has no vertex order; OFF, OBJ and PLY keep their
        numbering, also where coincident vertices split the surface along a seam (as texture
        coordinates or normals do; :func:`~hope_rs.match` welds those copies itself, see
        :func:`seam_welds`). ``True`` merges for every
        format (indices then refer to the merged mesh), ``False`` never (an STL file stays a
        soup of triangles).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file cannot be read as a triangle mesh (one line, naming the file and, where
        it helps, the line).
    """
    return parse_mesh(path, read_mesh_file(path), merge_duplicates=merge_duplicates)


def read_mesh_file(path: str | os.PathLike) -> bytes:
    """The bytes of a mesh file, after the checks of :func:`load_mesh` (it exists, is a
    regular file, has a known suffix); parse them with :func:`parse_mesh`."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        if os.path.isdir(path):
            raise ValueError(f"cannot read {path!r}: it is a folder, not a mesh file")
        if os.path.exists(path):
            raise ValueError(f"cannot read {path!r}: not a regular file (a device or a pipe)")
        raise FileNotFoundError(f"no such mesh file: {path!r}")
    _format(path)
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except OSError as e:
        raise ValueError(f"cannot read {path!r}: {e.strerror or e}") from None


def _format(path: str) -> str:
    """The reader's key of ``path`` (its lower-case suffix), or a one-line error."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in READERS:
        raise ValueError(
            f"cannot read {path!r}: unknown mesh format {ext or '(no extension)'!r}; "
            f"supported: {', '.join(SUPPORTED_FORMATS)}"
        )
    return ext


def parse_mesh(
    path: str | os.PathLike,
    data: bytes,
    *,
    merge_duplicates: bool | None = None,
) -> Mesh:
    """The mesh in ``data``, the bytes of the file ``path`` (its suffix picks the reader;
    see :func:`load_mesh` for ``merge_duplicates`` and the errors)."""
    path = os.fspath(path)
    ext = _format(path)
    try:
        if not data.strip():
            raise ValueError("the file is empty")
        v, f = READERS[ext](data)
        merge = ext == ".stl" if merge_duplicates is None else bool(merge_duplicates)
        if merge:
            v, f = merge_coincident_vertices(v, f)
        mesh = Mesh(v, f)
    except LineError as e:
        raise ValueError(f"cannot read {path!r}: line {e.line}: {e.message}") from None
    except (ValueError, TypeError, OverflowError) as e:
        raise ValueError(f"cannot read {path!r} as a triangle mesh: {one_line(e)}") from None
    return mesh
