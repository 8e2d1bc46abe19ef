"""A spectral pass after HOPE: ZoomOut from HOPE's map, then a per-region choice of the two.

HOPE assigns vertices one to one by hop counts, which is exact where the two meshes share their
connectivity but leaves a vertex-level roughness where they do not: no bijection between two
triangulations exists, and every forced pairing is an edge or two off. ZoomOut (Melzi et al.
2019) turns a map into a functional map on the Laplace–Beltrami eigenbases, grows the basis
20 → 120 and reads a new map off each size; the result is smooth but rarely exact. Started
from HOPE's map, it repairs what HOPE leaves on differently triangulated pairs, while on
identically triangulated pairs it would trade HOPE's exact map for a smooth near miss (see
docs/decisions.md#spectral).

So the result takes, region by region, whichever map distorts A's 2-rings less (LMD's mean
distortion, smoothed over a few rings of A so the choice is made by regions, not vertex by
vertex): faust_reg keeps HOPE's exact map, remeshed pairs take the spectral one, and the TOSCA
cat, exact in some regions and slid in others, takes each where it is better. A last check
on distances to far-apart anchors (:func:`long_range_discrepancy`) keeps HOPE's map when the
chosen one bends them, as ZoomOut does between a partial shape and a whole one. When one shape
is a part measured at the whole's scale, ZoomOut's functional map is a slanted rectangle, not a
square (:func:`basis_slope`, ``SpectralConfig.slanted``).
"""

from __future__ import annotations

import threading
import time
import warnings
from contextlib import ExitStack

import numpy as np
import scipy.linalg
from scipy.spatial import cKDTree

from .. import _core
from .._blas import single_threaded_blas
from ..kernels.search import nearest_one
from ..shape import Shape
from .anchors import distance_fields, farthest_witnesses, reachable
from .config import RefineConfig, RepairConfig, SpectralConfig
from .landmarks import coordinate_landmarks, landmark_embedding
from .lmd import local_map_distortion
from .state import Background, MatchState, Stage


def basis_sizes(k_start: int, k_end: int, step: int) -> list[int]:
    """ZoomOut's sizes ``k_start, k_start + step, ...``, ending at ``k_end`` exactly."""
    ks = list(range(min(k_start, k_end), k_end + 1, step))
    if ks[-1] != k_end:
        ks.append(k_end)
    return ks


