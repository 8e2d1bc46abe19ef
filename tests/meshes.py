"""Generated test meshes and maps, and the helpers that build, move, write or read them."""

import hashlib
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

import hope_rs
from hope_rs.cli import main
from hope_rs.geometry.coarsen import Coarse
from hope_rs.geometry.collapse import shortest_path_tree


def bumped(p: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The convex-hull triangulation of the unit vectors ``p``, faces oriented outwards, with
    the sphere bent by the smooth field of the 6 x 3 frequencies ``w`` and stretched along y
    and z; returns vertices and faces."""
    faces = ConvexHull(p).simplices.astype(np.int64)
    c = p[faces].mean(axis=1)
    nrm = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    flip = np.einsum("ij,ij->i", nrm, c) < 0
    faces[flip] = faces[flip][:, ::-1]
    r = 1.0 + 0.25 * np.tanh(np.sin(p @ w.T * 2.0).sum(axis=1) / 2)
    return p * r[:, None] * np.array([1.0, 1.3, 0.8]), faces


def bumpy_sphere(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random Delaunay-like triangulation of a perturbed sphere: no symmetries to confuse a
    matcher, and a different triangulation for every seed."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return bumped(p, rng.normal(size=(6, 3)))


def sphere_points(n: int) -> np.ndarray:
    """``n`` unit vectors spread evenly on the sphere (a Fibonacci spiral), no two alike."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    rho = np.sqrt(1.0 - z * z)
    return np.c_[rho * np.cos(phi), rho * np.sin(phi), z]


def inverse(perm: np.ndarray) -> np.ndarray:
    """The inverse permutation: ``inverse(perm)[perm[i]] == i``."""
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.size)
    return inv


def relabel(faces: np.ndarray, perm: np.ndarray) -> np.ndarray:
    """Faces of the mesh whose new vertex i is old vertex perm[i]."""
    return inverse(perm)[faces]


def signed_volume(v: np.ndarray, f: np.ndarray) -> float:
    """Volume enclosed by the triangles ``f`` (positive when they face outwards)."""
    p = v[f]
    return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6)


def random_rigid(rng) -> tuple[np.ndarray, np.ndarray]:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q, rng.normal(size=3) * 5


def isometric_copy(v, f, perm, rot, scale: float, shift):
    """B = the mesh (v, f) relabelled (B's vertex i is vertex ``perm[i]``), rotated by ``rot``,
    scaled and shifted; returns B and the true map A -> B."""
    vb = scale * v[perm] @ np.asarray(rot).T + shift
    return hope_rs.Mesh(vb, relabel(f, perm)), inverse(perm)


def random_isometric_copy(v, f, rng):
    """:func:`isometric_copy` with a random relabelling, rigid motion and scale in [0.5, 2]."""
    perm = rng.permutation(v.shape[0])
    rot, shift = random_rigid(rng)
    return isometric_copy(v, f, perm, rot, rng.uniform(0.5, 2.0), shift)


