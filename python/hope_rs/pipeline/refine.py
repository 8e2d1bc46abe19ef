"""HOPE's refinement: re-assign every vertex to maximise the k-hop overlap of witnesses.

:func:`refine` is the loop; :class:`RefineStage` runs it as the "refine" and "polish" stages of
a match and publishes the refinement's events to the other stages (see
:data:`hope_rs.pipeline.state.EVENTS`).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .. import _core
from .._blas import with_single_threaded_blas
from ..kernels.maps import hint_rows, injective_completion
from ..shape import Shape
from .anchors import anchor_step, swapped_regions
from .config import LandmarkConfig, RefineConfig, RepairConfig
from .landmarks import LandmarkCoordinates, pin
from .lmd import LmdTracker
from .progress import StageLog, step_detail
from .state import Iteration, MatchState, Stage, StepClock
from .turned import TurnedFaces

__all__ = [
    "Iteration",
    "RefineResult",
    "RefineStage",
    "assign_by_overlap",
    "best_overlap",
    "default_schedule",
    "global_repair",
    "refine",
]


def default_schedule(k_max: int) -> list[int]:
    """One pass: k going k_max → 1. Coarse neighbourhoods first fix large errors, fine ones then
    sharpen (docs/decisions.md#schedule)."""
    return list(range(k_max, 0, -1))


@dataclass
class RefineResult:
    map: np.ndarray
    history: list[Iteration] = field(default_factory=list)
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
    config: RefineConfig = RefineConfig(),
    *,
    callback=None,
    on_last_pass=None,
    last_pass_if=None,
    landmarks: np.ndarray | None = None,
    landmark_config: LandmarkConfig = LandmarkConfig(),
    clock: StepClock | None = None,
) -> RefineResult:
    """Refine the map ``f0`` (A → B) with HOPE.

    ``f0`` and the result are in the shapes' internal numbering (see :class:`~hope_rs.Shape`;
    :func:`hope_rs.match` translates), as are the maps of every function of this module.

    The schedule (k_max → 1 by default) is repeated until a pass changes fewer than
    ``config.converged_fraction`` of the vertices, or ``config.max_passes`` passes. Each step selects
    witnesses by LMD, builds the overlap cost at hop radius k and solves the one-to-one
    assignment that maximises it. When LMD trusts fewer than ``config.min_witness_fraction`` of the
    vertices, every vertex votes instead: wrong votes scatter while right ones agree, so the
    overlap still points the right way.

    A last step at hop radius ``config.polish_k`` lets every vertex take its best-overlapping candidate
    without the one-to-one constraint. When the shapes are triangulated differently no bijection
    between their vertices exists, and forcing one leaves many vertices an edge or two off; on
    identically triangulated pairs the polish changes nothing (docs/decisions.md#polish).
    ``None`` keeps the one-to-one map.

    With ``config.global_step`` each pass starts with :func:`global_repair`, which re-places the
    vertices LMD does not trust by their geodesic distances to trusted ones; it is recorded in
    the history as a step with k = 0. The k-hop steps alone win back a wrongly matched region
    a few hops per pass (docs/decisions.md#global-repair). From the second pass on, the
    repair also distrusts vertices whose long-range distances disagree (see
    ``config.global_check_pass``), which LMD alone cannot see, and is preceded by a step that
    moves back whole regions mapped to the wrong place (``config.region_check_pass``).

    ``on_last_pass(f, n_pass)``, if given, is called once the first step of the last pass has
    run, with the map then (internal numbering) and the pass's 0-based index
    (the runner's "last_pass" event).

    ``last_pass_if(f)``, if given, is called with the map at the start of every pass from the
    second on; once it returns True, that pass is the last (and ``on_last_pass`` fires in it).
    (the runner's "stop_refining" question: the shared-face finish stops the refinement
    there when its rounds will take over).

    ``landmarks`` ((m, 2) internal vertex pairs, or None) are mapped exactly after every step
    and always witnesses; a vertex whose match fits its distances to them far worse than it
    could (``landmark_config.max_gap``) is never one, and the swapped-region step (and with
    ``landmark_config.repair_anchors`` the global repair) takes them as anchors
    (:mod:`hope_rs.pipeline.landmarks`).

    ``clock``, if given, adds up the k-hop steps' cost and assignment seconds (each step's
    own are in its :class:`Iteration`).
    """
    clock = StepClock() if clock is None else clock
    k_max = min(a.k_max, b.k_max)
    cfg, min_consistent = config, config.min_consistent
    schedule = list(cfg.schedule) if cfg.schedule is not None else default_schedule(k_max)
    if not schedule or any(not 1 <= k <= k_max for k in schedule):
        raise ValueError(f"every k of the schedule must be in [1, {k_max}], got {schedule}")
    f = np.ascontiguousarray(f0, dtype=np.int64)
    lmd = LmdTracker(a, b)
    turned = None
    if cfg.max_turned is not None:
        turned = functools.partial(TurnedFaces(a, b).vertices, max_share=cfg.max_turned)
    coords = fixed = None
    if landmarks is not None:
        coords = LandmarkCoordinates(a, b, landmarks, cfg.repair)
        fixed = coords.da, coords.db
        f = pin(f, landmarks)

    def trusted(w: np.ndarray, f: np.ndarray) -> np.ndarray:
        """The witnesses ``w`` of ``f`` as the landmarks judge them."""
        if coords is None:
            return w
        # A new array: ``w`` may be the tracker's own.
        w = (
            w & ~coords.off(f, landmark_config.max_gap)
            if landmark_config.refine_trust
            else w.copy()
        )
        assert landmarks is not None  # coords come with landmarks
        w[landmarks[:, 0]] = True
        return w

    history: list[Iteration] = []
    last_fraction = -1.0
    last_pass_changed = -1
    last_pass = cfg.max_passes - 1
    for n_pass in range(cfg.max_passes):
        changed_in_pass = 0
        if last_pass_if is not None and 1 <= n_pass < last_pass and last_pass_if(f):
            last_pass = n_pass
        if cfg.global_step:
            t0 = time.perf_counter()
            w = trusted(lmd.witnesses(f, min_consistent=min_consistent), f)
            untrusted, before = 1.0 - w.mean(), 1.0 - last_fraction
            drop = before * (1.0 - cfg.min_untrusted_drop)
            if n_pass >= cfg.untrusted_drop_pass and untrusted > drop:
                break  # the last pass did not gain: keep its map, skip the repair
            last_fraction = float(w.mean())
            f_new = f
            if n_pass >= cfg.region_check_pass:
                consistent = lmd.local_map_distortion(f)[1]
                anchors = fixed if landmark_config.swap_anchors else None
                f_new = pin(swapped_regions(a, b, f, consistent, cfg.repair, anchors), landmarks)
                if f_new is not f:
                    w = trusted(lmd.witnesses(f_new, min_consistent=min_consistent), f_new)
            check = n_pass >= cfg.global_check_pass
            f_new = global_repair(
                a,
                b,
                f_new,
                w,
                min_consistent,
                global_check=check,
                lmd=lmd,
                config=cfg.repair,
                fixed=fixed if landmark_config.repair_anchors else None,
            )
            f_new = pin(f_new, landmarks)
            changed = int(np.count_nonzero(f_new != f))
            changed_in_pass += changed
            f = f_new
            history.append(Iteration(0, float(w.mean()), changed, time.perf_counter() - t0, n_pass))
            if callback is not None:
                callback(history[-1])
        for step, k in enumerate(schedule):
            t0 = time.perf_counter()
            w = trusted(voters(lmd, f, min_consistent, cfg.min_witness_fraction, turned), f)
            stay = cfg.stay_counts if n_pass >= cfg.stay_pass and not w.all() else 0
            ran = clock.cost, clock.assign
            f_new = assign_by_overlap(a, b, k, f, w, config=cfg, stay=stay, clock=clock)
            f_new = pin(f_new, landmarks)
            changed = int(np.count_nonzero(f_new != f))
            changed_in_pass += changed
            f = f_new
            history.append(
                Iteration(
                    k,
                    float(w.mean()),
                    changed,
                    time.perf_counter() - t0,
                    n_pass,
                    cost_seconds=clock.cost - ran[0],
                    assign_seconds=clock.assign - ran[1],
                )
            )
            if callback is not None:
                callback(history[-1])
            if on_last_pass is not None and n_pass == last_pass and step == 0:
                on_last_pass(f, n_pass)
        last_pass_changed = changed_in_pass
        if changed_in_pass < cfg.converged_fraction * a.n_vertices or n_pass == last_pass:
            break
    settled = last_pass_changed == 0
    if cfg.polish_k is not None:
        t0 = time.perf_counter()
        k = min(cfg.polish_k, k_max)
        w = trusted(voters(lmd, f, min_consistent, cfg.min_witness_fraction, turned), f)
        f_new = pin(best_overlap(a, b, k, f, w, top_k=cfg.top_k), landmarks)
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
    config: RepairConfig = RepairConfig(),
    fixed: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """:func:`~hope_rs.pipeline.anchors.anchor_step` on ``w``, the LMD witnesses of ``f``, keeping a moved
    vertex only where it then passes LMD itself (the anchor coordinates are coarser than a k-hop
    step, so elsewhere the old match is at least as good). ``global_check``: see
    :func:`~hope_rs.pipeline.anchors.anchor_step`; ``lmd``: the tracker of the caller's maps, if any;
    ``fixed``: anchors known to be right (see :func:`~hope_rs.pipeline.anchors.anchor_step`)."""
    g = anchor_step(a, b, f, w, global_check=global_check, config=config, fixed=fixed)
    if g is f:
        return f
    ok = (lmd or LmdTracker(a, b)).witnesses(g, min_consistent=min_consistent)
    return np.where(ok | (g == f), g, f)


