"""``hope_rs.match``: two meshes in, a dense vertex-to-vertex map out."""

from __future__ import annotations

import inspect
import time
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from . import shared_faces as _faces_module
from . import spectral as _spectral_module
from ._options import check_options
from ._validate import as_index_map
from .initial import shapes_initial_map
from .lmd import MIN_CONSISTENT
from .mesh import Mesh, as_mesh
from .progress import ProgressBar, StageInfo, StageLog, step_detail
from .refine import MAX_PASSES, POLISH_K, TOP_K, Iteration, RefineResult, default_schedule
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
        ``map[i]`` is the vertex of B matched to vertex ``i`` of A. For pyFM, see
        :meth:`to_pyfm`.
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
    hope_map : (n_a,) int64
        HOPE's own map: the refinement's output, before the spectral pass chose between it and
        its ZoomOut refinement region by region and before the shared-face finish. Equal to
        ``map`` when neither of those changed it (see :attr:`stages`).
    stages : list of StageInfo
        Every stage in the order it ran, with whether it ran, why (or why not) and its seconds:
        "shapes", "descriptors", "init" ("coarse" and "lift" with ``multiscale``), "refine",
        "polish", "spectral", "faces" (see :data:`hope_rs.progress.STAGES`). ``str()`` of an
        entry reads "spectral: skipped (HOPE's map settled: ...)".
    """

    map: np.ndarray
    init_map: np.ndarray
    history: list[Iteration] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    #: With ``multiscale``, the match of the coarse copies (each coarse vertex ``j`` is the
    #: vertex ``coarse_level()[0].sites[j]`` of the shape's internal mesh); else ``None``.
    coarse: MatchResult | None = None
    hope_map: np.ndarray | None = None
    stages: list[StageInfo] = field(default_factory=list)

    def stage(self, name: str) -> StageInfo:
        """The :class:`~hope_rs.progress.StageInfo` of the stage ``name`` (e.g. "spectral").

        Raises
        ------
        KeyError
            When the match did not consider that stage ("coarse" without ``multiscale``).
        """
        for s in self.stages:
            if s.name == name:
                return s
        raise KeyError(
            f"no stage {name!r} in this match; it has {', '.join(s.name for s in self.stages)}"
        )

    def to_pyfm(self) -> np.ndarray:
        """The map as pyFM's ``p2p_21`` for ``mesh1 = B`` and ``mesh2 = A``.

        pyFM (``pip install pyfmaps``) writes a point-to-point map as ``p2p_21``: for each
        vertex of ``mesh2``, a vertex of ``mesh1``; it goes with the functional map ``FM_12``,
        which carries functions on ``mesh1`` to ``mesh2`` (``pyFM.spectral.mesh_p2p_to_FM(p2p_21,
        mesh1, mesh2)``). ``match(A, B).map`` gives a vertex of B for each vertex of A, so it is
        ``p2p_21`` with ``mesh1`` built from B and ``mesh2`` from A::

            res = hope_rs.match(a, b)
            mesh1, mesh2 = TriMesh(b.vertices, b.faces), TriMesh(a.vertices, a.faces)
            fm_12 = mesh_p2p_to_FM(res.to_pyfm(), mesh1, mesh2, dims=30)  # functions on B -> A

        With ``mesh1`` = A and ``mesh2`` = B instead, match the other way:
        ``hope_rs.match(b, a).to_pyfm()`` (a map is not one-to-one, so reversing it would lose
        vertices of B that nothing maps to).

        Returns
        -------
        (n_a,) int64
            A copy of :attr:`map`.
        """
        return np.array(self.map, dtype=np.int64)


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
    progress=None,
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
        Match coarse copies first, lift that map and refine it on the full meshes (see
        :mod:`hope_rs.multiscale`): faster on large meshes, with a larger error
        (docs/decisions.md#multiscale). Shapes too sparse to halve take the default path.
    spectral : bool
        After HOPE, run ZoomOut from its map and keep, region by region, whichever map distorts
        A's 2-rings less (see :mod:`hope_rs.spectral`). Skipped above
        :data:`~hope_rs.spectral.MAX_VERTICES` vertices, when HOPE's map has settled, and (with
        ``shared_faces``) when it sends every face onto a face (docs/decisions.md#spectral).
    shared_faces : bool
        On shapes that share most of their triangulation (at least
        :data:`~hope_rs.shared_faces.MIN_HANDLES` of A's vertices with all their faces mapped
        onto faces of B), finish with :mod:`hope_rs.shared_faces` and :mod:`hope_rs.growth`.
        Independently remeshed shapes never qualify and get the same map as with ``False``;
        skipped above :data:`~hope_rs.shared_faces.MAX_VERTICES` vertices
        (docs/decisions.md#shared-faces).
    callback : callable, optional
        Called with each :class:`~hope_rs.refine.Iteration` as it finishes (of the coarse
        match too, with ``multiscale``); the polish step has ``polish=True``. An exception it
        raises ends the match and propagates.
    progress : bool or callable, optional
        ``True`` draws the progress of every stage on stderr (one rewritten line on a terminal
        or in a notebook, one line per stage elsewhere; :class:`~hope_rs.progress.ProgressBar`).
        A callable receives a :class:`~hope_rs.progress.ProgressEvent` at the start and end of
        each stage (skipped ones included, with the reason) and at each refinement step (with
        the :class:`~hope_rs.refine.Iteration` that ``callback`` gets). Stages are also logged
        to ``logging.getLogger("hope_rs")`` (INFO per stage, DEBUG per step).

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
        progress=progress,
    )  # fmt: skip
    ma, mb = _as_mesh(a, k_max, "a"), _as_mesh(b, k_max, "b")
    if not isinstance(init, str):
        init = as_index_map(init, ma.n_vertices, mb.n_vertices, name="init")
    timings: dict[str, float] = {}
    sa, sb = _as_shape(ma, k_max), _as_shape(mb, k_max)
    timings["shapes"] = time.perf_counter() - t0
    if isinstance(progress, (bool, np.bool_)):  # True: the bar; False: nothing
        bar, progress = (ProgressBar() if progress else None), None
    else:
        bar = None
    log = StageLog(bar or progress, t0)
    log.ran("shapes", timings["shapes"], f"A {sa.n_vertices} vertices, B {sb.n_vertices}")
    if not isinstance(init, str):
        init = sa.map_in(sb, init)
    # The bar's line ends on every exit (an error or Ctrl-C included).
    try:
        options = {
            "schedule": schedule, "max_passes": max_passes, "min_consistent": min_consistent,
            "top_k": top_k, "polish_k": polish_k, "global_step": global_step, "callback": callback,
        }  # fmt: skip
        coarse = None
        t = time.perf_counter()
        # Both shapes or neither: a coarse copy matched against a sparser shape did worse than
        # the default path (docs/decisions.md#multiscale).
        sparse = _too_sparse_to_coarsen(sa, sb) if multiscale else None
        if multiscale and sparse is not None:
            log.skipped("coarse", f"multiscale not applied: {sparse}")
        if multiscale and sparse is None:
            from .multiscale import coarse_start, fine_passes

            # The spectral pass runs once, at the finest level it affords
            # (docs/decisions.md#spectral).
            coarse_spectral = spectral and not applies(sa, sb)
            log.start("coarse", detail="matching coarse copies of both shapes")
            relay = log.relay("coarse")
            coarse, f0 = coarse_start(
                sa, sb, init, k_max=k_max, spectral=coarse_spectral, progress=relay, **options
            )
            timings["coarse"] = time.perf_counter() - t
            n_ca, n_cb = sa.coarse_level()[1].n_vertices, sb.coarse_level()[1].n_vertices
            log.ran(
                "coarse", relay.last - t, f"coarse copies of {n_ca} and {n_cb} vertices matched"
            )
            log.ran("lift", time.perf_counter() - relay.last, "coarse map carried to every vertex")
            options["max_passes"] = min(max_passes, fine_passes(sa.n_vertices, sb.n_vertices))
            for stage in ("descriptors", "init"):
                log.skipped(stage, "multiscale: the lifted coarse map is the start")
        elif isinstance(init, str):
            t = log.start("descriptors", detail=init.upper())
            # In the shapes' internal numbering, like everything up to the result.
            da, db = sa.internal_descriptors(init), sb.internal_descriptors(init)
            timings["descriptors"] = time.perf_counter() - t
            log.ran("descriptors", timings["descriptors"], init.upper())
            t = log.start("init", detail=f"nearest {init.upper()} descriptors, one to one")
            f0 = shapes_initial_map(sa, sb, da, db, init)
            timings["init"] = time.perf_counter() - t
            log.ran("init", timings["init"], f"nearest {init.upper()} descriptors, one to one")
        else:
            f0 = init
            for stage in ("descriptors", "init"):
                log.skipped(stage, "an initial map was given (init=...)")
        f, res = refine_spectral_finish(
            sa, sb, f0, spectral=spectral, shared_faces=shared_faces, timings=timings,
            stage_log=log, **options,
        )  # fmt: skip
        hope_map = sa.map_out(sb, res.map).astype(np.int64)
        timings["total"] = time.perf_counter() - t0
        f_out, f0_out = sa.map_out(sb, f), sa.map_out(sb, f0)
        return MatchResult(
            f_out.astype(np.int64),
            f0_out.astype(np.int64),
            res.history,
            timings,
            coarse,
            hope_map,
            log.stages,
        )
    finally:
        if bar is not None:
            bar.close()


def _too_sparse_to_coarsen(sa: Shape, sb: Shape) -> str | None:
    """Why ``multiscale`` does not apply to these shapes, or ``None`` when it does."""
    for name, s in (("A", sa), ("B", sb)):
        if s.coarse_level() is None:
            return (
                f"{name} ({s.n_vertices} vertices) is too sparse to halve by vertex clustering "
                "(see hope_rs.multiscale.coarse_mesh)"
            )
    return None


def refine_spectral_finish(
    sa: Shape,
    sb: Shape,
    f0: np.ndarray,
    *,
    spectral: bool = True,
    shared_faces: bool = True,
    timings: dict[str, float] | None = None,
    on_stage=None,
    stage_log: StageLog | None = None,
    **options,
) -> tuple[np.ndarray, RefineResult]:
    """The stages of :func:`match` after the initial map ``f0`` (internal numbering): HOPE's
    refinement, the spectral pass and the shared-face finish, each where it applies.

    Returns the final map and the refinement's result.
    ``timings`` gets "refine" and, when they ran, "spectral" and "faces"; ``on_stage(name)``
    is called after each of the three (the benches record memory there); ``stage_log``
    records, logs and reports them (:class:`~hope_rs.progress.StageLog`); ``options`` go to
    :func:`~hope_rs.refine.refine`.
    """
    timings = {} if timings is None else timings
    log = StageLog() if stage_log is None else stage_log
    finishing = shared_faces and finish_applies(sa, sb)
    if finishing:
        options["last_pass_if"] = partial(qualifies, sa, sb)
    steps = _RefineSteps(sa, sb, log, options, background=spectral and applies(sa, sb))
    options["callback"] = steps
    t = log.start("refine", steps.total, f"pass 1/{steps.n_passes}")
    res = refine_while_solving_bases(sa, sb, f0, spectral, **options)
    timings["refine"] = time.perf_counter() - t
    steps.finished(timings["refine"])
    if on_stage is not None:
        on_stage("refine")
    # A map that sends every face onto a face one-to-one is already what the finish aims at,
    # and the spectral pass's region choice keeps it (it distorts no 2-ring).
    all_faces = finishing and not res.settled and bool(face_handles(sa, sb, res.map).all())
    done = res.settled or all_faces
    f = res.map
    if spectral and not done:
        t = log.start("spectral", detail="ZoomOut from HOPE's map, chosen region by region")
        f, z = spectral_refine(sa, sb, res.map, res.early_zoomout)
        if z is not None:
            timings["spectral"] = time.perf_counter() - t
            changed = int(np.count_nonzero(f != res.map))
            log.ran("spectral", timings["spectral"], f"changed {changed} of {f.size} vertices")
        else:
            log.skipped("spectral", _spectral_skip_reason(sa, sb))
    else:
        log.skipped("spectral", _done_reason(spectral, "spectral", res.settled))
    if on_stage is not None:
        on_stage("spectral")
    if finishing and not done:
        t = log.start("faces", detail="shared-face finish")
        f, rounds = finish(sa, sb, f)
        if rounds:
            timings["faces"] = time.perf_counter() - t
            log.ran("faces", timings["faces"], f"{rounds} rounds, then growth from trusted patches")
        else:
            share = float(face_handles(sa, sb, f).mean())
            need = _faces_module.MIN_HANDLES
            log.skipped(
                "faces",
                f"not applicable: {share:.1%} of A's vertices have all their faces mapped "
                f"onto faces of B (the finish needs {need:.0%} and patches to grow from)",
            )
    elif not shared_faces:
        log.skipped("faces", "turned off (shared_faces=False)")
    elif not finishing:
        log.skipped("faces", f"a shape has more than {_faces_module.MAX_VERTICES} vertices")
    else:
        log.skipped("faces", _done_reason(True, "faces", res.settled))
    if on_stage is not None:
        on_stage("faces")
    return f, res


def _done_reason(enabled: bool, flag: str, settled: bool) -> str:
    if not enabled:
        return f"turned off ({flag}=False)"
    if settled:
        return (
            "HOPE's map settled: its last pass and the polish moved no vertex and LMD trusts "
            "every vertex"
        )
    return "HOPE's map already sends every face of A onto a face of B, one to one"


def _spectral_skip_reason(sa: Shape, sb: Shape) -> str:
    if not applies(sa, sb):
        return (
            f"shapes of {sa.n_vertices} and {sb.n_vertices} vertices; the pass runs on "
            f"{_spectral_module.K_START + 2} to {_spectral_module.MAX_VERTICES}"
        )
    return "an eigenbasis could not be computed (see the warning)"


class _RefineSteps:
    """The refinement's ``callback``: logs and reports each step, labels the polish step,
    and calls the user's callback. With ``background``, the spectral pass's start is
    reported after the polish: the refinement then waits for its background work."""

    def __init__(self, sa: Shape, sb: Shape, log: StageLog, options: dict, background: bool):
        self.log, self.user, self.background = log, options.get("callback"), background
        schedule = options.get("schedule")
        if schedule is None:
            schedule = default_schedule(min(sa.k_max, sb.k_max))
        self.n_passes = options.get("max_passes", MAX_PASSES)
        self.per_pass = len(schedule) + (1 if options.get("global_step", True) else 0)
        self.total = self.n_passes * self.per_pass
        self.done, self.passes, self.t0, self.polish = 0, 0, time.perf_counter(), None

    def __call__(self, it: Iteration) -> None:
        if it.polish:
            self.polish = it
            seconds = time.perf_counter() - self.t0 - it.seconds
            self.log.ran("refine", seconds, self._summary(), self.done, self.total)
            self.log.step("polish", 1, 1, step_detail(it, self.n_passes), it)
            self.log.ran("polish", it.seconds, f"k={it.k}, changed {it.changed}", 1, 1)
            if self.background:  # the refinement now waits for the eigenbases and ZoomOut
                self.log.start("spectral", detail="finishing the eigenbases and ZoomOut")
        else:
            self.done, self.passes = self.done + 1, it.n_pass + 1
            self.log.step("refine", self.done, self.total, step_detail(it, self.n_passes), it)
        if self.user is not None:
            self.user(it)

    def _summary(self) -> str:
        return f"{self.passes} of at most {self.n_passes} passes, {self.done} steps"

    def finished(self, seconds: float) -> None:
        """After the refinement returned: records it, if the polish did not already."""
        if self.polish is None:
            self.log.ran("refine", seconds, self._summary(), self.done, self.total)
            self.log.skipped("polish", "turned off (polish_k=None)")


#: :func:`match`'s parameters, as defined here (tests may replace the module's ``match``).
_MATCH_SIGNATURE = inspect.signature(match)


def check_match_options(**options) -> None:
    """Check keyword options meant for :func:`match` (as a batch or the CLI passes them on)
    before any work: unknown names raise ``TypeError``, bad values what :func:`match` would
    raise, in one line."""
    try:
        bound = _MATCH_SIGNATURE.bind(None, None, **options)
    except TypeError as e:
        raise TypeError(f"not an option of hope_rs.match: {e}") from None
    bound.apply_defaults()
    given = {k: v for k, v in bound.arguments.items() if k not in ("a", "b")}
    check_options(**given)