def moved_copy(a, seed: int):
    """B = the hope_rs.Mesh A relabelled, rotated, scaled by 1.7 and shifted; returns B and A's
    vertex v's image in B."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(a.n_vertices)  # B's vertex i is A's vertex perm[i]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    return isometric_copy(a.vertices, a.faces, perm, q, 1.7, 1.0)


def corrupted(truth: np.ndarray, share: float, n_b: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """``truth`` with a random ``share`` of its vertices (returned as the mask ``bad``) sent to
    random vertices of B (``n_b`` of them); returns the map and ``bad``."""
    bad = rng.random(truth.size) < share
    f = truth.copy()
    f[bad] = rng.integers(0, n_b, bad.sum())
    return f, bad


def renumber(mesh, perm, face_order, turn):
    """The same mesh with its vertices relabelled (new vertex i = old vertex ``perm[i]``), its
    faces reordered (new face j = old face ``face_order[j]``) and face j's corners rotated
    ``turn[j]`` places (orientation kept)."""
    f = relabel(mesh.faces, np.asarray(perm))[np.asarray(face_order)]
    f = np.take_along_axis(f, (np.asarray(turn)[:, None] + np.arange(3)) % 3, axis=1)
    return hope_rs.Mesh(mesh.vertices[perm], f)


def renumbered(mesh, rng) -> tuple:
    """:func:`renumber` with a random vertex relabelling, face order and rotations; returns the
    new mesh and ``perm``."""
    perm = rng.permutation(mesh.n_vertices)
    face_order = rng.permutation(mesh.n_faces)
    turn = rng.integers(0, 3, mesh.n_faces)
    return renumber(mesh, perm, face_order, turn), perm


def drifted(a, truth: np.ndarray, centre: int, radius: float) -> np.ndarray:
    """``truth`` with a ball around vertex ``centre`` mapped one vertex along (each vertex to
    the image of the next vertex of one of its faces): a patch the overlaps cannot see."""
    region = np.linalg.norm(a.vertices - a.vertices[centre], axis=1) < radius * a.scale
    step = np.arange(a.n_vertices)
    step[a.faces[:, 0]] = a.faces[:, 1]
    f = truth.copy()
    f[region] = truth[step[region]]
    return f


def write_off(path, v, f) -> None:
    """An ASCII OFF file of vertices ``v`` and triangles ``f``, coordinates written exactly."""
    lines = [f"OFF\n{len(v)} {len(f)} 0\n"]
    lines += [f"{x!r} {y!r} {z!r}\n" for x, y, z in np.asarray(v, dtype=float).tolist()]
    lines += [f"3 {i} {j} {k}\n" for i, j, k in np.asarray(f).tolist()]
    Path(path).write_text("".join(lines))


def bumpy_sphere_files(folder, count: int, n: int) -> list[Path]:
    """``folder/s0.off`` … ``s{count-1}.off``: bumpy spheres of ``n`` vertices, one per seed."""
    paths = [Path(folder) / f"s{s}.off" for s in range(count)]
    for s, path in enumerate(paths):
        write_off(path, *bumpy_sphere(n, s))
    return paths


def cli_maps(folder, pa, pb, *flags: str) -> tuple[np.ndarray, np.ndarray]:
    """The maps that ``hope-rs match`` and ``hope-rs batch`` (one job, no cache) write for the
    pair of mesh files (pa, pb) given the extra command-line ``flags``; files go in ``folder``."""
    # A short name per set of flags (a file path may be among them).
    tag = hashlib.sha1("\0".join(flags).encode()).hexdigest()[:12] if flags else "default"
    out = Path(folder) / f"match{tag}.txt"
    assert main(["match", str(pa), str(pb), "-o", str(out), "-q", *flags]) == 0
    pairs = Path(folder) / f"pairs{tag}.txt"
    pairs.write_text(f"{pa} {pb}\n")
    batch = Path(folder) / f"batch{tag}"
    args = ["batch", str(pairs), "--out", str(batch), "-q", "-j", "1", "--no-cache", *flags]
    assert main(args) == 0
    (got,) = list(batch.glob("*.txt"))
    return np.loadtxt(out, dtype=np.int64), np.loadtxt(got, dtype=np.int64)


def echo_or_die(x: str, pause: float = 0.0) -> dict:
    """A task for a batch backend's worker: ``{"x": x}`` after ``pause`` seconds, or, for
    ``x == "die"``, the worker process killed with SIGKILL (as the out-of-memory killer does)."""
    import os
    import signal
    import time

    if x == "die":
        os.kill(os.getpid(), signal.SIGKILL)
    time.sleep(pause)
    return {"x": x}


def subdivided(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each face split into four at its edges' midpoints."""
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, inv = np.unique(edges, axis=0, return_inverse=True)
    mid = v.shape[0] + inv.reshape(3, -1).T
    corners = [np.stack([f[:, i], mid[:, i], mid[:, (i + 2) % 3]], 1) for i in range(3)]
    return np.vstack([v, v[uniq].mean(axis=1)]), np.concatenate([*corners, mid])


