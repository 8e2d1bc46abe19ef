"""The HOPE refinement loop: re-assign every vertex to maximise k-hop overlap of witnesses."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import _core
from ._blas import with_single_threaded_blas
from .anchors import anchor_step, swapped_regions
from .lmd import MIN_CONSISTENT, LmdTracker
from .shape import Shape

#: Candidates kept per row of the overlap cost (plus the current match).
TOP_K = 48
#: First auction epsilon at least (value range) / this: top-k overlap costs push some vertices
#: far down their rows, and a coarse first phase solves them faster than the solver's
#: general-purpose default (``auction_assignment_int_with`` in src/auction.rs;
#: docs/decisions.md#auction).
AUCTION_FLOOR_DIV = 16


def default_schedule(k_max: int) -> list[int]:
    """One pass: k going k_max → 1. Coarse neighbourhoods first fix large errors, fine ones then
    sharpen (docs/decisions.md#schedule)."""
    return list(range(k_max, 0, -1))


#: At most this many passes of the schedule. Pairs whose vertices keep trading places run to the
#: limit, so it sets their time; more passes did not pay (docs/decisions.md#stopping).
MAX_PASSES = 4
#: Stop after a pass that changed fewer than this fraction of the vertices.
CONVERGED_FRACTION = 0.01
#: With the global step, also stop (from the fourth pass on) when a pass shrank the share of
#: vertices LMD distrusts by less than this fraction of itself: differently triangulated pairs
#: never reach :data:`CONVERGED_FRACTION`, but their witness share levels off. Relative, since
#: same-connectivity pairs still gain near 1; not earlier, since early passes can lower the
#: share while they fix the map (docs/decisions.md#stopping).
MIN_UNTRUSTED_DROP = 0.1
#: From this pass (0-based) on, the global repair also checks long-range distances
#: (:func:`~hope_rs.anchors.anchor_step`): LMD looks at 2-rings only, so a region mapped
#: consistently onto its mirror image passes it. Every later pass checks again (a mirrored
#: region one check halves survives otherwise); not the first pass, where on the initial map
#: it flags right vertices (docs/decisions.md#global-repair).
GLOBAL_CHECK_PASS = 1
#: From this pass (0-based) on, a witness's current match is worth :data:`STAY_COUNTS` more
#: overlap counts, so it moves only for a clear gain: between different triangulations the
#: one-to-one steps otherwise trade witnesses between equal overlaps and slide the map. Earlier
#: passes still move everything (they fix the initial map's large errors); a stronger hold
#: keeps identically triangulated pairs from exact, since a witness one vertex off must still
#: be able to move (docs/decisions.md#stay).
STAY_PASS = 2
STAY_COUNTS = 1
#: From this pass (0-based) on, each pass first moves back whole regions that LMD trusts
#: but whose distances to the rest of the shape say they sit in the wrong place
#: (:func:`~hope_rs.anchors.swapped_regions`).
REGION_CHECK_PASS = 1
#: Hop radius of the final polishing step (each vertex takes its best overlap, not one-to-one).
POLISH_K = 3
#: Unused vertices ranked per group of duplicates beyond twice its size, in each round of
#: :func:`nearest_unused`.
NEAREST_UNUSED_K = 16


@dataclass
class Iteration:
    """What one refinement step did."""

    #: Hop radius of the step; 0 for a global repair step (:func:`global_repair`).
    k: int
    witness_fraction: float
    changed: int
    seconds: float
    #: The 0-based pass the step belongs to (the polish: the last pass that ran).
    n_pass: int = 0
    #: The final polishing step (see ``polish_k``), not a step of a pass.
    polish: bool = False


@dataclass
class RefineResult:
    map: np.ndarray
    history: list[Iteration] = field(default_factory=list)
    #: ZoomOut's map computed while the last pass ran (set by
    #: :func:`~hope_rs.spectral.refine_while_solving_bases`), else None.
    early_zoomout: np.ndarray | None = None
    #: The last pass and the polish moved no vertex, and LMD trusts every vertex of the map: a
    #: fixed point of the steps that keeps every 2-ring's distances (see :func:`refine`).
    settled: bool = False


# One BLAS thread: the products here are small (the global repair's projections), and
# OpenBLAS's spinning idle workers would take a core from rayon.
@with_single_threaded_blas
def refine(
    a: Shape,
    b: Shape,
    f0: np.ndarray,
    *,
    schedule: list[int] | None = None,
    max_passes: int = MAX_PASSES,
    min_consistent: float = MIN_CONSISTENT,
    top_k: int = TOP_K,
    min_witness_fraction: float = 0.1,
    polish_k: int | None = POLISH_K,
    global_step: bool = True,
    callback=None,
    on_last_pass=None,
    last_pass_if=None,
) -> RefineResult:
    """Refine the map ``f0`` (A → B) with HOPE.

    ``f0`` and the result are in the shapes' internal numbering (see :class:`~hope_rs.Shape`;
    :func:`hope_rs.match` translates), as are the maps of every function of this module.

    The schedule (k_max → 1 by default) is repeated until a pass changes fewer than
    :data:`CONVERGED_FRACTION` of the vertices, or ``max_passes`` passes. Each step selects
    witnesses by LMD, builds the overlap cost at hop radius k and solves the one-to-one
    assignment that maximises it. When LMD trusts fewer than ``min_witness_fraction`` of the
    vertices, every vertex votes instead: wrong votes scatter while right ones agree, so the
    overlap still points the right way.

    A last step at hop radius ``polish_k`` lets every vertex take its best-overlapping candidate
    without the one-to-one constraint. When the shapes are triangulated differently no bijection
    between their vertices exists, and forcing one leaves many vertices an edge or two off; on
    identically triangulated pairs the polish changes nothing (docs/decisions.md#polish).
    ``None`` keeps the one-to-one map.

    With ``global_step`` each pass starts with :func:`global_repair`, which re-places the
    vertices LMD does not trust by their geodesic distances to trusted ones; it is recorded in
    the history as a step with k = 0. The k-hop steps alone win back a wrongly matched region
    a few hops per pass (docs/decisions.md#global-repair). From the second pass on, the
    repair also distrusts vertices whose long-range distances disagree (see
    :data:`GLOBAL_CHECK_PASS`), which LMD alone cannot see, and is preceded by a step that
    moves back whole regions mapped to the wrong place (:data:`REGION_CHECK_PASS`).

    ``on_last_pass(f, n_pass)``, if given, is called once the first step of the last pass has
    run, with the map then (internal numbering) and the pass's 0-based index;
    :func:`~hope_rs.spectral.refine_while_solving_bases` starts ZoomOut there.

    ``last_pass_if(f)``, if given, is called with the map at the start of every pass from the
    second on; once it returns True, that pass is the last (and ``on_last_pass`` fires in it).
    :func:`hope_rs.match` stops there when the finishing rounds of
    :mod:`hope_rs.shared_faces` will take over.
    """
    k_max = min(a.k_max, b.k_max)
    schedule = list(schedule) if schedule is not None else default_schedule(k_max)
    if not schedule or any(not 1 <= k <= k_max for k in schedule):
        raise ValueError(f"every k of the schedule must be in [1, {k_max}], got {schedule}")
    f = np.ascontiguousarray(f0, dtype=np.int64)
    lmd = LmdTracker(a, b)
    history: list[Iteration] = []
    last_fraction = -1.0
    last_pass_changed = -1
    last_pass = max_passes - 1
    for n_pass in range(max_passes):
        changed_in_pass = 0
        if last_pass_if is not None and 1 <= n_pass < last_pass and last_pass_if(f):
            last_pass = n_pass
        if global_step:
            t0 = time.perf_counter()
            w = lmd.witnesses(f, min_consistent=min_consistent)
            untrusted, before = 1.0 - w.mean(), 1.0 - last_fraction
            if n_pass >= 3 and untrusted > before * (1.0 - MIN_UNTRUSTED_DROP):
                break  # the last pass did not gain: keep its map, skip the repair
            last_fraction = float(w.mean())
            f_new = f
            if n_pass >= REGION_CHECK_PASS:
                f_new = swapped_regions(a, b, f, lmd.local_map_distortion(f)[1])
                if f_new is not f:
                    w = lmd.witnesses(f_new, min_consistent=min_consistent)
            check = n_pass >= GLOBAL_CHECK_PASS
            f_new = global_repair(a, b, f_new, w, min_consistent, global_check=check, lmd=lmd)
            changed = int(np.count_nonzero(f_new != f))
            changed_in_pass += changed
            f = f_new
            history.append(Iteration(0, float(w.mean()), changed, time.perf_counter() - t0, n_pass))
            if callback is not None:
                callback(history[-1])
        for step, k in enumerate(schedule):
            t0 = time.perf_counter()
            w = voters(lmd, f, min_consistent, min_witness_fraction)
            stay = STAY_COUNTS if n_pass >= STAY_PASS and not w.all() else 0
            f_new = assign_by_overlap(a, b, k, f, w, top_k=top_k, stay=stay)
            changed = int(np.count_nonzero(f_new != f))
            changed_in_pass += changed
            f = f_new
            history.append(Iteration(k, float(w.mean()), changed, time.perf_counter() - t0, n_pass))
            if callback is not None:
                callback(history[-1])
            if on_last_pass is not None and n_pass == last_pass and step == 0:
                on_last_pass(f, n_pass)
        last_pass_changed = changed_in_pass
        if changed_in_pass < CONVERGED_FRACTION * a.n_vertices or n_pass == last_pass:
            break
    settled = last_pass_changed == 0
    if polish_k is not None:
        t0 = time.perf_counter()
        k = min(polish_k, k_max)
        w = voters(lmd, f, min_consistent, min_witness_fraction)
        f_new = best_overlap(a, b, k, f, w)
        history.append(
            Iteration(
                k,
                float(w.mean()),
                int(np.count_nonzero(f_new != f)),
                time.perf_counter() - t0,
                history[-1].n_pass if history else 0,
                polish=True,
            )
        )
        settled = settled and history[-1].changed == 0
        f = f_new
        if callback is not None:
            callback(history[-1])
    settled = settled and bool(lmd.witnesses(f, min_consistent=min_consistent).all())
    return RefineResult(f, history, settled=settled)


def global_repair(
    a: Shape,
    b: Shape,
    f,
    w,
    min_consistent: float,
    *,
    global_check: bool = False,
    lmd: LmdTracker | None = None,
) -> np.ndarray:
    """:func:`~hope_rs.anchors.anchor_step` on ``w``, the LMD witnesses of ``f``, keeping a moved
    vertex only where it then passes LMD itself (the anchor coordinates are coarser than a k-hop
    step, so elsewhere the old match is at least as good). ``global_check``: see
    :func:`~hope_rs.anchors.anchor_step`; ``lmd``: the tracker of the caller's maps, if any."""
    g = anchor_step(a, b, f, w, global_check=global_check)
    if g is f:
        return f
    ok = (lmd or LmdTracker(a, b)).witnesses(g, min_consistent=min_consistent)
    return np.where(ok | (g == f), g, f)


def voters(lmd: LmdTracker, f, min_consistent: float, min_fraction: float) -> np.ndarray:
    """The LMD witnesses of ``f``, or every vertex when fewer than ``min_fraction`` qualify."""
    w = lmd.witnesses(f, min_consistent=min_consistent)
    return w if w.mean() >= min_fraction else np.ones_like(w)


def assign_by_overlap(
    a: Shape, b: Shape, k: int, f, witnesses, *, top_k: int = TOP_K, stay: int = 0
) -> np.ndarray:
    """One HOPE step: the one-to-one map maximising the k-hop overlap of the witnesses.

    The current match is worth a quarter of one overlap count, so a vertex moves only when the
    overlap gains. Every row also keeps one column of an injective completion of ``f``, so a
    one-to-one assignment always exists even when ``f`` maps several vertices to one. Vertices
    of A that the assignment leaves out (when A has more vertices than B) take their best
    candidate. With ``stay`` > 0, the current match of each witness is worth that many overlap
    counts more (see :data:`STAY_PASS`).
    """
    if not 0 <= stay <= 1000:
        raise ValueError(f"stay must be in [0, 1000] overlap counts, got {stay}")
    keep = injective_completion(f, b.n_vertices, b.points)
    # ``keep`` is a full assignment inside the pattern, which spares the solver its
    # feasibility search.
    hint = keep if a.n_vertices <= b.n_vertices else _hint_rows(keep)
    # The cost is built and solved in one Rust call (src/step.rs), so it never makes the round
    # trip through NumPy; rows left out take their best column there.
    return _core.overlap_assignment_graphs(
        *_step_args(a, b, k, f, witnesses), top_k, keep, hint, AUCTION_FLOOR_DIV, stay
    )


def best_overlap(a: Shape, b: Shape, k: int, f, witnesses) -> np.ndarray:
    """Each vertex's best-overlapping vertex of B (ties kept at the current match): the cost of
    :func:`assign_by_overlap` without the one-to-one constraint."""
    return _core.best_overlap_graphs(*_step_args(a, b, k, f, witnesses), TOP_K)


def _step_args(a: Shape, b: Shape, k: int, f, witnesses) -> tuple:
    """The leading arguments of the Rust step functions: both graphs, k, the map, the voters."""
    return (
        a.graph,
        b.graph,
        k,
        np.ascontiguousarray(f, dtype=np.int64),
        np.ascontiguousarray(witnesses, dtype=bool),
    )


def _hint_rows(keep: np.ndarray) -> np.ndarray:
    """``keep`` with every repeat of a column set to -1: a one-to-one partial assignment that
    covers all n_b columns when A has more vertices than B."""
    _, first = np.unique(keep, return_index=True)
    hint = np.full_like(keep, -1)
    hint[first] = keep[first]
    return hint


def injective_completion(f: np.ndarray, n_b: int, points: np.ndarray | None = None) -> np.ndarray:
    """A map as close to ``f`` as possible that is one-to-one on min(n_a, n_b) vertices: the
    first vertex mapped to each column keeps it, later duplicates take unused columns.

    With ``points`` (B's vertex positions) each duplicate takes the unused column nearest to its
    current image, closest pairs first. Without them the duplicates take the unused columns in
    index order, which ties the result to how the two meshes happen to be numbered: on a pair
    numbered alike (TOSCA cat0 → cat6, whose ground truth is the identity) the k-th duplicate
    then lands near its true match, which leaks the ground truth into the cost
    (docs/decisions.md#numbering). Only the refinement's cost needs this, so ``points`` is
    optional for other callers.
    """
    f = np.asarray(f, dtype=np.int64)
    _, first = np.unique(f, return_index=True)
    dup = np.ones(f.size, dtype=bool)
    dup[first] = False
    dup_rows = np.flatnonzero(dup)
    used = np.zeros(n_b, dtype=bool)
    used[f] = True
    free = np.flatnonzero(~used)
    g = f.copy()
    if points is None:
        m = min(dup_rows.size, free.size)
        g[dup_rows[:m]] = free[:m]
        return g
    if dup_rows.size and free.size:
        rows, cols = nearest_unused(f[dup_rows], free, points)
        g[dup_rows[rows]] = cols
    return g


def nearest_unused(
    images: np.ndarray, free: np.ndarray, points: np.ndarray, k: int = NEAREST_UNUSED_K
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs duplicates, given by their images (vertices of B), with the unused vertices
    ``free``, closest pairs first (Euclidean, over ``points``): min(len(images), len(free))
    pairs, as (indices into ``images``, vertices of ``free``).

    Duplicates that share an image are one group with that many places to fill: each round
    ranks every group's ``2 * places + k`` nearest unused vertices by distance and keeps pairs in
    that order while the vertex is unused and the group has places left
    (``_core.greedy_pairs``); groups left short try again with the vertices still unused.
    """
    from scipy.spatial import cKDTree

    n_pairs = min(images.size, free.size)
    image, group, places = np.unique(images, return_inverse=True, return_counts=True)
    members = np.argsort(group, kind="stable")  # positions in `images`, grouped by image
    first = np.concatenate([[0], np.cumsum(places)[:-1]])
    left = places.copy()  # places still to fill per group
    unused = free
    out_rows, out_cols, paired = [], [], 0
    while paired < n_pairs:
        tree = cKDTree(points[unused])
        live = np.flatnonzero(left > 0)
        # Query sizes rounded up to powers of two, so that one query serves many groups.
        want = 2 ** np.ceil(np.log2(2 * left[live] + k)).astype(np.int64)
        want = np.minimum(unused.size, want)
        cand = []  # (distance, group, position in `unused`) per query size
        for kk in np.unique(want):
            g = live[want == kk]
            d, j = tree.query(points[image[g]], k=int(kk))
            d, j = d.reshape(g.size, -1), j.reshape(g.size, -1)
            cand.append((d.ravel(), np.repeat(g, d.shape[1]), j.ravel()))
        d, g, j = (np.concatenate(x) for x in zip(*cand))
        order = np.argsort(d, kind="stable")
        r, c = _core.greedy_pairs(g[order], j[order], left, unused.size)
        if r.size == 0:  # cannot happen (the closest candidate pair is always free): no hang
            break
        # The r-th pair of a group fills its next place, in the order the pairs were kept.
        by_group = np.argsort(r, kind="stable")
        r, c = r[by_group], c[by_group]
        start = np.searchsorted(r, r)  # first kept pair of each pair's group
        rank = np.arange(r.size) - start
        out_rows.append(members[first[r] + (places[r] - left[r]) + rank])
        out_cols.append(unused[c])
        left -= np.bincount(r, minlength=left.size)
        paired += r.size
        still = np.ones(unused.size, dtype=bool)
        still[c] = False
        unused = unused[still]
    if not out_rows:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate(out_rows), np.concatenate(out_cols)
