"""Generated test meshes."""

from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull


def bumpy_sphere(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random Delaunay-like triangulation of a perturbed sphere: no symmetries to confuse a
    matcher, and a different triangulation for every seed."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    faces = ConvexHull(p).simplices.astype(np.int64)
    # Orient faces outwards, then bend the sphere with a smooth random field.
    c = p[faces].mean(axis=1)
    nrm = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    flip = np.einsum("ij,ij->i", nrm, c) < 0
    faces[flip] = faces[flip][:, ::-1]
    w = rng.normal(size=(6, 3))
    r = 1.0 + 0.25 * np.tanh(np.sin(p @ w.T * 2.0).sum(axis=1) / 2)
    return p * r[:, None] * np.array([1.0, 1.3, 0.8]), faces


def random_rigid(rng) -> tuple[np.ndarray, np.ndarray]:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q, rng.normal(size=3) * 5


def moved_copy(a, seed: int):
    """B = the hope_rs.Mesh A relabelled, rotated, scaled by 1.7 and shifted; returns B and A's
    vertex v's image in B."""
    from conftest import relabel

    import hope_rs

    rng = np.random.default_rng(seed)
    perm = rng.permutation(a.n_vertices)  # B's vertex i is A's vertex perm[i]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    b = hope_rs.Mesh(1.7 * a.vertices[perm] @ q.T + 1.0, relabel(a.faces, perm))
    truth = np.empty_like(perm)
    truth[perm] = np.arange(perm.size)
    return b, truth


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
