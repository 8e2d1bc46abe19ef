"""Triangle meshes: validated arrays, and loading from OFF/OBJ/PLY/STL without reordering."""

from __future__ import annotations

import os
from functools import cached_property

import numpy as np

from ._validate import as_faces, as_vertices


class Mesh:
    """A triangle mesh given by ``vertices`` (N, 3) and ``faces`` (M, 3, 0-based).

    Vertex order is kept exactly as given: ground-truth correspondences index into it.
    Degenerate faces, duplicate or unreferenced vertices and several components are allowed.

    Parameters
    ----------
    vertices : (N, 3) array_like of float
        Finite coordinates.
    faces : (M, 3) array_like of int
        At least one triangle; indices in ``[0, N)``.
    """

    def __init__(self, vertices, faces):
        v = as_vertices(vertices)
        f = as_faces(faces, v.shape[0])
        if v.shape[0] == 0:
            raise ValueError("the mesh has no vertices")
        if f.shape[0] == 0:
            raise ValueError("the mesh has no faces; HOPE needs a triangle mesh, not a point cloud")
        v.flags.writeable = False
        f.flags.writeable = False
        self.vertices = v
        self.faces = f

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
        if not s > 0:
            raise ValueError("the mesh has zero surface area (all faces are degenerate)")
        return s

    @cached_property
    def vertex_areas(self) -> np.ndarray:
        """Barycentric (one third of incident face area) area of each vertex."""
        out = np.zeros(self.n_vertices)
        np.add.at(out, self.faces.reshape(-1), np.repeat(self.face_areas / 3.0, 3))
        return out


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """The undirected edges of ``faces``, each once as ``(low, high)``, sorted."""
    f = np.asarray(faces)
    return np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1), axis=0)


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Load a triangle mesh from OFF, OBJ, PLY or STL, keeping the file's vertex order.

    OFF files are parsed directly; other formats go through trimesh with ``process=False`` (its
    default merges and reorders vertices, which breaks ground-truth indices). Polygons with more
    than three corners are fan-triangulated.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file cannot be read as a triangle mesh.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no such mesh file: {path!r}")
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".off":
            v, f = _read_off(path)
        else:
            v, f = _read_with_trimesh(path)
    except (ValueError, IndexError, UnicodeDecodeError, OSError) as e:
        raise ValueError(f"cannot read {path!r} as a triangle mesh: {e}") from None
    return Mesh(v, f)


def _read_off(path: str) -> tuple[np.ndarray, np.ndarray]:
    with open(path, encoding="utf-8", errors="strict") as fh:
        tokens_lines = [ln.split("#", 1)[0].split() for ln in fh]
    lines = [t for t in tokens_lines if t]
    if not lines or not lines[0][0].upper().endswith("OFF"):
        raise ValueError("not an OFF file (first line must be 'OFF')")
    head = lines[0][1:] if len(lines[0]) > 1 else lines[1]
    body = lines[1:] if len(lines[0]) > 1 else lines[2:]
    if len(head) < 2:
        raise ValueError("OFF header must give vertex and face counts")
    nv, nf = int(head[0]), int(head[1])
    if nv < 0 or nf < 0 or len(body) < nv + nf:
        raise ValueError(f"OFF header promises {nv} vertices and {nf} faces, file is shorter")
    v = np.array([ln[:3] for ln in body[:nv]], dtype=np.float64).reshape(nv, 3)
    tris = []
    for ln in body[nv : nv + nf]:
        k = int(ln[0])
        idx = [int(x) for x in ln[1 : 1 + k]]
        if k < 3 or len(idx) != k:
            raise ValueError(f"malformed OFF face line: {' '.join(ln)!r}")
        tris.extend([idx[0], idx[i], idx[i + 1]] for i in range(1, k - 1))
    return v, np.array(tris, dtype=np.int64).reshape(-1, 3)


def _read_with_trimesh(path: str) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    try:
        m = trimesh.load(path, process=False, force="mesh")
    except Exception as e:  # noqa: BLE001 - trimesh raises many types for bad files
        raise ValueError(str(e) or type(e).__name__) from None
    if not hasattr(m, "faces") or len(getattr(m, "faces", [])) == 0:
        raise ValueError("the file holds no triangle faces")
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)