def voters(
    lmd: LmdTracker,
    f,
    min_consistent: float,
    min_fraction: float,
    turned: Callable[[np.ndarray], np.ndarray] | None = None,
) -> np.ndarray:
    """The LMD witnesses of ``f``, or every vertex when fewer than ``min_fraction`` qualify;
    without the vertices ``turned(f)`` marks (the orientation check of
    ``RefineConfig.max_turned``)."""
    w = lmd.witnesses(f, min_consistent=min_consistent)
    w = w if w.mean() >= min_fraction else np.ones_like(w)
    return w if turned is None else w & ~turned(f)


def assign_by_overlap(
    a: Shape,
    b: Shape,
    k: int,
    f,
    witnesses,
    *,
    config: RefineConfig = RefineConfig(),
    stay: int = 0,
    clock: StepClock | None = None,
) -> np.ndarray:
    """One HOPE step: the one-to-one map maximising the k-hop overlap of the witnesses.

    The current match is worth a quarter of one overlap count, so a vertex moves only when the
    overlap gains. Every row also keeps one column of an injective completion of ``f``, so a
    one-to-one assignment always exists even when ``f`` maps several vertices to one. Vertices
    of A that the assignment leaves out (when A has more vertices than B) take their best
    candidate. With ``stay`` > 0, the current match of each witness is worth that many overlap
    counts more (see ``RefineConfig.stay_pass``). ``config`` gives ``top_k``,
    ``auction_floor_div`` and ``nearest_unused_k``. ``clock``, if given, adds the step's
    seconds of building the cost and of solving it.
    """
    if not 0 <= stay <= 1000:
        raise ValueError(f"stay must be in [0, 1000] overlap counts, got {stay}")
    keep = injective_completion(f, b.n_vertices, b.points, k=config.nearest_unused_k)
    # ``keep`` is a full assignment inside the pattern, which spares the solver its
    # feasibility search.
    hint = keep if a.n_vertices <= b.n_vertices else hint_rows(keep)
    # The cost is built and solved in one Rust call (src/step.rs), so it never makes the round
    # trip through NumPy; rows left out take their best column there.
    g, cost_seconds, assign_seconds = _core.overlap_assignment_graphs(
        *_step_args(a, b, k, f, witnesses),
        config.top_k,
        keep,
        hint,
        config.auction_floor_div,
        stay,
    )
    if clock is not None:
        clock.add(cost_seconds, assign_seconds)
    return g


