"""Seeing a map: colour transfer from A to B, both shapes side by side, rendered to a PNG.

Every vertex of A gets a colour from its position (normalised x, y, z as red, green, blue: a
smooth field that tells left from right and top from bottom). Each vertex j of B is then
coloured by pulling back: the mean colour of the vertices of A mapped onto j; vertices of B
that nothing maps to take the colour of the nearest vertex (in space) that was hit. A correct
map shows the same colours at the same body parts; a flipped limb shows up as a swapped hue.

Rendering is an orthographic projection with matplotlib's Agg backend (no display needed):
faces are painted back to front with Lambert shading. Both shapes are seen in A's principal
frame (largest extent up, smallest along the line of sight), which suits data sets whose shapes
share one orientation, as benchmark sets do.
"""

from __future__ import annotations

import os

import numpy as np

from ._validate import as_index_map
from .map_io import read_map
from .mesh import Mesh


def position_colours(mesh: Mesh) -> np.ndarray:
    """(n, 3) RGB in [0, 1]: each coordinate rescaled to [0.1, 0.9] over the shape."""
    v = mesh.vertices
    lo, hi = v.min(axis=0), v.max(axis=0)
    return 0.1 + 0.8 * (v - lo) / np.where(hi > lo, hi - lo, 1.0)


def pull_back_colours(colours_a: np.ndarray, mapping, mesh_b: Mesh) -> np.ndarray:
    """Colours of B's vertices: the mean colour of the A vertices mapped onto each; vertices
    nothing maps to copy their nearest hit vertex."""
    from scipy.spatial import cKDTree

    f = as_index_map(mapping, colours_a.shape[0], mesh_b.n_vertices, name="map")
    total = np.zeros((mesh_b.n_vertices, colours_a.shape[1]))
    np.add.at(total, f, colours_a)
    count = np.bincount(f, minlength=mesh_b.n_vertices)
    hit = count > 0
    out = np.empty_like(total)
    out[hit] = total[hit] / count[hit, None]
    if not hit.all():
        _, nearest = cKDTree(mesh_b.vertices[hit]).query(mesh_b.vertices[~hit])
        out[~hit] = out[hit][nearest]
    return out


def view_frame(v: np.ndarray, up: str = "auto") -> np.ndarray:
    """(3, 3) rotation with columns (screen up, screen right, towards the viewer).

    ``up="auto"``: the principal axis of largest variance points up (right for standing
    figures). ``up`` in "x", "y", "z": that axis of the file points up. Either way the line of
    sight is the direction of least variance across it, so the silhouette is the widest; axes
    are signed to point along the file's own axes they are closest to, so views are stable.
    """
    c = v - v.mean(axis=0)
    if up == "auto":
        _, vecs = np.linalg.eigh(c.T @ c)
        u = vecs[:, -1]
        j = int(np.argmax(np.abs(u)))
        u = u if u[j] > 0 else -u
    elif up in ("x", "y", "z"):
        u = np.eye(3)[" xyz".index(up) - 1]
    else:
        raise ValueError(f"up must be 'auto', 'x', 'y' or 'z', got {up!r}")
    flat = c - np.outer(c @ u, u)  # the points projected across the up axis
    _, vecs = np.linalg.eigh(flat.T @ flat)
    depth = next(w for w in vecs.T if abs(w @ u) < 0.5)  # least variance across u
    depth = depth - (depth @ u) * u
    depth /= np.linalg.norm(depth)
    j = int(np.argmax(np.abs(depth)))
    depth = depth if depth[j] > 0 else -depth
    return np.stack([u, np.cross(u, depth), depth], axis=1)


def _in_frame(v: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Screen coordinates (right, up, towards the viewer) in the frame of :func:`view_frame`."""
    p = (v - v.mean(axis=0)) @ axes
    return np.stack([p[:, 1], p[:, 0], p[:, 2]], axis=1)


def _draw(ax, mesh: Mesh, colours: np.ndarray, axes: np.ndarray, title: str) -> None:
    from matplotlib.collections import PolyCollection

    p = _in_frame(mesh.vertices, axes)
    tri = p[mesh.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    light = 0.35 + 0.65 * np.abs(n @ np.array([0.3, 0.3, 0.9]) / np.linalg.norm([0.3, 0.3, 0.9]))
    rgb = np.clip(colours[mesh.faces].mean(axis=1) * light[:, None], 0, 1)
    order = np.argsort(tri[:, :, 2].mean(axis=1))  # far (small z) first: viewer looks from +z
    ax.add_collection(
        PolyCollection(tri[order, :, :2], facecolors=rgb[order], edgecolors="none", linewidths=0)
    )
    ax.set_xlim(p[:, 0].min(), p[:, 0].max())
    ax.set_ylim(p[:, 1].min(), p[:, 1].max())
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(title, fontsize=9)


def render_pair(
    a: Mesh, b: Mesh, mapping, path, *, title: str | None = None, up: str = "auto", dpi: int = 100
):
    """Write a PNG of A (coloured by position) next to B (coloured through ``mapping``).

    Parameters
    ----------
    a, b : Mesh
    mapping : (n_a,) array_like of int
        ``mapping[i]`` is the vertex of B matched to vertex i of A.
    path : str or PathLike
        Output PNG.
    title : str, optional
        Figure title.
    up : {"auto", "x", "y", "z"}
        Which way is up: A's longest principal axis, or a coordinate axis of the files.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    ca = position_colours(a)
    cb = pull_back_colours(ca, mapping, b)
    fig, axes = plt.subplots(1, 2, figsize=(6.4, 4.0), dpi=dpi)
    frame = view_frame(a.vertices, up)  # one view for both: data sets share an orientation
    _draw(axes[0], a, ca, frame, "A (source)")
    _draw(axes[1], b, cb, frame, "B, coloured through the map")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(os.fspath(path))
    plt.close(fig)


def add_parser(sub) -> None:
    """Register ``hope-rs show``."""
    p = sub.add_parser("show", help="render a map as a colour transfer from A to B (PNG)")
    p.add_argument("a", help="source mesh")
    p.add_argument("b", help="target mesh")
    p.add_argument(
        "map", help="map file: one 0-based B index per line, or .npy (hope-rs match output)"
    )
    p.add_argument("--png", required=True, help="output PNG file")
    p.add_argument("--title", help="figure title")
    p.add_argument(
        "--up", default="auto", choices=["auto", "x", "y", "z"],
        help="axis drawn upwards (default: the longest principal axis of A)",
    )  # fmt: skip
    p.set_defaults(func=cmd_show)


def require_matplotlib() -> None:
    """ValueError with the install command when matplotlib cannot be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise ValueError("hope-rs show needs matplotlib: pip install matplotlib") from None


def cmd_show(args) -> int:
    from .mesh import load_mesh

    require_matplotlib()
    a, b = load_mesh(args.a), load_mesh(args.b)
    render_pair(
        a, b, read_map(args.map, a.n_vertices, b.n_vertices), args.png, title=args.title, up=args.up
    )
    return 0
