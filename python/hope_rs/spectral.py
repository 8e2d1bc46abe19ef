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
chosen one bends them, as ZoomOut does between a partial shape and a whole one.
"""

from __future__ import annotations

import threading
import warnings

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from . import _core
from ._blas import single_threaded_blas
from .anchors import N_ANCHORS, distance_fields, farthest_witnesses, reachable
from .initial import _nearest_one
from .lmd import MIN_CONSISTENT, local_map_distortion
from .refine import RefineResult, refine
from .shape import Shape

#: ZoomOut's basis sizes: from K_START to K_END eigenfunctions in steps of K_STEP. A larger
#: final basis lowered the error on remeshed pairs at about a second more per 5k-vertex pair
#: (docs/decisions.md#spectral).
K_START, K_END, K_STEP = 20, 120, 5
#: ZoomOut iterates on at most this many vertices of each shape (evenly spread: a stride
#: through the position-ordered internal numbering). Each sample of A is then matched among
#: B's samples and moved to the best of the CANDIDATES vertices of B around that one; at the
#: end every vertex of A is matched among the CANDIDATES around its nearest sample's image.
MAX_SAMPLES = 8000
CANDIDATES = 32
#: From this basis size on, each vertex of a shape small enough to have no samples looks for
#: its image only among the LOCAL_CANDIDATES vertices of B nearest (in space) to its current
#: one, not among all of B: by then the map moves by a few edges per size. Sampled shapes keep
#: the search among B's samples (docs/decisions.md#spectral).
LOCAL_FROM = 60
LOCAL_CANDIDATES = 64
#: The stage is skipped when either shape has more vertices: their eigenbases alone would take
#: longer than the rest of the match.
MAX_VERTICES = 60_000
#: The chosen map is dropped for HOPE's own when its distances to trusted anchors disagree
#: more than this factor times HOPE's do (see :func:`long_range_discrepancy`).
MAX_DISCREPANCY_RATIO = 1.1
#: ... and also when ZoomOut's own map disagrees more than this factor times HOPE's: then the
#: two eigenbases do not correspond (a partial shape), and the regions taken from it are suspect
#: even when the chosen map's distances look no worse (docs/decisions.md#spectral).
MAX_ZOOMOUT_DISCREPANCY_RATIO = 1.2
#: When the refinement reaches its last pass and that pass is at least this one (0-based: the
#: fourth, the last of the default four), ZoomOut starts from the map after the pass's first
#: step, in a background thread while the rest of the pass runs, instead of after the polish
#: (see :class:`EarlyZoomOut`); the maps are the same within noise. Earlier starts, before
#: the pass's global repair, cost accuracy (docs/decisions.md#spectral).
EARLY_FROM_PASS = 3
#: Rounds of 1-ring averaging of the distortion difference before the choice.
SMOOTHING_STEPS = 32
#: HOPE's map is kept where its smoothed mean distortion exceeds the spectral map's by at most
#: this much (in A's mean edge lengths), so exact regions do not flip on noise.
MARGIN = 0.05


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
    *,
    k_start: int = K_START,
    k_end: int = K_END,
    step: int = K_STEP,
    max_samples: int = MAX_SAMPLES,
    stop: threading.Event | None = None,
) -> np.ndarray | None:
    """ZoomOut (Melzi et al. 2019) from the map ``f`` (A → B, internal numbering).

    At each basis size k the functional map C (k × k) is the least-squares fit, in A's mass
    inner product, of B's eigenfunctions pulled back through the current map onto A's; each
    vertex of A then takes the vertex of B whose spectral embedding mapped by C is nearest
    its own. Returns the map at ``k_end`` (internal numbering), or None when ``stop`` was set
    (checked before each basis size).
    """
    phi_a, mass_a = a.spectral_basis(k_end)
    phi_b, _ = b.spectral_basis(k_end)
    # Small products (k x k fits, n x k embeddings): one BLAS thread is faster here; the
    # nearest-neighbour search splits its rows between threads itself.
    with single_threaded_blas():
        return _zoomout(a, b, f, phi_a, mass_a, phi_b, k_start, k_end, step, max_samples, stop)


def _zoomout(
    a: Shape,
    b: Shape,
    f: np.ndarray,
    phi_a: np.ndarray,
    mass_a: np.ndarray,
    phi_b: np.ndarray,
    k_start: int,
    k_end: int,
    step: int,
    max_samples: int,
    stop: threading.Event | None = None,
) -> np.ndarray | None:
    k_end = min(k_end, phi_a.shape[1], phi_b.shape[1])
    sa, sb = _samples(a.n_vertices, max_samples), _samples(b.n_vertices, max_samples)
    sampled = sa.size < a.n_vertices or sb.size < b.n_vertices
    near_b = _SpectralNeighbours(b)
    pa, wa = phi_a[sa], mass_a[sa]
    gram = pa.T @ (wa[:, None] * pa)  # the identity when every vertex is a sample
    t = np.asarray(f, dtype=np.int64)[sa]  # vertices of B
    for k in basis_sizes(k_start, k_end, step):
        if stop is not None and stop.is_set():
            return None
        c = functional_map(pa[:, :k], wa, phi_b[t, :k], gram[:k, :k])
        eb = phi_b[:, :k] @ c.T
        if k >= LOCAL_FROM and not sampled:
            t = near_b.best(pa[:, :k], eb, t, LOCAL_CANDIDATES)
            continue
        t = sb[nearest_rows(pa[:, :k], eb[sb])]
        if sampled:
            # Down from B's samples to its vertices: the map the next fit reads must be as
            # sharp as the basis, or the high frequencies of C blur.
            t = near_b.best(pa[:, :k], eb, t)
    if not sampled:
        return t
    # Every vertex of A, near the image of its nearest sample.
    from scipy.spatial import cKDTree

    _, own = cKDTree(a.points[sa]).query(a.points, workers=2)
    return near_b.best(phi_a[:, :k], eb, t[own])


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
    return _nearest_one(x32, y32, np.einsum("ij,ij->i", y32, y32))[0][:, 0]


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

    def best(
        self, emb_a: np.ndarray, emb_b: np.ndarray, guess: np.ndarray, k: int = CANDIDATES
    ) -> np.ndarray:
        k = min(k, self.points.shape[0])
        if self.near.shape[1] < k:
            # Every vertex's spatial neighbours, once: a k-d tree query per call took most of
            # the call's time.
            from scipy.spatial import cKDTree

            _, near = cKDTree(self.points).query(self.points, k=k, workers=2)
            self.near = near.reshape(self.points.shape[0], -1).astype(np.int64, copy=False)
        # In Rust: NumPy gathered an (n, CANDIDATES, k) array per call.
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
    smoothing: int = SMOOTHING_STEPS,
    margin: float = MARGIN,
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
        p = _ring_average(a)
        for _ in range(smoothing):
            d = p @ d
    return np.where(d <= margin, h, z)


def _ring_average(a: Shape) -> sp.csr_matrix:
    """The operator averaging a vertex function over each closed 1-ring of A (internal)."""
    n = a.n_vertices
    e = a.edges
    rows = np.concatenate([e[:, 0], e[:, 1], np.arange(n)])
    cols = np.concatenate([e[:, 1], e[:, 0], np.arange(n)])
    m = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    return sp.diags(1.0 / np.asarray(m.sum(axis=1)).ravel()) @ m


def applies(a: Shape, b: Shape) -> bool:
    """Whether :func:`spectral_refine` runs on these shapes: both sizes pass
    :func:`applies_to_size`."""
    return applies_to_size(a.n_vertices) and applies_to_size(b.n_vertices)


def applies_to_size(n_vertices: int) -> bool:
    """At most :data:`MAX_VERTICES` vertices, and enough for a basis of :data:`K_START`."""
    return K_START + 2 <= n_vertices <= MAX_VERTICES


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

    def __init__(self, a: Shape, b: Shape, k: int = K_END):
        self.shapes = [s for s in dict.fromkeys((a, b)) if not s.has_spectral_basis(k)]
        self.k = k
        self.solved: list[tuple[Shape, tuple[np.ndarray, np.ndarray]]] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, name="hope_rs-eigenbases", daemon=True)

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


def _join(thread: threading.Thread | None) -> None:
    """Waits for ``thread`` if it was started."""
    if thread is not None and thread.ident is not None:
        thread.join()


def _pass_zoomout(
    a: Shape, b: Shape, f: np.ndarray, stop: threading.Event | None = None
) -> np.ndarray | None:
    """The spectral pass's ZoomOut, with the module's basis sizes as they are when called."""
    return zoomout(
        a, b, f, k_start=K_START, k_end=K_END, step=K_STEP, max_samples=MAX_SAMPLES, stop=stop
    )


class EarlyZoomOut:
    """ZoomOut started from the refinement's map partway through its last pass, in a background
    thread: the pass's auctions run on one core, and ZoomOut fills the other (see
    :data:`EARLY_FROM_PASS` for the accuracy, docs/decisions.md#spectral for the time).

    :meth:`start` is the refinement's ``on_last_pass`` hook. The thread first waits for the
    :class:`BasisPrefetch` of the same match; when either basis is missing after it (its solve
    failed) it does nothing, and :func:`spectral_refine` runs ZoomOut afterwards, which solves
    the basis again and reports a failure as usual. :attr:`result` is ZoomOut's map, or None.
    """

    def __init__(self, a: Shape, b: Shape, prefetch: BasisPrefetch):
        self.a, self.b, self.prefetch = a, b, prefetch
        self.thread: threading.Thread | None = None
        self.result: np.ndarray | None = None
        self.stop = threading.Event()

    def start(self, f: np.ndarray, n_pass: int) -> None:
        if n_pass < EARLY_FROM_PASS or self.thread is not None:
            return
        self.thread = threading.Thread(
            target=self._run, args=(np.array(f),), name="hope_rs-zoomout", daemon=True
        )
        self.thread.start()

    def _run(self, f: np.ndarray) -> None:
        self.prefetch.finish()
        if self.stop.is_set():
            return
        if not (self.a.has_spectral_basis(K_END) and self.b.has_spectral_basis(K_END)):
            return
        try:
            self.result = _pass_zoomout(self.a, self.b, f, self.stop)
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


def refine_while_solving_bases(
    a: Shape, b: Shape, f0: np.ndarray, spectral: bool = True, **options
) -> RefineResult:
    """:func:`hope_rs.refine.refine` of ``f0``, with both shapes' eigenbases for
    :func:`spectral_refine` solved meanwhile (:class:`BasisPrefetch`) and ZoomOut started during
    the last pass (:class:`EarlyZoomOut`, its map in the result's ``early_zoomout``) when
    ``spectral`` and the pass applies to these shapes; the refinement's result.

    Both threads have ended when this returns or raises: on an error, Ctrl-C or a raising
    ``callback``, and when the map settled (no spectral pass follows), they are told to stop
    first (within one solver step or basis size); bases solved by then stay in the shapes."""
    if not (spectral and applies(a, b)):
        return refine(a, b, f0, **options)
    # One BLAS thread from before the solves start to after they end (see BasisPrefetch).
    with single_threaded_blas():
        prefetch = BasisPrefetch(a, b)
        early = EarlyZoomOut(a, b, prefetch)
        res = None
        try:
            prefetch.start()
            res = refine(a, b, f0, on_last_pass=early.start, **options)
        finally:
            # A settled map skips the spectral pass (see hope_rs.match), as does an error: no
            # need to wait for either thread's work then.
            if res is None or res.settled:
                # Both flags before any wait, so that a second Ctrl-C during the joins below
                # still leaves the threads stopping.
                early.stop.set()
                prefetch.stop.set()
            early.join(cancel=res is None or res.settled)
            prefetch.finish()
    res.early_zoomout = early.result
    return res


def spectral_refine(
    a: Shape, b: Shape, h: np.ndarray, z: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """(the map chosen by region between ``h`` and ZoomOut from it, the ZoomOut map), maps in
    internal numbering. The ZoomOut map is ``None``, and ``h`` is returned unchanged, when a
    shape is too large (:data:`MAX_VERTICES`), too small for a basis of :data:`K_START`
    functions, or its eigenbasis cannot be computed (a warning says so). ``z``: a ZoomOut map
    computed already (:class:`EarlyZoomOut`), used instead of one from ``h``."""
    if not applies(a, b):
        return h, None
    try:
        if z is None:
            z = _pass_zoomout(a, b, h)
    except RuntimeError as e:  # ARPACK did not converge, or a singular factorisation
        warnings.warn(f"spectral pass skipped, HOPE's map kept: {e}", RuntimeWarning, stacklevel=3)
        return h, None
    # LMD of both maps once: the region choice reads the means, the guard's anchors the
    # consistent fractions.
    mh, ch = local_map_distortion(a, b, h)
    mz, cz = local_map_distortion(a, b, z)
    f = _choose(a, h, z, mh.astype(np.float64) - mz, SMOOTHING_STEPS, MARGIN)
    if not np.array_equal(f, h):
        trusted = (ch >= MIN_CONSISTENT) & (cz >= MIN_CONSISTENT)
        d_h, d_f, d_z = long_range_discrepancy(a, b, h, trusted, [h, f, z])
        if d_f > MAX_DISCREPANCY_RATIO * d_h or d_z > MAX_ZOOMOUT_DISCREPANCY_RATIO * d_h:
            return h, z
    return f, z


def long_range_discrepancy(
    a: Shape, b: Shape, h: np.ndarray, trusted: np.ndarray, maps: list[np.ndarray]
) -> list[float]:
    """For each map of ``maps`` (A → B, internal numbering), the mean |d_A(p, x) - d_B(m(p),
    h(x))| over vertices p and anchors x (sqrt(area) units, edge-graph geodesics): how far the
    map bends distances to :data:`~hope_rs.anchors.N_ANCHORS` farthest-point anchors among the
    ``trusted`` vertices (a mask: those both candidate maps keep LMD-consistent).

    The choice by region compares 2-rings only. Where the two bases differ (a partial shape:
    FAUST without its legs against a whole body) ZoomOut can map a region smoothly to the wrong
    place, which its 2-rings do not show; its distances to the rest of the shape do (see
    :data:`MAX_ZOOMOUT_DISCREPANCY_RATIO` and docs/decisions.md#spectral). On remeshed pairs
    the chosen map bends these distances as little as HOPE's or less.
    """
    cand = np.flatnonzero(trusted)
    if cand.size < 4:
        cand = np.arange(a.n_vertices)
    anchors, da = farthest_witnesses(a, cand, N_ANCHORS)
    db = distance_fields(b, h[anchors])
    seen = np.isfinite(da)  # anchors in other components of A say nothing
    db = reachable(db)
    out = []
    for m in maps:
        err = np.abs(da - db[:, m])
        out.append(float(err[seen].mean()) if seen.any() else 0.0)
    return out
