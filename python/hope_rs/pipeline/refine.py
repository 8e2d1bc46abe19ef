"""HOPE's refinement: re-assign every vertex to maximise the k-hop overlap of witnesses.

:func:`refine` is the loop over the pass steps of :mod:`hope_rs.pipeline.refine_steps`;
:class:`RefineStage` runs it as the "refine" and "polish" stages of a match and publishes the
refinement's events to the other stages (see :data:`hope_rs.pipeline.state.EVENTS`). The
steps' own parts (one HOPE step, the polish's best overlap, the global repair) are in
:mod:`hope_rs.pipeline.overlap`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .._blas import with_single_threaded_blas
from ..shape import Shape
from .config import LandmarkConfig, RefineConfig
from .overlap import assign_by_overlap, best_overlap, global_repair, hop_limit
from .progress import StageLog, step_detail
from .refine_steps import (
    Landmarks,
    RefineEvents,
    final_steps,
    pass_steps,
    run_steps,
    start_state,
)
from .state import Halt, Iteration, MatchState, Stage, StepClock

__all__ = [
    "Iteration",
    "RefineEvents",
    "RefineResult",
    "RefineStage",
    "assign_by_overlap",
    "best_overlap",
    "default_schedule",
    "global_repair",
    "pass_schedule",
    "refine",
]


def default_schedule(k_max: int) -> list[int]:
    """One pass: k going k_max → 1. Coarse neighbourhoods first fix large errors, fine ones then
    sharpen (docs/decisions.md#schedule)."""
    return list(range(k_max, 0, -1))


def pass_schedule(schedule: Sequence[int], config: RefineConfig, n_pass: int) -> list[int]:
    """The hop radii of pass ``n_pass`` (0-based): those of ``schedule`` up to the pass's entry
    of ``config.pass_k_max`` (its last entry for every later pass; ``None``: all of them), or
    the schedule's smallest when none is (docs/decisions.md#schedule)."""
    caps = config.pass_k_max
    cap = None if caps is None else caps[min(n_pass, len(caps) - 1)]
    if cap is None:
        return list(schedule)
    return [k for k in schedule if k <= cap] or [min(schedule)]


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
    events: RefineEvents | None = None,
    landmarks: np.ndarray | None = None,
    landmark_config: LandmarkConfig = LandmarkConfig(),
    clock: StepClock | None = None,
    k_max: int | None = None,
) -> RefineResult:
    """Refine the map ``f0`` (A → B) with HOPE.

    ``f0`` and the result are in the shapes' internal numbering (see :class:`~hope_rs.Shape`;
    :func:`hope_rs.match` translates), as are the maps of every function of this module.

    Each pass runs the steps of :func:`~hope_rs.pipeline.refine_steps.pass_steps`, each when
    its rule says: the global repair (``config.global_step``; from ``config.region_check_pass``
    on preceded by the region check, from ``config.untrusted_drop_pass`` on ending the passes
    when it stalls), then one HOPE step per hop radius of the schedule (k_max → 1 by
    default), capped per pass by ``config.pass_k_max`` (:func:`pass_schedule`). Passes repeat until one changes fewer than ``config.converged_fraction`` of the
    vertices, or ``config.max_passes`` passes; then the polish (``config.polish_k``) runs.

    A HOPE step selects witnesses by LMD, builds the overlap cost at hop radius k and solves
    the one-to-one assignment that maximises it. When LMD trusts fewer than
    ``config.min_witness_fraction`` of the vertices, every vertex votes instead: wrong votes
    scatter while right ones agree, so the overlap still points the right way.

    The polish lets every vertex take its best-overlapping candidate without the one-to-one
    constraint. When the shapes are triangulated differently no bijection between their
    vertices exists, and forcing one leaves many vertices an edge or two off; on identically
    triangulated pairs the polish changes nothing (docs/decisions.md#polish).

    The global repair (:func:`~hope_rs.pipeline.overlap.global_repair`) re-places the
    vertices LMD does not trust by their geodesic distances to trusted ones; it is recorded in
    the history as a step with k = 0. The k-hop steps alone win back a wrongly matched region
    a few hops per pass (docs/decisions.md#global-repair). From the second pass on, the
    repair also distrusts vertices whose long-range distances disagree (see
    ``config.global_check_pass``), which LMD alone cannot see, and is preceded by the region
    check, which moves back whole regions mapped to the wrong place.

    ``events`` (:class:`~hope_rs.pipeline.refine_steps.RefineEvents`), if given, hears of
    every recorded step and of the last pass's start, and is asked at the start of every pass
    from the second on whether that pass is the last.

    ``landmarks`` ((m, 2) internal vertex pairs, or None) are mapped exactly after every step
    and always witnesses; a vertex whose match fits its distances to them far worse than it
    could (``landmark_config.max_gap``) is never one, and the region check (and with
    ``landmark_config.repair_anchors`` the global repair) takes them as anchors
    (:mod:`hope_rs.pipeline.landmarks`).

    ``clock``, if given, adds up the k-hop steps' cost and assignment seconds (each step's
    own are in its :class:`Iteration`).

    ``k_max``: the largest hop radius (``MatchConfig.k_max``); the shapes' own ``k_max`` (the
    balls they hold) when None or larger.
    """
    k_max = hop_limit(a, b, k_max)
    schedule = list(config.schedule) if config.schedule is not None else default_schedule(k_max)
    if not schedule or any(not 1 <= k <= k_max for k in schedule):
        raise ValueError(f"every k of the schedule must be in [1, {k_max}], got {schedule}")
    marks = Landmarks(a, b, landmarks, config, landmark_config)
    events = RefineEvents() if events is None else events
    clock = StepClock() if clock is None else clock
    st = start_state(a, b, f0, config, schedule, events, marks, clock)
    for n_pass in range(config.max_passes):
        st.n_pass, st.pass_changed = n_pass, 0
        if not run_steps(st, pass_steps(pass_schedule(schedule, config, n_pass))):
            break  # a step ended the passes
        st.last_pass_changed = st.pass_changed
        if st.pass_changed < config.converged_fraction * a.n_vertices or n_pass == st.last_pass:
            break
    # The final steps belong to the last pass that ran a step.
    st.n_pass, st.pass_changed = (st.history[-1].n_pass if st.history else 0), 0
    run_steps(st, final_steps(config, k_max))
    # A fixed point of the steps that LMD trusts everywhere.
    settled = st.last_pass_changed == 0 and st.pass_changed == 0
    settled = settled and bool(st.lmd.witnesses(st.f, min_consistent=config.min_consistent).all())
    return RefineResult(st.f, st.history, settled=settled)