def best_overlap(a: Shape, b: Shape, k: int, f, witnesses, *, top_k: int) -> np.ndarray:
    """Each vertex's best-overlapping vertex of B (ties kept at the current match): the cost of
    :func:`assign_by_overlap` without the one-to-one constraint."""
    return _core.best_overlap_graphs(*_step_args(a, b, k, f, witnesses), top_k)


def _step_args(
    a: Shape, b: Shape, k: int, f, witnesses
) -> tuple[_core.MeshGraph, _core.MeshGraph, int, np.ndarray, np.ndarray]:
    """The leading arguments of the Rust step functions: both graphs, k, the map, the voters."""
    return (
        a.graph,
        b.graph,
        k,
        np.ascontiguousarray(f, dtype=np.int64),
        np.ascontiguousarray(witnesses, dtype=bool),
    )


class RefineStage(Stage):
    """The "refine" stage (and its "polish" step): :func:`refine` from ``state.f0``.

    Publishes "refine_start", "last_pass" and "refine_end" and asks "stop_refining" (see
    :data:`hope_rs.pipeline.state.EVENTS`); sets ``state.f``, ``state.hope_map``,
    ``state.history`` and ``state.settled`` (and ``state.done`` when settled).
    """

    name = "refine"

    def skip_reason(self, state: MatchState):
        # A stage before it may have the final map already (the partial stage's inverse).
        return state.done if state.f is not None else None

    def run(self, state: MatchState) -> None:
        a, b, cfg, hooks = state.a, state.b, state.config.refine, state.hooks
        steps = _RefineSteps(a, b, state.log, cfg, state.callback)
        clock = StepClock()
        t = state.log.start("refine", steps.total, f"pass 1/{steps.n_passes}")
        hooks.emit("refine_start", state)
        res = None
        try:
            res = refine(
                a,
                b,
                state.f0,
                cfg,
                callback=steps,
                on_last_pass=lambda f, n_pass: hooks.emit("last_pass", f, n_pass),
                last_pass_if=(
                    (lambda f: hooks.any("stop_refining", f))
                    if hooks.has("stop_refining")
                    else None
                ),
                landmarks=state.landmarks,
                landmark_config=state.config.landmarks,
                clock=clock,
            )
        finally:
            hooks.emit("refine_end", state, res)
        state.timings["refine"] = time.perf_counter() - t
        clock.record(state.timings, "refine")
        steps.finished(state.timings["refine"])
        state.f = state.hope_map = res.map
        state.history = res.history
        state.settled = res.settled
        if res.settled:
            state.done = (
                "HOPE's map settled: its last pass and the polish moved no vertex and LMD "
                "trusts every vertex"
            )


class _RefineSteps:
    """The refinement's ``callback``: logs and reports each step, labels the polish step,
    and calls the user's callback."""

    def __init__(self, sa: Shape, sb: Shape, log: StageLog, cfg: RefineConfig, user):
        self.log, self.user = log, user
        schedule: Sequence[int] | None = cfg.schedule
        if schedule is None:
            schedule = default_schedule(min(sa.k_max, sb.k_max))
        self.n_passes = cfg.max_passes
        self.per_pass = len(schedule) + (1 if cfg.global_step else 0)
        self.total = self.n_passes * self.per_pass
        self.polish: Iteration | None
        self.done, self.passes, self.t0, self.polish = 0, 0, time.perf_counter(), None

    def __call__(self, it: Iteration) -> None:
        if it.polish:
            self.polish = it
            seconds = time.perf_counter() - self.t0 - it.seconds
            self.log.ran("refine", seconds, self._summary(), self.done, self.total)
            self.log.step("polish", 1, 1, step_detail(it, self.n_passes), it)
            self.log.ran("polish", it.seconds, f"k={it.k}, changed {it.changed}", 1, 1)
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
