"""Seeing a map: colour transfer from A to B rendered to a PNG, or written as coloured PLY files.

Every vertex of A gets a colour from its position (:func:`position_colours`: hue runs from
head to foot, left and right differ in lightness and saturation, a smooth field). Each vertex j
of B is then coloured by pulling back (:func:`pull_back_colours`): the mean colour of the
vertices of A mapped onto j; vertices of B that nothing maps to take the colour of the nearest
vertex (in space) that was hit. A correct map shows the same colours at the same body parts; a
flipped limb shows up as a swapped hue.

With a ground truth, a third panel colours A by each vertex's geodesic error (sqrt(area of B)
units, with a colour bar); per-vertex confidence values can be shown the same way.

Rendering is an orthographic projection with matplotlib's Agg backend (no display needed):
faces are painted back to front with Lambert shading. Both shapes are seen in one frame made
from A (:func:`view_frame`): benchmark data sets store their shapes upright along a coordinate
axis (FAUST: y up, TOSCA: z up); ``up="auto"`` takes the axis of largest extent, right for
standing figures (give ``"z"`` for TOSCA's four-legged animals).
"""

from __future__ import annotations

import functools
import os
import pickle

import numpy as np

from .._validate import as_index_map
from ..geometry.map_io import atomic_write, check_not_an_input, check_output_file, read_map
from ..geometry.mesh import Mesh, load_mesh
from ..pipeline.config import MatchConfig
from ..pipeline.unreferenced import body_vertices
from .evaluate import geodesic_errors, load_vts

__all__ = [
    "detect_up",
    "ply_pair_paths",
    "position_colours",
    "pull_back_colours",
    "render_pair",
    "view_frame",
    "write_ply_pair",
]


def _body(mesh: Mesh) -> np.ndarray:
    """Bool per vertex: on the surface a match keeps (not in scan debris, small loose pieces,
    nor in no face), which frames the view and spans the colours."""
    return body_vertices(mesh, MatchConfig().min_piece)


