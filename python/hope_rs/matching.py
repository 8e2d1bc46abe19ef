"""``hope_rs.match``: two meshes in, a dense vertex-to-vertex map out."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ._options import check_options
from ._validate import as_index_map
from .initial import shapes_initial_map
from .lmd import MIN_CONSISTENT
from .mesh import Mesh, as_mesh
from .refine import MAX_PASSES, POLISH_K, TOP_K, Iteration, RefineResult
from .shape import K_MAX, Shape
from .shared_faces import applies as finish_applies
from .shared_faces import face_handles, finish, qualifies
from .spectral import applies, refine_while_solving_bases, spectral_refine


@dataclass
class MatchResult:
    """The outcome of :func:`match`.

    Attributes
    ----------
    map : (n_a,) int64
        ``map[i]`` is the vertex of B matched to vertex ``i`` of A. (pyFM's ``p2p_21`` is the
        other direction: one entry per vertex of shape 2.)
    init_map : (n_a,) int64
        The map refinement started from.
    history : list of Iteration
        Per refinement step: k, witness fraction, vertices changed, seconds.
    timings : dict
        Seconds per stage ("shapes", "descriptors", "init" or, with ``multiscale``,
        "coarse"; "refine", "spectral", "faces" (the finishing rounds of
        :mod:`hope_rs.shared_faces`, when they ran), "total"). The spectral pass's eigenbases are solved
        in a background thread during "refine" and count there, as does its ZoomOut when the
        refinement reaches its last pass (:class:`~hope_rs.spectral.EarlyZoomOut`).
    coarse : MatchResult or None
        With ``multiscale``, the match of the coarse copies.
    hope_map : (n_a,) int64 or None
        HOPE's own map, before the spectral pass chose between it and its ZoomOut refinement
        region by region and before the shared-face finish; ``None`` when neither ran.
    """

    map: np.ndarray
    init_map: np.ndarray
    history: list[Iteration] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    #: With ``multiscale``, the match of the coarse copies (each coarse vertex ``j`` is the
    #: vertex ``coarse_level()[0].sites[j]`` of the shape's internal mesh); else ``None``.
    coarse: MatchResult | None = None
    hope_map: np.ndarray | None = None


def _as_mesh(x, k_max: int, name: str) -> Shape | Mesh:
    """``x`` as a Shape or Mesh, checked: the cheap part of :func:`_as_shape`."""
    if isinstance(x, Shape):
        if x.k_max < k_max:
            raise ValueError(f"{name} was built with k_max={x.k_max} < requested k_max={k_max}")
        return x
    return as_mesh(x, name)


def _as_shape(x: Shape | Mesh, k_max: int) -> Shape:
    return x if isinstance(x, Shape) else Shape(x, k_max=k_max)


def match(
    a,
    b,
    *,
    init="shot",
    k_max: int = K_MAX,
    schedule: list[int] | None = None,
    max_passes: int = MAX_PASSES,
    min_consistent: float = MIN_CONSISTENT,
    top_k: int = TOP_K,
    polish_k: int | None = POLISH_K,
    global_step: bool = True,
    multiscale: bool = False,
    spectral: bool = True,
    shared_faces: bool = True,
    callback=None,
) -> MatchResult:
    """Dense correspondence from shape A to shape B with HOPE.

    Parameters
    ----------
    a, b : Shape, Mesh or (vertices, faces)
        The shapes. Pass :class:`Shape` objects to reuse their precomputation across pairs.
    init : {"shot", "wks", "hks"} or (n_a,) array_like of int, keyword-only
        Descriptors for the initial map, or an initial map itself (``init[i]`` a vertex of B).
    k_max : int
        Largest hop radius, in [2, 64].
    schedule : list of int, optional
        Hop radii of one refinement pass, each in [1, k_max]; default k_max → 1.
    max_passes : int
        Passes of the schedule at most (at least 1); refinement stops earlier once a pass
        changes almost nothing.
    min_consistent : float
        Witness rule, in [0, 1] (see :data:`hope_rs.lmd.MIN_CONSISTENT`).
    top_k : int
        Candidates kept per vertex in each overlap cost (at least 1).
    polish_k : int or None
        Hop radius, in [1, k_max], of a final step in which each vertex takes its
        best-overlapping candidate; ``None`` returns the one-to-one map of the last assignment
        instead (with ``spectral=False``: the spectral pass is not one-to-one).
    global_step : bool
        Start each pass by re-placing untrusted vertices by their geodesic distances to trusted
        ones (see :func:`hope_rs.refine.global_repair`); ``False`` is the paper's loop.
    multiscale : bool
        For large meshes: match coarse copies of the shapes first (with the options above),
        lift that map to the fine vertices and refine it for
        :func:`~hope_rs.multiscale.fine_passes` passes (see :mod:`hope_rs.multiscale`). About
        three times faster on 100k-vertex meshes, with a larger error (FAUST subdivided to
        110k: 37 s instead of 123 s, mean geodesic error 0.0112 instead of 0.0088). Unless
        both shapes are dense enough to halve (see
        :func:`~hope_rs.multiscale.coarse_mesh`), this is the default path.
    spectral : bool
        After HOPE, run ZoomOut from its map and keep, region by region, whichever of the two
        maps distorts A's 2-rings less (see :mod:`hope_rs.spectral`). On differently
        triangulated shapes this lowers HOPE's error (63 remeshed FAUST/TOSCA pairs: mean
        geodesic error 0.042 → 0.024), on identically triangulated ones HOPE's exact map stays.
        It costs two Laplace–Beltrami eigenbases (about 0.7 s each at 5k vertices, 4 s at 28k)
        and is skipped when a shape has more than
        :data:`~hope_rs.spectral.MAX_VERTICES` vertices, and when HOPE's map has settled (its
        last pass and the polish moved no vertex and LMD trusts every vertex; see
        :attr:`hope_rs.refine.RefineResult.settled`): 5 of the 6 faust_reg pairs of the
        bench and TOSCA remeshed wolf, whose maps are exact, and no other remeshed pair; there
        the pass never changed the map and took 0.3-0.6 s. With ``shared_faces`` it is also
        skipped when HOPE's map sends every face of A onto a face of B one to one.
    shared_faces : bool
        Last, on shapes that share most of their triangulation (at least
        :data:`~hope_rs.shared_faces.MIN_HANDLES` of A's vertices have all their faces mapped
        onto faces of B), run the finishing rounds of :mod:`hope_rs.shared_faces`: deform A as
        rigidly as possible onto the images of those vertices, move the others to the nearest
        vertex of B and repair with HOPE steps; then rebuild the map outward from its trusted
        patches (:mod:`hope_rs.growth`). The refinement hands over after the pass
        in which such vertices reach that share (from its second pass on). On the TOSCA cat
        (28k vertices, 85% of its faces shared) 41.7% → 98.0% exact and a mean geodesic error
        of 0.0139 → 0.0003, in 1–3 s more; on FAUST 012 without its legs against 018
        93.1% → 100% exact. Shapes remeshed independently never qualify (at most 8.6% on 45
        FAUST pairs), and the map is the same as with ``False``. Skipped above
        :data:`~hope_rs.shared_faces.MAX_VERTICES` vertices.
    callback : callable, optional
        Called with each :class:`~hope_rs.refine.Iteration` as it finishes (of the coarse
        match too, with ``multiscale``). An exception it raises ends the match and propagates.

    Returns
    -------
    MatchResult

    Raises
    ------
    TypeError, ValueError
        For a bad option or input, before any expensive work (one line: what is allowed, what
        was given). Whatever the exit (an error, a raising ``callback``, Ctrl-C), the
        background threads of the spectral pass have stopped when ``match`` returns or raises.
    """
    t0 = time.perf_counter()
    # Every option, then the inputs, before any expensive work.
    check_options(
        init=init, k_max=k_max, schedule=schedule, max_passes=max_passes,
        min_consistent=min_consistent, top_k=top_k, polish_k=polish_k, global_step=global_step,
        multiscale=multiscale, spectral=spectral, shared_faces=shared_faces, callback=callback,
    )  # fmt: skip
    ma, mb = _as_mesh(a, k_max, "a"), _as_mesh(b, k_max, "b")
    if not isinstance(init, str):
        init = as_index_map(init, ma.n_vertices, mb.n_vertices, name="init")
    timings: dict[str, float] = {}
    sa, sb = _as_shape(ma, k_max), _as_shape(mb, k_max)
    timings["shapes"] = time.perf_counter() - t0
    if not isinstance(init, str):
        init = sa.map_in(sb, init)
    options = {
        "schedule": schedule, "max_passes": max_passes, "min_consistent": min_consistent,
        "top_k": top_k, "polish_k": polish_k, "global_step": global_step, "callback": callback,
    }  # fmt: skip
    coarse = None
    t = time.perf_counter()
    # Both shapes or neither: a coarse copy matched against a fine shape of another density
    # did worse than the default path (FAUST 27k -> 6.9k: 0.070 against 0.048).
    if multiscale and sa.coarse_level() is not None and sb.coarse_level() is not None:
        from .multiscale import coarse_start, fine_passes

        # The spectral pass runs once, at the finest level it affords: on the TOSCA cat
        # (28k) a pass on the coarse copies as well left 9.3% exact / 0.0214 in 27.4 s, against
        # 27.2% / 0.0182 in 22.8 s with the fine pass only; on FAUST subdivided to 110k, where
        # the fine shapes are too large for it, the coarse pass took 0.0131 to 0.0116 (with a 20 → 100 basis).
        coarse_spectral = spectral and not applies(sa, sb)
        coarse, f0 = coarse_start(sa, sb, init, k_max=k_max, spectral=coarse_spectral, **options)
        timings["coarse"] = time.perf_counter() - t
        options["max_passes"] = min(max_passes, fine_passes(sa.n_vertices, sb.n_vertices))
    elif isinstance(init, str):
        t = time.perf_counter()
        # In the shapes' internal numbering, like everything up to the result.
        da, db = sa.internal_descriptors(init), sb.internal_descriptors(init)
        timings["descriptors"] = time.perf_counter() - t
        t = time.perf_counter()
        f0 = shapes_initial_map(sa, sb, da, db, init)
        timings["init"] = time.perf_counter() - t
    else:
        f0 = init
    f, res = refine_spectral_finish(
        sa, sb, f0, spectral=spectral, shared_faces=shared_faces, timings=timings, **options
    )
    later = "spectral" in timings or "faces" in timings
    hope_map = sa.map_out(sb, res.map).astype(np.int64) if later else None
    timings["total"] = time.perf_counter() - t0
    f_out, f0_out = sa.map_out(sb, f), sa.map_out(sb, f0)
    return MatchResult(
        f_out.astype(np.int64), f0_out.astype(np.int64), res.history, timings, coarse, hope_map
    )


def refine_spectral_finish(
    sa: Shape,
    sb: Shape,
    f0: np.ndarray,
    *,
    spectral: bool = True,
    shared_faces: bool = True,
    timings: dict[str, float] | None = None,
    on_stage=None,
    **options,
) -> tuple[np.ndarray, RefineResult]:
    """The stages of :func:`match` after the initial map ``f0`` (internal numbering): HOPE's
    refinement, the spectral pass and the shared-face finish, each where it applies.

    Returns the final map and the refinement's result.
    ``timings`` gets "refine" and, when they ran, "spectral" and "faces"; ``on_stage(name)``
    is called after each of the three (the benches record memory there); ``options`` go to
    :func:`~hope_rs.refine.refine`.
    """
    timings = {} if timings is None else timings
    finishing = shared_faces and finish_applies(sa, sb)
    t = time.perf_counter()
    if finishing:
        options["last_pass_if"] = partial(qualifies, sa, sb)
    res = refine_while_solving_bases(sa, sb, f0, spectral, **options)
    timings["refine"] = time.perf_counter() - t
    if on_stage is not None:
        on_stage("refine")
    # A map that sends every face onto a face one-to-one is already what the finish aims at,
    # and the spectral pass's region choice keeps it (it distorts no 2-ring).
    done = res.settled or (finishing and bool(face_handles(sa, sb, res.map).all()))
    f = res.map
    if spectral and not done:
        t = time.perf_counter()
        f, z = spectral_refine(sa, sb, res.map, res.early_zoomout)
        if z is not None:
            timings["spectral"] = time.perf_counter() - t
    if on_stage is not None:
        on_stage("spectral")
    if finishing and not done:
        t = time.perf_counter()
        f, rounds = finish(sa, sb, f)
        if rounds:
            timings["faces"] = time.perf_counter() - t
    if on_stage is not None:
        on_stage("faces")
    return f, res
