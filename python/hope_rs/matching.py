"""``hope_rs.match``: two meshes in, a dense vertex-to-vertex map out.

:func:`match` checks its options and inputs, builds the shapes, and runs the stage list of
:mod:`hope_rs.pipeline` (:func:`~hope_rs.pipeline.runner.run_match`).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ._validate import as_index_map
from .geometry.mesh import Mesh, as_mesh
from .pipeline.config import KEYWORDS, MatchConfig
from .pipeline.landmarks import check_landmarks
from .pipeline.options import check_config, check_options
from .pipeline.progress import ProgressBar, StageLog
from .pipeline.result import MatchResult
from .pipeline.runner import run_match
from .pipeline.unreferenced import referenced
from .shape import Shape

__all__ = ["MatchConfig", "MatchResult", "check_match_options", "match", "unknown_options"]


def _as_mesh(x, k_max: int, name: str) -> Shape | Mesh:
    """``x`` as a Shape or Mesh, checked: the cheap part of :func:`_as_shape`."""
    if isinstance(x, Shape):
        if x.k_max < k_max:
            raise ValueError(
                f"{name} was built with k_max={x.k_max} < requested k_max={k_max}; build it "
                f"with Shape(..., k_max={k_max}) or more, or match with k_max={x.k_max}"
            )
        return x
    try:
        return as_mesh(x, name)
    except (TypeError, ValueError) as e:
        # Named as the other input errors are ("b: ..."), unless the message names it already.
        text = str(e)
        if type(e) not in (TypeError, ValueError) or text.startswith((f"{name}: ", f"{name} ")):
            raise
        raise type(e)(f"{name}: {text}") from None


def _mesh_of(x: Shape | Mesh) -> Mesh:
    """The mesh of ``x`` in its input numbering."""
    return x.mesh if isinstance(x, Shape) else x


def _like(x: Shape | Mesh, mesh: Mesh, min_piece: float) -> Shape | Mesh:
    """``mesh`` (``x``'s mesh with vertices left out, as ``min_piece`` decided) as a Shape
    built as ``x`` was (:meth:`Shape.without`), or as a Mesh when ``x`` is one."""
    return x.without(mesh, min_piece) if isinstance(x, Shape) else mesh


def _as_shape(x: Shape | Mesh, config: MatchConfig, name: str) -> Shape:
    """``x`` as a Shape; a mesh that cannot be one (no surface area) is named (``name: ...``)."""
    if isinstance(x, Shape):
        return x
    try:
        return Shape(x, k_max=config.k_max, config=config.shape)
    except ValueError as e:
        raise ValueError(f"{name}: {e}") from None


def match(
    a,
    b,
    *,
    init=None,
    landmarks=None,
    config: MatchConfig | None = None,
    callback=None,
    progress=None,
    **options,
) -> MatchResult:
    """Dense correspondence from shape A to shape B with HOPE.

    Parameters
    ----------
    a, b : Shape, Mesh, (vertices, faces), a mesh file's path or a mesh object
        The shapes (anything :func:`~hope_rs.geometry.mesh.as_mesh` reads: a
        ``trimesh.Trimesh``, an open3d ``TriangleMesh``, a one-mesh ``trimesh.Scene``;
        polygons are fan-triangulated). Pass :class:`Shape` objects to reuse their
        precomputation across pairs;
        a Shape keeps the :class:`~hope_rs.ShapeConfig` it was built with, over
        ``config.shape`` (``res.config.shape`` is the one used, and a mesh given beside it is
        described with it too).
    init : {"shot", "wks", "hks"} or (n_a,) array_like of int, keyword-only
        Descriptors for the initial map (default ``config.initial.descriptor``, "shot"), or
        an initial map itself (``init[i]`` a vertex of B).
    landmarks : (m, 2) array_like of int, keyword-only
        Vertex pairs known to correspond: row ``(i, j)`` says vertex ``i`` of A is vertex
        ``j`` of B (0-based, the meshes' own numbering). The map sends each exactly there,
        and the vertices around them follow: a few well-spread landmarks (four extremities)
        tell a left limb from the right one. ``None`` or an empty array: none
        (:mod:`hope_rs.pipeline.landmarks`; their settings are ``config.landmarks``).
    config : MatchConfig, optional
        Every setting, stage by stage (:class:`~hope_rs.MatchConfig`); default
        ``MatchConfig()``, the method's one parameter set for all data.
    callback : callable, optional
        Called with each :class:`~hope_rs.pipeline.state.Iteration` as it finishes (of the
        coarse match too, with ``multiscale``); the polish step has ``polish=True``. An
        exception it raises ends the match and propagates.
    progress : bool or callable, optional
        ``True`` draws the progress of every stage on stderr (one rewritten line on a terminal
        or in a notebook, one line per stage elsewhere;
        :class:`~hope_rs.pipeline.progress.ProgressBar`). A callable receives a
        :class:`~hope_rs.pipeline.progress.ProgressEvent` at the start and end of each stage
        (skipped ones included, with the reason) and at each refinement step. Stages are also
        logged to ``logging.getLogger("hope_rs")`` (INFO per stage, DEBUG per step).
    **options
        The most used settings by name, over ``config`` (see
        :data:`hope_rs.pipeline.config.KEYWORDS`):

        - ``k_max`` (int, 8): largest hop radius, in [2, 64].
        - ``schedule`` (list of int): hop radii of one refinement pass, each in [1, k_max];
          default k_max → 1.
        - ``max_passes`` (int, 4): passes of the schedule at most; refinement stops earlier
          once a pass changes almost nothing.
        - ``min_consistent`` (float, 0.5): LMD's witness rule, in [0, 1].
        - ``top_k`` (int, 48): candidates kept per vertex in each overlap cost.
        - ``polish_k`` (int or None, 3): hop radius of a last step in which each vertex takes
          its best-overlapping candidate; ``None`` keeps the one-to-one map.
        - ``global_step`` (bool, True): start each pass by re-placing untrusted vertices by
          their geodesic distances to trusted ones; ``False`` is the paper's loop.
        - ``multiscale`` (bool or None, None): match coarse copies first, lift that map and
          refine it on the full meshes (then the shared-face finish where the shapes share
          their triangulation). ``None`` chooses by size: coarse-to-fine when a shape has more
          than ``MultiscaleConfig.auto_vertices`` (60,000) vertices; ``False`` forces the
          full path (docs/decisions.md#multiscale).
        - ``spectral`` (bool, True): after HOPE, run ZoomOut from its map and keep, region by
          region, whichever map distorts A's 2-rings less (docs/decisions.md#spectral).
        - ``shared_faces`` (bool, True): on shapes that share most of their triangulation,
          finish with ARAP rounds and a growth from trusted patches; independently remeshed
          shapes never qualify (docs/decisions.md#shared-faces).
        - ``confidence`` (bool, True): compute ``MatchResult.confidence`` (per vertex of A,
          in [0, 1]) and ``MatchResult.quality`` (docs/confidence.md); the map is the same.

    Returns
    -------
    MatchResult

    Raises
    ------
    TypeError, ValueError
        For a bad option or input, before any expensive work (one line: what is allowed, what
        was given). Whatever the exit (an error, a raising ``callback``, Ctrl-C), the
        background threads of the spectral pass have stopped when ``match`` returns or raises.

    Examples
    --------
    >>> import hope_rs, trimesh
    >>> a = trimesh.creation.icosphere(subdivisions=3)  # 642 vertices; or hope_rs.load_mesh(path)
    >>> b = a.copy()
    >>> b.vertices *= [1.0, 1.2, 0.9]  # a stretched copy
    >>> res = hope_rs.match(a, b)
    >>> res.map.shape == (len(a.vertices),)
    True
    >>> [s.name for s in res.stages][:4]
    ['shapes', 'descriptors', 'init', 'refine']
    """
    t0 = time.perf_counter()
    # Every option, then the inputs, before any expensive work.
    config = _effective_config(config, init, options, callback, progress)
    if init is None:
        init = config.initial.descriptor
    ma, mb = _as_mesh(a, config.k_max, "a"), _as_mesh(b, config.k_max, "b")
    config = _shape_settings(ma, mb, config)
    if not isinstance(init, str):
        init = as_index_map(init, ma.n_vertices, mb.n_vertices, name="init")
    landmarks = given = check_landmarks(landmarks, ma.n_vertices, mb.n_vertices)
    # Vertices in no face and small loose pieces have no surface to match by: the pair is
    # matched without them.
    ref = referenced(_mesh_of(ma), _mesh_of(mb), config.min_piece)
    if ref is not None:
        ma = ma if ref.mesh_a is None else _like(ma, ref.mesh_a, config.min_piece)
        mb = mb if ref.mesh_b is None else _like(mb, ref.mesh_b, config.min_piece)
        if not isinstance(init, str):
            init = ref.init_in(init)
        landmarks = ref.landmarks_in(landmarks)
    sa, sb = _as_shape(ma, config, "a"), _as_shape(mb, config, "b")
    timings = {"shapes": time.perf_counter() - t0}
    if isinstance(progress, (bool, np.bool_)):  # True: the bar; False: nothing
        bar, progress = (ProgressBar() if progress else None), None
    else:
        bar = None
    log = StageLog(bar or progress, t0)
    shapes = f"A {sa.n_vertices} vertices, B {sb.n_vertices}"
    log.ran("shapes", timings["shapes"], shapes + (f" ({ref.note()})" if ref else ""))
    # The bar's line ends on every exit (an error or Ctrl-C included).
    try:
        res = run_match(
            sa, sb, init, config, callback=callback, log=log, timings=timings, landmarks=landmarks
        )
        return res if ref is None else ref.expand(res, given)
    finally:
        if bar is not None:
            bar.close()


def _shape_settings(ma: Shape | Mesh, mb: Shape | Mesh, config: MatchConfig) -> MatchConfig:
    """``config`` with the :class:`~hope_rs.ShapeConfig` the match uses: a given Shape's own
    (its descriptors are computed with it), so that ``res.config`` says so and a mesh given
    beside it is described alike. Two Shapes built with different settings are refused:
    their descriptors cannot be compared."""
    own = [x.config for x in (ma, mb) if isinstance(x, Shape)]
    for shape_config in own:
        check_config(shape_config, "Shape.config")
    if len(own) == 2 and own[0] != own[1]:
        raise ValueError(
            "a and b are Shapes built with different ShapeConfigs, whose descriptors cannot be "
            "compared; build both with the same config"
        )
    if own and own[0] != config.shape:
        return dataclasses.replace(config, shape=own[0])
    return config


def _effective_config(config, init, options: dict, callback, progress) -> MatchConfig:
    """``config`` (default ``MatchConfig()``) with ``options`` set, every value checked."""
    if config is None:
        config = MatchConfig()
    elif not isinstance(config, MatchConfig):
        raise TypeError(
            f"config must be a hope_rs.MatchConfig or None, got {type(config).__name__}"
        )
    check_config(config)
    unknown = _unknown_option(options)
    if unknown:
        raise TypeError(f"match() got an unexpected keyword argument {unknown}")
    values = {**config.options(), **options}
    kind = config.initial.descriptor if init is None else init
    check_options(init=kind, callback=callback, progress=progress, **values)
    config = config.with_options(**options) if options else config
    if isinstance(init, str) and init != config.initial.descriptor:
        # res.config says which descriptors started the match, as a batch's does.
        config = dataclasses.replace(
            config, initial=dataclasses.replace(config.initial, descriptor=init)
        )
    return config


def unknown_options(options) -> list[str]:
    """The names among ``options`` that are no keyword option of :func:`match` (sorted)."""
    return sorted(set(options) - set(KEYWORDS))


def _unknown_option(options: dict) -> str | None:
    """The first name of ``options`` that is no option of :func:`match`, with the list of
    options, or ``None``."""
    unknown = unknown_options(options)
    if not unknown:
        return None
    return (
        f"{unknown[0]!r}; the options are init, landmarks, config, callback, progress, "
        f"{', '.join(KEYWORDS)}"
    )


def check_match_options(**options) -> MatchConfig:
    """Check keyword options meant for :func:`match` (as a batch or the CLI passes them on)
    before any work: unknown names raise ``TypeError``, bad values what :func:`match` would
    raise, in one line. Returns the config :func:`match` would run with."""
    given = dict(options)
    config, init = given.pop("config", None), given.pop("init", None)
    callback, progress = given.pop("callback", None), given.pop("progress", None)
    unknown = _unknown_option(given)
    if unknown:
        raise TypeError(
            f"not an option of hope_rs.match: match() got an unexpected keyword argument {unknown}"
        )
    return _effective_config(config, init, given, callback, progress)