def position_colours(mesh: Mesh, frame: np.ndarray | None = None) -> np.ndarray:
    """(n, 3) RGB in [0, 1]: a vivid, smooth colouring of the vertex positions.

    In the view frame (``frame``, default :func:`view_frame` of ``mesh``): the hue runs
    around the colour wheel from the top of the shape to its bottom, and the left-right
    coordinate turns the hue a little and sets the lightness, so that left and right limbs
    differ too.
    """
    import colorsys

    p = _in_frame(mesh.vertices, view_frame(mesh) if frame is None else frame)
    body = p[_body(mesh)]
    lo, hi = body.min(axis=0), body.max(axis=0)
    t = np.clip((p - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0, 1.0)  # right, up, depth
    # Hue from the top (red) to the bottom (violet), turned by up to a tenth of the wheel
    # from left to right; lightness rises from left to right.
    hue = (0.8 * (1.0 - t[:, 1]) + 0.2 * (t[:, 0] - 0.5)) % 1.0
    light = 0.34 + 0.3 * t[:, 0]
    sat = np.full_like(hue, 0.95)
    return np.array([colorsys.hls_to_rgb(h, l_, s) for h, l_, s in zip(hue, light, sat)])


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


def detect_up(mesh: Mesh | np.ndarray) -> tuple[int, int]:
    """(axis, sign) of the file's coordinate axis drawn upwards: the axis of largest extent,
    pointing along its positive direction, e.g. (1, +1) for +y.

    Right for standing figures stored upright, as benchmark data sets store them (FAUST: +y,
    TOSCA's people: +z). Four-legged animals are longer than tall: give ``up`` explicitly for
    them (TOSCA: "z").
    """
    v = np.asarray(mesh.vertices if isinstance(mesh, Mesh) else mesh, dtype=np.float64)
    return int(np.argmax(np.ptp(v, axis=0))), 1


def view_frame(shape, up: str = "auto") -> np.ndarray:
    """(3, 3) rotation with columns (screen up, screen right, towards the viewer).

    ``shape``: a :class:`~hope_rs.Mesh` or an (n, 3) array of points. ``up="auto"``: the
    axis of :func:`detect_up`; "x", "y", "z": that axis of the file. The line of sight is the
    remaining coordinate axis of least extent, so the silhouette is the widest (a standing
    figure from the front, an animal from the side), looking along its negative direction.
    """
    if isinstance(shape, Mesh):
        v = shape.vertices[_body(shape)]
    else:
        v = np.asarray(shape, dtype=np.float64)
    if up == "auto":
        axis, sign = detect_up(v)
    elif up in ("x", "y", "z"):
        axis, sign = "xyz".index(up), 1
    else:
        raise ValueError(f"up must be 'auto', 'x', 'y' or 'z', got {up!r}")
    u = sign * np.eye(3)[axis]
    ext = np.ptp(v, axis=0)
    depth = np.eye(3)[min((i for i in range(3) if i != axis), key=lambda i: ext[i])]
    return np.stack([u, np.cross(u, depth), depth], axis=1)


def _in_frame(v: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Screen coordinates (right, up, towards the viewer) in the frame of :func:`view_frame`."""
    p = (v - v.mean(axis=0)) @ axes
    return np.stack([p[:, 1], p[:, 0], p[:, 2]], axis=1)


def _half_size(meshes, axes: np.ndarray) -> np.ndarray:
    """Half the largest screen width and height of ``meshes``, plus a margin: one scale for
    every panel, so that shapes of one size look one size."""
    sizes = [np.ptp(_in_frame(m.vertices[_body(m)], axes)[:, :2], axis=0) for m in meshes]
    return 0.52 * np.max(sizes, axis=0)


def _draw(ax, mesh: Mesh, colours: np.ndarray, axes: np.ndarray, title: str, half) -> None:
    from matplotlib.collections import PolyCollection

    p = _in_frame(mesh.vertices, axes)
    tri = p[mesh.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    # Lambert from a light above and in front of the viewer, plus ambient: faces keep the
    # colour's own saturation where they face the light.
    light_dir = np.array([0.25, 0.45, 0.86]) / np.linalg.norm([0.25, 0.45, 0.86])
    light = 0.45 + 0.55 * np.abs(n @ light_dir)
    rgb = np.clip(colours[mesh.faces].mean(axis=1) * light[:, None], 0, 1)
    order = np.argsort(tri[:, :, 2].mean(axis=1))  # far (small z) first: viewer looks from +z
    ax.add_collection(
        PolyCollection(
            tri[order, :, :2], facecolors=rgb[order], edgecolors=rgb[order], linewidths=0.1
        )
    )
    body = p[_body(mesh), :2]
    mid = (body.min(axis=0) + body.max(axis=0)) / 2
    ax.set_xlim(mid[0] - half[0], mid[0] + half[0])
    ax.set_ylim(mid[1] - half[1], mid[1] + half[1])
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(title, fontsize=13)


def render_pair(
    a: Mesh,
    b: Mesh,
    mapping,
    path,
    *,
    title: str | None = None,
    up: str = "auto",
    dpi: int = 100,
    size: tuple[int, int] = (1600, 900),
    values: np.ndarray | None = None,
    values_label: str = "",
    values_name: str = "",
    values_max: float | None = None,
    cmap: str = "inferno_r",
) -> None:
    """Write a PNG of A (coloured by position) next to B (coloured through ``mapping``), and
    a third panel of A coloured by per-vertex ``values`` when given.

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
        Which axis of the files points up (see :func:`view_frame`).
    dpi : int
        Pixels per inch of the figure (text size scales with it).
    size : (int, int)
        Width and height of the PNG in pixels.
    values : (n_a,) array_like of float, optional
        Per-vertex values of A (a geodesic error, a confidence), drawn with ``cmap`` from 0 to
        ``values_max`` (default: their maximum) with a colour bar labelled ``values_label``;
        the panel's title names them ``values_name`` (default: the label).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    width, height = size
    if width < 100 or height < 100:
        raise ValueError(f"size must be at least 100x100 pixels, got {width}x{height}")
    frame = view_frame(a, up)  # one view for both: data sets share an orientation
    ca = position_colours(a, frame)
    cb = pull_back_colours(ca, mapping, b)
    panels = 2 if values is None else 3
    # Constrained layout keeps the titles inside the figure beside equal-aspect panels.
    fig, axes = plt.subplots(
        1, panels, figsize=(width / dpi, height / dpi), dpi=dpi, layout="constrained"
    )
    half = _half_size((a, b), frame)
    _draw(axes[0], a, ca, frame, "A (source), coloured by position", half)
    _draw(axes[1], b, cb, frame, "B, coloured through the map", half)
    if values is not None:
        vals = np.asarray(values, dtype=np.float64)
        if vals.shape != (a.n_vertices,):
            raise ValueError(f"values must have one entry per vertex of A ({a.n_vertices})")
        top = float(np.nanmax(vals)) if values_max is None else values_max
        norm = Normalize(0.0, top if top > 0 else 1.0)
        colours = plt.get_cmap(cmap)(norm(vals))[:, :3]
        _draw(axes[2], a, colours, frame, f"A, coloured by {values_name or values_label}", half)
        bar = fig.colorbar(
            ScalarMappable(norm=norm, cmap=cmap), ax=axes[2], fraction=0.05, shrink=0.7
        )
        bar.set_label(values_label, fontsize=11)
    if title:
        fig.suptitle(title, fontsize=15)
    atomic_write(path, lambda fh: fig.savefig(fh, format="png"))
    plt.close(fig)


def ply_pair_paths(path) -> tuple[str, str]:
    """The two files :func:`write_ply_pair` writes for ``path``: ``out.ply`` (or ``out``) names
    ``out_A.ply`` and ``out_B.ply``; another suffix is kept (``out.txt``: ``out.txt_A.ply``)."""
    stem = os.fspath(path)
    stem = stem[:-4] if stem.lower().endswith(".ply") else stem
    return f"{stem}_A.ply", f"{stem}_B.ply"


def write_ply_pair(a: Mesh, b: Mesh, mapping, path, *, up: str = "auto") -> tuple[str, str]:
    """Write the colour transfer as two PLY files with per-vertex colours: A coloured by
    position (:func:`position_colours`) and B coloured through ``mapping``
    (:func:`pull_back_colours`: the mean colour of the A vertices mapped onto each vertex,
    the nearest hit vertex's colour where nothing maps). Any mesh viewer then shows the
    correspondence.

    ``path`` names the pair: ``out.ply`` (or ``out``) writes ``out_A.ply`` and ``out_B.ply``.
    Each file appears whole or not at all. Returns the two paths.
    """
    import trimesh

    targets = ply_pair_paths(path)
    ca = position_colours(a, view_frame(a, up))
    cb = pull_back_colours(ca, mapping, b)
    out = []
    for mesh, colours, tag in ((a, ca, "A"), (b, cb, "B")):
        rgba = np.concatenate(
            [np.round(255 * np.clip(colours, 0, 1)), np.full((mesh.n_vertices, 1), 255)], axis=1
        ).astype(np.uint8)
        tm = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_colors=rgba, process=False)
        target = targets[0 if tag == "A" else 1]
        atomic_write(target, functools.partial(tm.export, file_type="ply"))
        out.append(target)
    return out[0], out[1]


def _parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise ValueError(
            f"--size must be WIDTHxHEIGHT in pixels, e.g. 1600x900, got {text!r}"
        ) from None
    if w < 100 or h < 100 or w > 20000 or h > 20000:
        raise ValueError(f"--size must be between 100x100 and 20000x20000 pixels, got {text!r}")
    return w, h


def _confidence(path: str, n: int) -> np.ndarray:
    """The per-vertex confidence of A from the .npy file ``path``, checked: ``n`` finite
    numbers in [0, 1], as ``hope-rs match --confidence-out`` writes them."""
    try:
        values = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise FileNotFoundError(f"no such confidence file: {path!r}") from None
    except (OSError, ValueError, pickle.UnpicklingError):
        raise ValueError(
            f"--confidence {path!r} is not a NumPy .npy array (hope-rs match --confidence-out "
            "writes one)"
        ) from None
    if values.shape != (n,):
        raise ValueError(
            f"--confidence holds {values.shape} values; it needs one per vertex of A ({n})"
        )
    real = np.issubdtype(values.dtype, np.integer) or np.issubdtype(values.dtype, np.floating)
    if not real or not (np.isfinite(values).all() and values.min() >= 0.0 and values.max() <= 1.0):
        raise ValueError(f"--confidence {path!r} must hold numbers in [0, 1]")
    return values


def add_parser(sub) -> None:
    """Register ``hope-rs show``."""
    p = sub.add_parser(
        "show",
        help="render a map as a colour transfer from A to B (PNG) or write coloured PLY files",
        description="Colours A by position and B through the map. --png renders both side by "
        "side (plus A coloured by error or confidence); --ply writes OUT_A.ply and OUT_B.ply "
        "with vertex colours for any mesh viewer.",
    )
    p.add_argument("a", help="source mesh")
    p.add_argument("b", help="target mesh")
    p.add_argument(
        "map", help="map file: one 0-based B index per line, or .npy (hope-rs match output)"
    )
    p.add_argument("--png", help="output PNG file")
    p.add_argument(
        "--ply",
        help="output PLY pair: OUT.ply (or OUT) writes OUT_A.ply and OUT_B.ply; another "
        "suffix is kept in the names (out.txt writes out.txt_A.ply)",
    )
    p.add_argument("--title", help="figure title")
    p.add_argument(
        "--up", default="auto", choices=["auto", "x", "y", "z"],
        help="axis drawn upwards (default: the axis of largest extent, right for standing "
        "figures; give z for TOSCA's animals)",
    )  # fmt: skip
    p.add_argument("--size", default="1600x900", help="PNG size in pixels (default 1600x900)")
    p.add_argument(
        "--truth", nargs="+", metavar="GT",
        help="ground truth: 'identity', or A.vts B.vts (1-based landmarks)",
    )  # fmt: skip
    p.add_argument(
        "--color-by", choices=["position", "error", "confidence"],
        help="third panel: 'error' (needs --truth; the default with it) or 'confidence' "
        "(needs --confidence)",
    )  # fmt: skip
    p.add_argument(
        "--confidence",
        help=".npy of per-vertex confidence values of A (0..1), as hope-rs match "
        "--confidence-out writes it",
    )
    p.set_defaults(func=cmd_show)


def require_matplotlib() -> None:
    """ValueError with the install command when matplotlib cannot be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise ValueError("hope-rs show needs matplotlib: pip install matplotlib") from None


def _truth(spec: list[str], n_a: int, n_b: int) -> tuple[np.ndarray, np.ndarray]:
    if spec == ["identity"]:
        if n_a != n_b:
            raise ValueError(f"--truth identity needs equal vertex counts, got {n_a} and {n_b}")
        return np.arange(n_a), np.arange(n_a)
    if len(spec) != 2:
        raise ValueError("--truth takes 'identity' or two .vts files (A's, then B's)")
    ai, bi = load_vts(spec[0]), load_vts(spec[1])
    if ai.size != bi.size:
        raise ValueError(f"--truth files list {ai.size} and {bi.size} landmarks; they must match")
    if ai.max(initial=-1) >= n_a or bi.max(initial=-1) >= n_b:
        raise ValueError("--truth indices exceed the meshes' vertex counts (swapped files?)")
    return ai, bi


def vertex_errors(a: Mesh, b: Mesh, mapping, a_idx, b_idx) -> np.ndarray:
    """Geodesic error (edge-graph, / sqrt(area of B)) of every vertex of A: scored vertices
    their own, the others that of the nearest scored vertex (a landmark may repeat: the
    largest error counts)."""
    from scipy.spatial import cKDTree

    e = geodesic_errors(b, mapping, a_idx=a_idx, b_idx=b_idx)
    out = np.full(a.n_vertices, -1.0)
    np.maximum.at(out, a_idx, e)
    seen = out >= 0
    if not seen.all():
        _, nearest = cKDTree(a.vertices[seen]).query(a.vertices[~seen])
        out[~seen] = out[seen][nearest]
    return out


def cmd_show(args) -> int:
    if not args.png and not args.ply:
        raise ValueError("give --png FILE and/or --ply FILE: there is nothing to write")
    given = [o for o, x in [("--truth", args.truth), ("--confidence", args.confidence),
                            ("--color-by", args.color_by)] if x]  # fmt: skip
    if given and not args.png:
        raise ValueError(
            f"{', '.join(given)} colour the --png picture only (the PLY pair carries the "
            "position colours through the map): add --png FILE, or leave them out"
        )
    size = _parse_size(args.size)
    color_by = args.color_by or (
        "error" if args.truth else "confidence" if args.confidence else "position"
    )
    unused = [o for o, x, by in [("--truth", args.truth, "error"),
                                 ("--confidence", args.confidence, "confidence")]
              if x and color_by != by]  # fmt: skip
    if unused:
        raise ValueError(
            f"{unused[0]} is read only with --color-by "
            f"{'error' if unused[0] == '--truth' else 'confidence'}, not {color_by}: "
            "leave it out or colour by it"
        )
    if color_by == "error" and not args.truth:
        raise ValueError("--color-by error needs --truth ('identity' or A.vts B.vts)")
    if color_by == "confidence" and not args.confidence:
        raise ValueError(
            "--color-by confidence needs --confidence FILE.npy (hope-rs match A B -o MAP "
            "--confidence-out FILE.npy writes it)"
        )
    if args.png:
        require_matplotlib()
    inputs = [x for x in (args.a, args.b, args.map, args.confidence) if x]
    if args.png:  # before any work
        check_output_file(args.png, "--png")
        check_not_an_input(args.png, inputs, "--png")
        if os.path.splitext(args.png)[1].lower() not in ("", ".png"):
            raise ValueError(f"--png {args.png!r} must end in .png (the picture is written as PNG)")
    if args.ply:
        if os.path.isdir(args.ply):
            raise ValueError(f"--ply {args.ply!r} is a folder; give a file name such as out.ply")
        for target in ply_pair_paths(args.ply):
            check_output_file(target, "--ply")
            check_not_an_input(target, inputs, "--ply")
    a, b = load_mesh(args.a), load_mesh(args.b)
    f = read_map(args.map, a.n_vertices, b.n_vertices)
    values, label, top, cmap = None, "", None, "inferno_r"
    if color_by == "error":
        ai, bi = _truth(args.truth, a.n_vertices, b.n_vertices)
        values = vertex_errors(a, b, f, ai, bi)
        label = "geodesic error / sqrt(area of B)"
        top = max(0.1, float(np.quantile(values, 0.99)))
    elif color_by == "confidence":
        values = _confidence(args.confidence, a.n_vertices)
        label, top, cmap = "confidence", 1.0, "viridis"
    if args.png:
        render_pair(
            a, b, f, args.png, title=args.title, up=args.up, size=size, values=values,
            values_label=label, values_name=label.split(" /")[0], values_max=top, cmap=cmap,
        )  # fmt: skip
    if args.ply:
        write_ply_pair(a, b, f, args.ply, up=args.up)
    return 0