class RefineStage(Stage):
    """The "refine" stage (and its "polish" step): :func:`refine` from ``state.f0``.

    Publishes "last_pass" and asks "stop_refining" (see
    :data:`hope_rs.pipeline.state.EVENTS`); sets ``state.f``, ``state.hope_map``,
    ``state.history`` and ``state.settled``, and halts the stages after it when settled.
    """

    name = "refine"
    runs_on_final_map = False

    def run(self, state: MatchState) -> Halt | None:
        a, b, cfg, hooks = state.a, state.b, state.config.refine, state.hooks
        k_max = hop_limit(a, b, state.config.k_max)
        steps = _RefineSteps(k_max, state.log, cfg, state.callback, hooks)
        clock = StepClock()
        t = state.log.start("refine", steps.total, f"pass 1/{steps.n_passes}")
        res = refine(
            a,
            b,
            state.f0,
            cfg,
            events=steps,
            landmarks=state.landmarks,
            landmark_config=state.config.landmarks,
            clock=clock,
            k_max=k_max,
        )
        state.timings["refine"] = time.perf_counter() - t
        clock.record(state.timings, "refine")
        steps.finished(state.timings["refine"])
        state.f = state.hope_map = res.map
        state.history = res.history
        state.settled = res.settled
        if res.settled:
            return Halt(
                "HOPE's map settled: its last pass and the polish moved no vertex and LMD "
                "trusts every vertex"
            )
        return None


class _RefineSteps(RefineEvents):
    """The refinement's events in a match: logs and reports each step, labels the polish
    step and calls the user's callback; relays the last pass to the runner's hooks."""

    def __init__(self, k_max: int, log: StageLog, cfg: RefineConfig, user, hooks):
        self.log, self.user, self.hooks = log, user, hooks
        schedule: Sequence[int] | None = cfg.schedule
        if schedule is None:
            schedule = default_schedule(k_max)
        self.n_passes = cfg.max_passes
        # Steps per pass; the passes after the caps' last entry are like the last one.
        repair = 1 if cfg.global_step else 0
        capped = min(self.n_passes, len(cfg.pass_k_max or (None,)))
        per_pass = [len(pass_schedule(schedule, cfg, n)) + repair for n in range(capped)]
        self.total = sum(per_pass) + (self.n_passes - capped) * per_pass[-1]
        self.polish: Iteration | None
        self.done, self.passes, self.t0, self.polish = 0, 0, time.perf_counter(), None

    def last_pass(self, f: np.ndarray, n_pass: int) -> None:
        self.hooks.emit("last_pass", f, n_pass)

    def last_pass_now(self, f: np.ndarray) -> bool:
        return self.hooks.any("stop_refining", f)

    def step(self, it: Iteration) -> None:
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
