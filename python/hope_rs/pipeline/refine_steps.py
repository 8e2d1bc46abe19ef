"""The steps of HOPE's refinement passes, and the state they share.

:func:`hope_rs.pipeline.refine.refine` runs :func:`pass_steps` in order in every pass, then
:func:`final_steps` once. A step is a small object: :meth:`PassStep.when` says whether it runs
(from the pass a setting of :class:`~hope_rs.pipeline.config.RefineConfig` names, or always);
:meth:`PassStep.run` reads the shared :class:`RefineState` and returns the new map, or
:data:`HALT` to end the passes. The loop pins the landmarks in every map a step returns, counts
the vertices it moved and records the history: a step with a hop radius ``k`` closes one
:class:`~hope_rs.pipeline.state.Iteration`, a step without one counts in the next step's (the
region check in the global repair's), and an ``event`` step only talks to the caller.

Adding a step: a class here, one line in :func:`pass_steps` (or :func:`final_steps`) and its
field of :class:`~hope_rs.pipeline.config.RefineConfig`.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..shape import Shape
from . import overlap
from .anchors import swapped_regions
from .config import LandmarkConfig, RefineConfig
from .landmarks import LandmarkCoordinates, coordinate_landmarks, pin
from .lmd import LmdTracker
from .state import Iteration, StepClock
from .turned import TurnedFaces

__all__ = [
    "HALT",
    "AnnounceLastPass",
    "AskLastPass",
    "GlobalRepair",
    "KHop",
    "PassStep",
    "Polish",
    "RefineEvents",
    "RefineState",
    "RegionCheck",
    "StopWhenRepairStalls",
    "final_steps",
    "pass_steps",
]

#: What :meth:`PassStep.run` returns to end the passes (the map of the last pass is kept; the
#: final steps still run).
HALT = object()


class RefineEvents:
    """What the refinement tells its caller while it runs, and the one thing it asks. Every
    method has a default that does nothing; override those you need."""

    def step(self, it: Iteration) -> None:
        """A step was recorded in the history."""

    def last_pass(self, f: np.ndarray, n_pass: int) -> None:
        """The first k-hop step of the last pass has run; ``f`` is the map then."""

    def last_pass_now(self, f: np.ndarray) -> bool:
        """Asked with the map at the start of every pass from the second on (while a later
        one could run): True makes that pass the last."""
        return False


class Landmarks:
    """The caller's landmarks as the refinement uses them (none: every method leaves maps
    and witnesses as they are). ``landmarks``: (m, 2) internal vertex pairs."""

    def __init__(
        self,
        a: Shape,
        b: Shape,
        landmarks: np.ndarray | None,
        config: RefineConfig,
        landmark_config: LandmarkConfig,
    ):
        self.pairs, self.config = landmarks, landmark_config
        self.coords = None
        if landmarks is not None:
            some = coordinate_landmarks(a, landmarks, landmark_config.max_coordinates)
            self.coords = LandmarkCoordinates(a, b, some, config.repair)

    def pin(self, f: np.ndarray) -> np.ndarray:
        """``f`` with every landmark mapped exactly (``f`` itself when it is already)."""
        return pin(f, self.pairs)

    def trusted(self, w: np.ndarray, f: np.ndarray) -> np.ndarray:
        """The witnesses ``w`` of ``f`` as the landmarks judge them: always the landmarks,
        never a vertex whose match fits its distances to them far worse than it could
        (``LandmarkConfig.max_gap``, with ``refine_trust``)."""
        if self.coords is None:
            return w
        cfg = self.config
        # A new array: ``w`` may be the tracker's own.
        w = w & ~self.coords.off(f, cfg.max_gap) if cfg.refine_trust else w.copy()
        assert self.pairs is not None  # coords come with landmarks
        w[self.pairs[:, 0]] = True
        return w

    def anchors(self, use: bool) -> tuple[np.ndarray, np.ndarray] | None:
        """The landmarks' distance fields (A's, B's) as anchors known to be right, when
        ``use`` and there are landmarks."""
        return (self.coords.da, self.coords.db) if use and self.coords is not None else None


@dataclass
class RefineState:
    """What the steps of a refinement share; maps in the shapes' internal numbering."""

    a: Shape
    b: Shape
    config: RefineConfig
    landmarks: Landmarks
    events: RefineEvents
    clock: StepClock
    #: The hop radii of one pass.
    schedule: list[int]
    #: The current map.
    f: np.ndarray
    lmd: LmdTracker
    #: Per map, the vertices whose triangles it turns over (``RefineConfig.max_turned``).
    turned: Callable[[np.ndarray], np.ndarray] | None = None
    #: The 0-based pass running (in the final steps: the last pass that ran a step).
    n_pass: int = 0
    #: The pass that will be the last (an event may bring it forward).
    last_pass: int = 0
    history: list[Iteration] = field(default_factory=list)
    #: Vertices moved so far in this pass, and in the last pass that ran to its end (-1: none).
    pass_changed: int = 0
    last_pass_changed: int = -1
    #: The share of vertices the global repair trusted at its last run (-1: not yet).
    trusted_share: float = -1.0
    #: The witnesses of the step running (recorded in its Iteration).
    w: np.ndarray | None = None
    #: The k-hop steps' last inputs and results, by (k, from ``stay_pass`` on): (map in,
    #: voters, map out). A step's result depends on nothing else (see :class:`KHop`).
    seen: dict[tuple[int, bool], tuple[np.ndarray, np.ndarray, np.ndarray]] = field(
        default_factory=dict
    )
    #: The step running took an earlier step's result instead of solving (recorded in its
    #: Iteration).
    reused: bool = False
    _trusted: tuple[np.ndarray, np.ndarray] | None = None

    def trusted_witnesses(self) -> np.ndarray:
        """The LMD witnesses of the current map as the landmarks judge them (computed once
        per map)."""
        if self._trusted is None or self._trusted[0] is not self.f:
            lmd_w = self.lmd.witnesses(self.f, min_consistent=self.config.min_consistent)
            self._trusted = (self.f, self.landmarks.trusted(lmd_w, self.f))
        return self._trusted[1]

    def voters(self) -> np.ndarray:
        """The voters of a k-hop step or the polish: the witnesses, every vertex when too few
        (``min_witness_fraction``), never a turned-over one (``max_turned``)."""
        cfg = self.config
        w = overlap.voters(
            self.lmd, self.f, cfg.min_consistent, cfg.min_witness_fraction, self.turned
        )
        return self.landmarks.trusted(w, self.f)