def slivered(
    v: np.ndarray, f: np.ndarray, k: int = 3, axis: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Long thin triangles on one side: on each face whose centroid lies beyond the median of
    coordinate ``axis``, ``k`` evenly spaced points inserted on its longest edge; a face with
    one split edge fanned from the opposite corner into slivers, a face with more split edges
    fanned from its centroid. The original vertices come first (ground truth stays valid)."""
    v = np.asarray(v, dtype=np.float64)
    side = v[f].mean(axis=1)[:, axis] > np.median(v[:, axis])
    ts = [(j + 1) / (k + 1) for j in range(k)]
    split: dict[tuple[int, int], list[int]] = {}
    new: list[np.ndarray] = []
    for face in f[side]:
        pairs = [(face[0], face[1]), (face[1], face[2]), (face[2], face[0])]
        p, q = pairs[int(np.argmax([np.linalg.norm(v[p] - v[q]) for p, q in pairs]))]
        key = (int(min(p, q)), int(max(p, q)))
        if key not in split:
            lo, hi = key
            split[key] = [len(v) + len(new) + j for j in range(k)]
            new += [(1 - t) * v[lo] + t * v[hi] for t in ts]

    def chain(a: int, b: int) -> list[int]:
        ids = split.get((min(a, b), max(a, b)), [])
        return ids if a < b else ids[::-1]

    out = []
    for face in f.tolist():
        ch = [chain(face[0], face[1]), chain(face[1], face[2]), chain(face[2], face[0])]
        cut = [i for i in range(3) if ch[i]]
        if not cut:
            out.append(face)
        elif len(cut) == 1:
            i = cut[0]
            seq = [face[i], *ch[i], face[(i + 1) % 3]]
            out += [[p, q, face[(i + 2) % 3]] for p, q in zip(seq[:-1], seq[1:])]
        else:
            ring = [face[0], *ch[0], face[1], *ch[1], face[2], *ch[2]]
            centre = len(v) + len(new)
            new.append(v[face].mean(axis=0))
            out += [[centre, p, q] for p, q in zip(ring, ring[1:] + ring[:1])]
    return np.vstack([v, np.array(new).reshape(-1, 3)]), np.array(out, dtype=np.int64)


def legless(a: hope_rs.Mesh) -> tuple[hope_rs.Mesh, np.ndarray]:
    """A without its lowest 30% of vertices (a FAUST body's legs), and the kept vertices."""
    keep = a.vertices[:, 1] > np.quantile(a.vertices[:, 1], 0.3)
    idx = np.flatnonzero(keep)
    new = np.full(a.n_vertices, -1)
    new[idx] = np.arange(idx.size)
    return hope_rs.Mesh(a.vertices[idx], new[a.faces[keep[a.faces].all(axis=1)]]), idx


def flat_grid(n: int, alternate: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """An n x n flat grid of unit spacing, vertex ``i * n + j`` at (i, j, 0); each square
    split along the same diagonal, or (``alternate``) along alternating ones, which gives
    the grid all 8 symmetries of the square when n is odd."""
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v = np.column_stack([ii.ravel(), jj.ravel(), np.zeros(n * n)]).astype(np.float64)
    i, j = (x.ravel() for x in np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij"))
    a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
    one = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    other = np.vstack([np.column_stack([a, b, d]), np.column_stack([b, c, d])])
    if not alternate:
        return v, one
    odd = np.tile((i + j) % 2 == 1, 2)
    return v, np.where(odd[:, None], other, one)


def mesh_defects(faces: np.ndarray) -> dict:
    """What keeps ``faces`` from being a valid oriented manifold triangle mesh: faces with a
    repeated corner, faces on the same three vertices, edges of three or more faces, and
    directed edges met twice (two neighbouring faces of opposite orientation); all 0 when
    valid. ``boundary`` counts the edges of one face (not a defect)."""
    f = np.asarray(faces)
    degenerate = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    _, per_edge = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    _, per_directed = np.unique(directed, axis=0, return_counts=True)
    return {
        "degenerate": int(degenerate.sum()),
        "duplicate": int(len(f) - len(np.unique(np.sort(f, axis=1), axis=0))),
        "non_manifold_edges": int((per_edge > 2).sum()),
        "flipped_edges": int((per_directed > 1).sum()),
        "boundary": int((per_edge == 1).sum()),
    }


def euler_characteristic(n_vertices: int, faces: np.ndarray) -> int:
    """V - E + F of a triangle mesh (2 per closed genus-0 piece, 1 per disc)."""
    f = np.asarray(faces)
    edges = np.unique(
        np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0
    )
    return n_vertices - len(edges) + len(f)


class PyCollapser:
    """The reference of the core's half-edge collapses (src/collapse.rs), in Python: a
    triangle mesh under collapses, with the faces of each vertex and the vertex each removed
    vertex was merged into."""

    def __init__(self, mesh):
        self.v = np.asarray(mesh.vertices, dtype=np.float64)
        self.f = np.array(mesh.faces, dtype=np.int64)
        self.face_alive = np.ones(len(self.f), dtype=bool)
        self.vfaces: list[set[int]] = [set() for _ in range(len(self.v))]
        for i, face in enumerate(self.f.tolist()):
            for x in face:
                self.vfaces[x].add(i)
        self.merged_into = np.arange(len(self.v))

    def neighbours(self, u: int) -> set[int]:
        out: set[int] = set()
        for i in self.vfaces[u]:
            out.update(self.f[i].tolist())
        out.discard(u)
        return out

    def on_boundary(self, u: int) -> bool:
        """Whether an edge at ``u`` lies on one face only."""
        count: dict[int, int] = {}
        for i in self.vfaces[u]:
            for x in self.f[i].tolist():
                if x != u:
                    count[x] = count.get(x, 0) + 1
        return any(c == 1 for c in count.values())

    def normal(self, a: int, b: int, c: int) -> np.ndarray:
        return np.cross(self.v[b] - self.v[a], self.v[c] - self.v[a])

    def can_collapse(self, u: int, w: int) -> bool:
        """Whether removing ``u`` into its neighbour ``w`` keeps a manifold with no face
        turned over or flattened."""
        shared = [i for i in self.vfaces[u] if i in self.vfaces[w]]
        if not shared:
            return False  # not an edge
        opposite = {x for i in shared for x in self.f[i].tolist() if x not in (u, w)}
        # Link condition: the only common neighbours of u and w are the edge's opposite
        # corners (otherwise the collapse makes a non-manifold edge or a duplicate face).
        if self.neighbours(u) & self.neighbours(w) != opposite:
            return False
        # The boundary keeps its shape: a boundary vertex moves only along a boundary edge.
        if len(shared) != 1 and self.on_boundary(u):
            return False
        for i in self.vfaces[u]:
            if i in shared:
                continue
            face = self.f[i].tolist()
            before = self.normal(*face)
            after = self.normal(*[w if x == u else x for x in face])
            # No face turns over or collapses to a line.
            if np.dot(before, after) <= 0.0 or not np.any(after):
                return False
        return True

    def collapse(self, u: int, w: int) -> None:
        """Remove ``u`` into ``w`` (checked by :meth:`can_collapse`)."""
        for i in list(self.vfaces[u]):
            face = self.f[i]
            if i in self.vfaces[w]:  # a face of the edge (u, w): it collapses
                self.face_alive[i] = False
                for x in face.tolist():
                    self.vfaces[x].discard(i)
            else:
                face[face == u] = w
                self.vfaces[w].add(i)
        self.vfaces[u] = set()
        self.merged_into[u] = w

    def result(self, alive: np.ndarray):
        """The collapsed mesh in compact numbering, the input vertex of each coarse vertex and
        the coarse vertex each input vertex was merged into."""
        sites = np.flatnonzero(alive)
        index = np.full(len(self.v), -1, dtype=np.int64)
        index[sites] = np.arange(sites.size)
        root = self.merged_into.copy()
        while True:  # follow merge chains to a kept vertex
            nxt = root[root]
            if np.array_equal(nxt, root):
                break
            root = nxt
        faces = index[self.f[self.face_alive]]
        return Coarse(hope_rs.Mesh(self.v[sites], faces), sites, index[root])


def py_collapse_to_sites(mesh, sites: np.ndarray):
    """:func:`hope_rs.geometry.collapse.collapse_to_sites` in Python, by :class:`PyCollapser`."""
    n = mesh.n_vertices
    dist, pred, source = shortest_path_tree(mesh, sites)
    c = PyCollapser(mesh)
    alive = np.ones(n, dtype=bool)
    is_site = np.zeros(n, dtype=bool)
    is_site[sites] = True
    # Farthest first: every vertex whose path to the site runs through u is merged before u.
    order = [int(u) for u in np.argsort(-dist, kind="stable") if np.isfinite(dist[u])]
    order = [u for u in order if not is_site[u]]
    for u in order:
        if c.can_collapse(u, int(pred[u])):
            c.collapse(u, int(pred[u]))
            alive[u] = False
    # Vertices refused on the tree: merge into another neighbour of the same site, nearest
    # that site first, until no more can go.
    changed = True
    while changed:
        changed = False
        for u in order:
            if not alive[u]:
                continue
            cands = [x for x in c.neighbours(u) if source[x] == source[u]]
            for x in sorted(cands, key=lambda x: (dist[x], x)):
                if dist[x] < dist[u] and c.can_collapse(u, x):
                    c.collapse(u, x)
                    alive[u], changed = False, True
                    break
    return c.result(alive)