def zoomout(
    a: Shape,
    b: Shape,
    f: np.ndarray,
    config: SpectralConfig = SpectralConfig(),
    *,
    stop: threading.Event | None = None,
    extra: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray | None:
    """ZoomOut (Melzi et al. 2019) from the map ``f`` (A → B, internal numbering).

    At each basis size k the functional map C (k × k) is the least-squares fit, in A's mass
    inner product, of B's eigenfunctions pulled back through the current map onto A's; each
    vertex of A then takes the vertex of B whose spectral embedding mapped by C is nearest
    its own, over the basis sizes ``config.k_start`` to ``config.k_end`` in steps of
    ``config.k_step``. Returns the map at ``k_end`` (internal numbering), or None when ``stop`` was set
    (checked before each basis size). ``extra``: (n_a, j) and (n_b, j) columns appended to
    A's and to B's embeddings in every nearest-vertex search, not to the fit (the caller's
    landmark coordinates, :func:`hope_rs.pipeline.landmarks.landmark_embedding`).
    """
    phi_a, mass_a = a.spectral_basis(config.k_end)
    phi_b, _ = b.spectral_basis(config.k_end)
    # Small products (k x k fits, n x k embeddings): one BLAS thread is faster here; the
    # nearest-neighbour search splits its rows between threads itself.
    with single_threaded_blas():
        return _zoomout(a, b, f, phi_a, mass_a, phi_b, config, stop, extra)


def _zoomout(
    a: Shape,
    b: Shape,
    f: np.ndarray,
    phi_a: np.ndarray,
    mass_a: np.ndarray,
    phi_b: np.ndarray,
    cfg: SpectralConfig,
    stop: threading.Event | None = None,
    extra: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray | None:
    k_end = min(cfg.k_end, phi_a.shape[1], phi_b.shape[1])
    sa, sb = _samples(a.n_vertices, cfg.max_samples), _samples(b.n_vertices, cfg.max_samples)
    sampled = sa.size < a.n_vertices or sb.size < b.n_vertices
    near_b = _SpectralNeighbours(b)
    pa, wa = phi_a[sa], mass_a[sa]
    gram = pa.T @ (wa[:, None] * pa)  # the identity when every vertex is a sample
    t = np.asarray(f, dtype=np.int64)[sa]  # vertices of B
    slope = basis_slope(a, b) if cfg.slanted else (1.0, 1.0)
    for k in basis_sizes(cfg.k_start, k_end, cfg.k_step):
        if stop is not None and stop.is_set():
            return None
        # C is ka x kb: A's first ka functions against B's first kb (k x k for whole shapes).
        ka, kb = (max(1, round(k * s)) for s in slope)
        c = functional_map(pa[:, :ka], wa, phi_b[t, :kb], gram[:ka, :ka])
        ea, eb = pa[:, :ka], phi_b[:, :kb] @ c.T
        if extra is not None:
            ea, eb = np.hstack([ea, extra[0][sa]]), np.hstack([eb, extra[1]])
        if k >= cfg.local_from and not sampled:
            t = near_b.best(ea, eb, t, cfg.local_candidates)
            continue
        t = sb[nearest_rows(ea, eb[sb])]
        if sampled:
            # Down from B's samples to its vertices: the map the next fit reads must be as
            # sharp as the basis, or the high frequencies of C blur.
            t = near_b.best(ea, eb, t, cfg.candidates)
    if not sampled:
        return t
    # Every vertex of A, near the image of its nearest sample.
    _, own = cKDTree(a.points[sa]).query(a.points, workers=2)
    ea = phi_a[:, :ka] if extra is None else np.hstack([phi_a[:, :ka], extra[0]])
    return near_b.best(ea, eb, t[own], cfg.candidates)


def basis_slope(a: Shape, b: Shape) -> tuple[float, float]:
    """The shares (of A's, of B's) of a basis size ZoomOut uses at each step: 1 for the
    larger shape and (its area / the larger's area) for the smaller, both measured in the
    units each shape is matched in. Eigenvalue i of a surface grows like i / area (Weyl's
    law), so a part's first k·area_part/area_whole eigenfunctions span the frequencies of
    the whole's first k: the functional map between them is a slanted diagonal (partial
    functional maps, Rodolà et al. 2017), not a square one. Whole shapes, each in units of
    its own sqrt(area), get (1, 1)."""
    area_a, area_b = a.unit_area, b.unit_area
    if area_a == area_b:
        return 1.0, 1.0
    return min(1.0, area_a / area_b), min(1.0, area_b / area_a)


def functional_map(
    phi_a: np.ndarray, mass: np.ndarray, pulled_b: np.ndarray, gram: np.ndarray | None = None
) -> np.ndarray:
    """C minimising ||phi_a C - pulled_b|| in the ``mass``-weighted norm (rows are vertices of
    A; ``pulled_b`` holds B's eigenfunctions at each vertex's image), by its normal equations;
    ``gram`` is phi_aᵀ M phi_a if known. (Normal equations rather than an SVD least-squares
    solve: the eigenvectors are M-orthonormal, so the system is well conditioned.)"""
    if gram is None:
        gram = phi_a.T @ (mass[:, None] * phi_a)
    return scipy.linalg.solve(gram, phi_a.T @ (mass[:, None] * pulled_b), assume_a="pos")


def nearest_rows(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Index of the nearest row of ``y`` for each row of ``x`` (Euclidean, exhaustive): the
    initial map's float32 BLAS search. In 20-120 dimensions a k-d tree searches nearly
    everything anyway, and was slower here."""
    x32, y32 = x.astype(np.float32), y.astype(np.float32)
    return nearest_one(x32, y32, np.einsum("ij,ij->i", y32, y32))[0][:, 0]


def _samples(n: int, m: int) -> np.ndarray:
    """``min(n, m)`` vertices spread over the shape: the internal numbering follows a
    space-filling curve, so an even stride through it is an even spread in space."""
    if n <= m:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, m).round().astype(np.int64))


class _SpectralNeighbours:
    """Among the ``k`` vertices of B nearest (in space) to a guess, the one whose spectral
    embedding is nearest a query's."""

    def __init__(self, b: Shape):
        self.points = b.points
        self.near = np.empty((b.n_vertices, 0), dtype=np.int64)

    def best(self, emb_a: np.ndarray, emb_b: np.ndarray, guess: np.ndarray, k: int) -> np.ndarray:
        k = min(k, self.points.shape[0])
        if self.near.shape[1] < k:
            # Every vertex's spatial neighbours, once: a k-d tree query per call took most of
            # the call's time.
            _, near = cKDTree(self.points).query(self.points, k=k, workers=2)
            self.near = near.reshape(self.points.shape[0], -1).astype(np.int64, copy=False)
        # In Rust: NumPy gathered an (n, candidates, k) array per call.
        return _core.nearest_among(
            np.ascontiguousarray(emb_a, dtype=np.float32),
            np.ascontiguousarray(emb_b, dtype=np.float32),
            np.ascontiguousarray(self.near[guess, :k]),
        )


def choose_by_region(
    a: Shape,
    b: Shape,
    h: np.ndarray,
    z: np.ndarray,
    *,
    smoothing: int = SpectralConfig.smoothing_steps,
    margin: float = SpectralConfig.margin,
) -> np.ndarray:
    """``h`` where it distorts A's 2-rings about as little as ``z`` or less, else ``z``
    (maps A → B in internal numbering). The difference of the two maps' mean LMD is averaged
    over 1-rings ``smoothing`` times first, so that regions choose, not single vertices."""
    mh, _ = local_map_distortion(a, b, h)
    mz, _ = local_map_distortion(a, b, z)
    return _choose(a, h, z, mh.astype(np.float64) - mz, smoothing, margin)


def _choose(a: Shape, h, z, d: np.ndarray, smoothing: int, margin: float) -> np.ndarray:
    """:func:`choose_by_region` given ``d``, the per-vertex mean LMD of ``h`` minus ``z``'s."""
    if smoothing:
        p = a.ring_average()
        for _ in range(smoothing):
            d = p @ d
    return np.where(d <= margin, h, z)


def applies(a: Shape, b: Shape, config: SpectralConfig = SpectralConfig()) -> bool:
    """Whether :func:`spectral_refine` runs on these shapes: both sizes pass
    :func:`applies_to_size`."""
    return applies_to_size(a.n_vertices, config) and applies_to_size(b.n_vertices, config)


def applies_to_size(n_vertices: int, config: SpectralConfig = SpectralConfig()) -> bool:
    """At most ``config.max_vertices`` vertices, and enough for a basis of ``config.k_start``."""
    return config.k_start + 2 <= n_vertices <= config.max_vertices


class BasisPrefetch:
    """Both shapes' eigenbases for :func:`spectral_refine`, solved in a background thread while
    the caller refines.

    HOPE's auction runs on one core, and the eigensolves release the GIL, so the solves fill
    the idle core. The thread keeps the caller's CPU priority: the caller waits for its bases,
    so a lowered priority starves both on a busy machine (see ``docs/decisions.md#spectral``).

    Use it inside :func:`~hope_rs._blas.single_threaded_blas`, entered before :meth:`start`
    and left after :meth:`finish`: BLAS thread limits are global, and a limit restored while
    the solve runs would change its last bits. (Every route to a basis solves on one BLAS
    thread, so the bases are the same bits whichever way they were computed.) A failure in
    the thread is not raised: the basis is then left unset, and :func:`spectral_refine` solves
    again and reports it as usual. :meth:`cancel` stops the solve at its next step (every
    solve of the eigensolver checks :attr:`stop`).
    """

    def __init__(self, a: Shape, b: Shape, k: int):
        self.shapes = [s for s in dict.fromkeys((a, b)) if not s.has_spectral_basis(k)]
        self.k = k
        self.solved: list[tuple[Shape, tuple[np.ndarray, np.ndarray]]] = []
        self.stop = threading.Event()
        self.thread = _Background(self._run, "hope_rs-eigenbases")

    def start(self) -> BasisPrefetch:
        if self.shapes:
            self.thread.start()
        return self

    def _run(self) -> None:
        for s in self.shapes:
            try:
                self.solved.append((s, s.solve_spectral_basis(self.k, stop=self.stop)))
            except Exception:  # noqa: BLE001 - the caller solves again and reports it
                return  # Cancelled, or a failure the spectral pass meets again

    def cancel(self) -> None:
        """Tells the thread to stop at the eigensolver's next step (one shift-invert solve)
        and waits for it; bases solved before stay in :attr:`solved`."""
        self.stop.set()
        _join(self.thread)

    def finish(self) -> None:
        """Waits for the thread and stores the bases it solved in their shapes."""
        _join(self.thread)
        for s, (evecs, mass) in self.solved:
            s.set_spectral_basis(evecs, mass)


class _Background(threading.Thread):
    """A daemon thread that sets :attr:`ended` when it returns. Waiting on that event, not on
    ``Thread.join`` alone: in Python < 3.13 a join interrupted by Ctrl-C marks the running
    thread as ended, and every later join then returns while it still runs."""

    def __init__(self, target, name: str, args: tuple = ()):
        super().__init__(target=target, name=name, args=args, daemon=True)
        self.ended = threading.Event()

    def run(self) -> None:
        try:
            super().run()
        finally:
            self.ended.set()


def _join(thread: _Background | None) -> None:
    """Waits for ``thread`` if it was started."""
    if thread is not None and thread.ident is not None:
        thread.ended.wait()
        thread.join()


class EarlyZoomOut:
    """ZoomOut started from the refinement's map partway through its last pass, in a background
    thread: the pass's auctions run on one core, and ZoomOut fills the other (see
    ``SpectralConfig.early_from_pass`` for the accuracy, docs/decisions.md#spectral for the time).

    :meth:`start` answers the runner's "last_pass" event. The thread first waits for the
    :class:`BasisPrefetch` of the same match; when either basis is missing after it (its solve
    failed) it does nothing, and :func:`spectral_refine` runs ZoomOut afterwards, which solves
    the basis again and reports a failure as usual. :attr:`result` is ZoomOut's map, or None.
    """

    def __init__(
        self,
        a: Shape,
        b: Shape,
        prefetch: BasisPrefetch,
        config: SpectralConfig,
        extra: tuple[np.ndarray, np.ndarray] | None = None,
    ):
        self.a, self.b, self.prefetch, self.config = a, b, prefetch, config
        self.extra = extra
        self.thread: _Background | None = None
        self.result: np.ndarray | None = None
        self.stop = threading.Event()

    def start(self, f: np.ndarray, n_pass: int) -> None:
        if n_pass < self.config.early_from_pass or self.thread is not None:
            return
        self.thread = _Background(self._run, "hope_rs-zoomout", (np.array(f),))
        self.thread.start()

    def _run(self, f: np.ndarray) -> None:
        self.prefetch.finish()
        if self.stop.is_set():
            return
        k = self.config.k_end
        if not (self.a.has_spectral_basis(k) and self.b.has_spectral_basis(k)):
            return
        try:
            self.result = zoomout(self.a, self.b, f, self.config, stop=self.stop, extra=self.extra)
        except Exception:  # noqa: BLE001 - spectral_refine runs it again and reports it
            return

    def join(self, cancel: bool = False) -> None:
        """Waits for the thread; with ``cancel``, first tells it to stop at its next basis size
        (its result is then None)."""
        if cancel:
            self.stop.set()
        _join(self.thread)
        if cancel:
            self.result = None


def spectral_refine(
    a: Shape,
    b: Shape,
    h: np.ndarray,
    z: np.ndarray | None = None,
    config: SpectralConfig = SpectralConfig(),
    *,
    min_consistent: float = RefineConfig.min_consistent,
    repair: RepairConfig = RepairConfig(),
    extra: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """(the map chosen by region between ``h`` and ZoomOut from it, the ZoomOut map), maps in
    internal numbering. The ZoomOut map is ``None``, and ``h`` is returned unchanged, when a
    shape is too large (``config.max_vertices``), too small for a basis of ``config.k_start``
    functions, or its eigenbasis cannot be computed (a warning says so). ``z``: a ZoomOut map
    computed already (:class:`EarlyZoomOut`), used instead of one from ``h``. The anchors of
    :func:`long_range_discrepancy` are vertices both maps keep LMD-consistent (``min_consistent``).
    ``extra``: columns appended to ZoomOut's embeddings (see :func:`zoomout`)."""
    if not applies(a, b, config):
        return h, None
    try:
        if z is None:
            z = zoomout(a, b, h, config, extra=extra)
    except RuntimeError as e:  # ARPACK did not converge, or a singular factorisation
        warnings.warn(f"spectral pass skipped, HOPE's map kept: {e}", RuntimeWarning, stacklevel=3)
        return h, None
    # LMD of both maps once: the region choice reads the means, the guard's anchors the
    # consistent fractions.
    assert z is not None  # zoomout without a stop event returns a map
    mh, ch = local_map_distortion(a, b, h)
    mz, cz = local_map_distortion(a, b, z)
    f = _choose(a, h, z, mh.astype(np.float64) - mz, config.smoothing_steps, config.margin)
    if not np.array_equal(f, h):
        trusted = (ch >= min_consistent) & (cz >= min_consistent)
        d_h, d_f, d_z = long_range_discrepancy(a, b, h, trusted, [h, f, z], repair)
        bent = d_f > config.max_discrepancy_ratio * d_h
        if bent or d_z > config.max_zoomout_discrepancy_ratio * d_h:
            return h, z
    return f, z


def long_range_discrepancy(
    a: Shape,
    b: Shape,
    h: np.ndarray,
    trusted: np.ndarray,
    maps: list[np.ndarray],
    repair: RepairConfig = RepairConfig(),
) -> list[float]:
    """For each map of ``maps`` (A → B, internal numbering), the mean |d_A(p, x) - d_B(m(p),
    h(x))| over vertices p and anchors x (sqrt(area) units, edge-graph geodesics): how far the
    map bends distances to ``repair.n_anchors`` farthest-point anchors among the
    ``trusted`` vertices (a mask: those both candidate maps keep LMD-consistent).

    The choice by region compares 2-rings only. Where the two bases differ (a partial shape:
    FAUST without its legs against a whole body) ZoomOut can map a region smoothly to the wrong
    place, which its 2-rings do not show; its distances to the rest of the shape do (see
    ``SpectralConfig.max_zoomout_discrepancy_ratio`` and docs/decisions.md#spectral). On remeshed pairs
    the chosen map bends these distances as little as HOPE's or less.
    """
    cand = np.flatnonzero(trusted)
    if cand.size < 4:
        cand = np.arange(a.n_vertices)
    anchors, da = farthest_witnesses(a, cand, repair.n_anchors)
    db = distance_fields(b, h[anchors])
    seen = np.isfinite(da)  # anchors in other components of A say nothing
    db = reachable(db, repair)
    out = []
    for m in maps:
        err = np.abs(da - db[:, m])
        out.append(float(err[seen].mean()) if seen.any() else 0.0)
    return out


class SpectralBackground(Background):
    """The spectral pass's work while HOPE refines, and its BLAS scope: both eigenbases
    solved in a background thread (:class:`BasisPrefetch`) and ZoomOut started during the
    last pass (:class:`EarlyZoomOut`, from the "last_pass" event), inside one
    :func:`~hope_rs._blas.single_threaded_blas` from before the solves start to after they
    end. Leaving it waits for both threads (with ``keep``, when a spectral pass follows) or
    stops them first; :attr:`zoomout` is then the early ZoomOut's map, or None.
    """

    def __init__(self, state: MatchState):
        self.state = state
        self.extra: tuple[np.ndarray, np.ndarray] | None = None
        self.zoomout: np.ndarray | None = None
        #: When leaving began to wait for the threads (log seconds), if it did.
        self.waited_from: float | None = None
        self.prefetch: BasisPrefetch | None = None
        self.early: EarlyZoomOut | None = None
        self.blas = ExitStack()

    def start(self) -> None:
        state = self.state
        cfg, lm = state.config.spectral, state.config.landmarks
        if state.landmarks is not None and lm.zoomout_weight > 0:
            # Before the BLAS limit below, at the process's own thread count.
            self.extra = landmark_embedding(
                state.a,
                state.b,
                coordinate_landmarks(state.a, state.landmarks, lm.max_coordinates),
                lm.zoomout_weight,
                state.config.refine.repair,
                near_weight=lm.near_weight,
                near_radius=lm.near_radius,
            )
        # One BLAS thread from before the solves start to after they end (see BasisPrefetch).
        self.blas.enter_context(single_threaded_blas())
        try:
            self.prefetch = BasisPrefetch(state.a, state.b, cfg.k_end)
            self.early = EarlyZoomOut(state.a, state.b, self.prefetch, cfg, self.extra)
            self.prefetch.start()
        except BaseException:
            self.blas.close()  # the runner leaves only what it entered
            raise

    def last_pass(self, f: np.ndarray, n_pass: int) -> None:
        if self.early is not None:
            self.early.start(f, n_pass)

    def stop(self, keep: bool) -> None:
        prefetch, early = self.prefetch, self.early
        self.prefetch = self.early = None
        try:
            if prefetch is None:
                return
            assert early is not None  # made with the prefetch, in start

            def halt() -> None:
                early.stop.set()
                prefetch.stop.set()

            try:
                history = self.state.history
                if keep and history and history[-1].polish:
                    # The caller's progress callback runs here, so it is inside the try too.
                    self.waited_from = self.state.log.start(
                        "spectral", detail="finishing the eigenbases and ZoomOut"
                    )
                if not keep:
                    # Both flags before any wait, so that a second Ctrl-C during the joins
                    # below still leaves the threads stopping.
                    halt()
                early.join(cancel=not keep)
                prefetch.finish()
            except BaseException:
                # Interrupted (Ctrl-C, SIGTERM) while waiting for the results: stop the
                # threads and wait for them, so none outlives the call.
                halt()
                early.join(cancel=True)
                prefetch.finish()
                raise
            self.zoomout = early.result
        finally:
            self.blas.close()


class SpectralStage(Stage):
    """The "spectral" stage: :func:`spectral_refine` of the refinement's map, from the
    ZoomOut its :class:`SpectralBackground` started while the refinement ran, when it did.
    """

    name = "spectral"
    runs_on_final_map = False
    alongside = "refine"

    def __init__(self):
        self.work: SpectralBackground | None = None

    def attach(self, state: MatchState) -> None:
        if self._applies(state):
            state.hooks.on("last_pass", self._last_pass)

    @staticmethod
    def _applies(state: MatchState) -> bool:
        cfg = state.config.spectral
        return cfg.enabled and applies(state.a, state.b, cfg)

    def background(self, state: MatchState) -> SpectralBackground | None:
        self.work = SpectralBackground(state) if self._applies(state) else None
        return self.work

    def _last_pass(self, f: np.ndarray, n_pass: int) -> None:
        if self.work is not None:
            self.work.last_pass(f, n_pass)

    def skip_reason(self, state: MatchState):
        if not state.config.spectral.enabled:
            return "turned off (spectral=False)"
        return None

    def run(self, state: MatchState) -> None:
        a, b, cfg, work = state.a, state.b, state.config.spectral, self.work
        t = state.log.start("spectral", detail="ZoomOut from HOPE's map, chosen region by region")
        if work is not None and work.waited_from is not None:
            t = work.waited_from  # the wait for the background work is the pass's too
        h = state.f
        assert h is not None  # the refinement's map
        f, z = spectral_refine(
            a,
            b,
            h,
            None if work is None else work.zoomout,
            cfg,
            min_consistent=state.config.refine.min_consistent,
            repair=state.config.refine.repair,
            extra=None if work is None else work.extra,
        )
        if z is None:
            if not applies(a, b, cfg):
                reason = (
                    f"shapes of {a.n_vertices} and {b.n_vertices} vertices; the pass runs on "
                    f"{cfg.k_start + 2} to {cfg.max_vertices}"
                )
            else:
                reason = "an eigenbasis could not be computed (see the warning)"
            state.log.skipped("spectral", reason)
            return
        state.zoomout = z
        state.timings["spectral"] = time.perf_counter() - t
        changed = int(np.count_nonzero(f != h))
        state.log.ran(
            "spectral", state.timings["spectral"], f"changed {changed} of {f.size} vertices"
        )
        state.f = f