class PassStep:
    """One step of a refinement pass (see the module notes)."""

    #: The hop radius of the history entry this step closes (0: a repair step); ``None``: its
    #: work counts in the next step's entry.
    k: int | None = None
    #: The final polishing step (recorded with ``Iteration.polish``).
    polish: bool = False
    #: Only talks to the caller: moves no vertex and counts in no history entry.
    event: bool = False

    def when(self, st: RefineState) -> bool:
        """Whether the step runs now."""
        return True

    def run(self, st: RefineState):
        """The new map (the loop pins the landmarks), or :data:`HALT`."""
        raise NotImplementedError


class AskLastPass(PassStep):
    """From the second pass on, asks the caller whether this pass is the last
    (:meth:`RefineEvents.last_pass_now`: the shared-face finish takes over from there)."""

    event = True

    def when(self, st: RefineState) -> bool:
        return 1 <= st.n_pass < st.last_pass

    def run(self, st: RefineState):
        if st.events.last_pass_now(st.f):
            st.last_pass = st.n_pass
        return st.f


class StopWhenRepairStalls(PassStep):
    """With the global repair: ends the passes, keeping the last pass's map, when that pass
    shrank the share of vertices the repair does not trust by less than
    ``min_untrusted_drop`` of itself (from pass ``untrusted_drop_pass`` on)."""

    def when(self, st: RefineState) -> bool:
        return st.config.global_step

    def run(self, st: RefineState):
        cfg, w = st.config, st.trusted_witnesses()
        untrusted, before = 1.0 - w.mean(), 1.0 - st.trusted_share
        if st.n_pass >= cfg.untrusted_drop_pass and untrusted > before * (
            1.0 - cfg.min_untrusted_drop
        ):
            return HALT
        st.trusted_share = float(w.mean())
        return st.f


class RegionCheck(PassStep):
    """Moves back whole regions mapped to the wrong place
    (:func:`~hope_rs.pipeline.anchors.swapped_regions`), from pass ``region_check_pass`` on,
    before the global repair; the landmarks are its anchors with ``swap_anchors``."""

    def when(self, st: RefineState) -> bool:
        return st.config.global_step and st.n_pass >= st.config.region_check_pass

    def run(self, st: RefineState):
        consistent = st.lmd.local_map_distortion(st.f)[1]
        anchors = st.landmarks.anchors(st.landmarks.config.swap_anchors)
        return swapped_regions(st.a, st.b, st.f, consistent, st.config.repair, anchors)


class GlobalRepair(PassStep):
    """:func:`~hope_rs.pipeline.overlap.global_repair` of the vertices LMD does not trust
    (``global_step``), checking long-range distances from pass ``global_check_pass`` on; the
    landmarks are its anchors with ``repair_anchors``."""

    k = 0

    def when(self, st: RefineState) -> bool:
        return st.config.global_step

    def run(self, st: RefineState):
        cfg = st.config
        st.w = st.trusted_witnesses()
        return overlap.global_repair(
            st.a,
            st.b,
            st.f,
            st.w,
            cfg.min_consistent,
            global_check=st.n_pass >= cfg.global_check_pass,
            lmd=st.lmd,
            config=cfg.repair,
            fixed=st.landmarks.anchors(st.landmarks.config.repair_anchors),
        )


class KHop(PassStep):
    """One HOPE step at hop radius ``k`` (:func:`~hope_rs.pipeline.overlap.assign_by_overlap`);
    from pass ``stay_pass`` on, while some vertex is not a voter, a voter's current match is
    worth ``stay_counts`` more overlap counts.

    The result is a function of k, the map and whether the pass is ``stay_pass`` or later (the
    voters are a function of the map), so a step whose map is the one the last step at the same
    k started from, on the same side of ``stay_pass``, takes that step's result without solving
    (a map that earlier steps left unchanged comes back a pass later): the same map
    bit for bit."""

    k: int

    def __init__(self, k: int):
        self.k = k

    def run(self, st: RefineState):
        cfg = st.config
        late = st.n_pass >= cfg.stay_pass
        key = (self.k, late)
        last = st.seen.get(key)
        if last is not None and np.array_equal(last[0], st.f):
            st.w, st.reused = last[1].copy(), True
            return last[2].copy()
        st.w = st.voters()
        stay = cfg.stay_counts if late and not st.w.all() else 0
        g = overlap.assign_by_overlap(
            st.a, st.b, self.k, st.f, st.w, config=cfg, stay=stay, clock=st.clock
        )
        # Copies: a caller may keep and change the maps it is given.
        st.seen[key] = (st.f.copy(), st.w.copy(), np.array(g, copy=True))
        return g


class AnnounceLastPass(PassStep):
    """Tells the caller the last pass has begun (:meth:`RefineEvents.last_pass`: the spectral
    pass starts its ZoomOut from this map)."""

    event = True

    def when(self, st: RefineState) -> bool:
        return st.n_pass == st.last_pass

    def run(self, st: RefineState):
        st.events.last_pass(st.f, st.n_pass)
        return st.f


class Polish(PassStep):
    """Every vertex takes its best-overlapping candidate at hop radius ``polish_k``, without
    the one-to-one constraint (:func:`~hope_rs.pipeline.overlap.best_overlap`)."""

    polish = True

    def __init__(self, config: RefineConfig, k_max: int):
        self.k = None if config.polish_k is None else min(config.polish_k, k_max)

    def when(self, st: RefineState) -> bool:
        return self.k is not None

    def run(self, st: RefineState):
        assert self.k is not None  # when() runs the polish only with a polish_k
        st.w = st.voters()
        return overlap.best_overlap(st.a, st.b, self.k, st.f, st.w, top_k=st.config.top_k)


def pass_steps(schedule: list[int]) -> list[PassStep]:
    """The steps of one pass, in order; each runs when its :meth:`~PassStep.when` says."""
    first, *rest = schedule
    return [
        AskLastPass(),
        StopWhenRepairStalls(),
        RegionCheck(),
        GlobalRepair(),
        KHop(first),
        AnnounceLastPass(),
        *(KHop(k) for k in rest),
    ]


def final_steps(config: RefineConfig, k_max: int) -> list[PassStep]:
    """The steps after the last pass, in order."""
    return [Polish(config, k_max)]


def start_state(
    a: Shape,
    b: Shape,
    f0: np.ndarray,
    config: RefineConfig,
    schedule: list[int],
    events: RefineEvents,
    landmarks: Landmarks,
    clock: StepClock,
) -> RefineState:
    """The state before the first pass: ``f0`` with the landmarks pinned."""
    turned = None
    if config.max_turned is not None:
        turned = functools.partial(TurnedFaces(a, b).vertices, max_share=config.max_turned)
    f = landmarks.pin(np.ascontiguousarray(f0, dtype=np.int64))
    return RefineState(
        a,
        b,
        config,
        landmarks,
        events,
        clock,
        schedule,
        f,
        LmdTracker(a, b),
        turned,
        last_pass=config.max_passes - 1,
    )


def run_steps(st: RefineState, steps: list[PassStep]) -> bool:
    """Runs those of ``steps`` whose rule says so, in order (see the module notes); False
    when one ended the passes."""
    opened = None  # (seconds, map, clock's cost and assign seconds) where the entry began
    for step in steps:
        if not step.when(st):
            continue
        if step.event:
            step.run(st)
            continue
        if opened is None:
            opened = (time.perf_counter(), st.f, st.clock.cost, st.clock.assign)
        g = step.run(st)
        if g is HALT:
            return False
        st.f = st.landmarks.pin(g)  # the one place the landmarks are pinned after a step
        if step.k is None:
            continue
        t0, before, cost, assign = opened
        opened = None
        assert st.w is not None  # set by every step that closes an entry (k not None)
        changed = int(np.count_nonzero(st.f != before))
        st.pass_changed += changed
        it = Iteration(
            step.k,
            float(st.w.mean()),
            changed,
            time.perf_counter() - t0,
            st.n_pass,
            polish=step.polish,
            cost_seconds=st.clock.cost - cost,
            assign_seconds=st.clock.assign - assign,
            reused=st.reused,
        )
        st.reused = False
        st.history.append(it)
        st.events.step(it)
    return True
