"""What the stages of a match share: the match state, the runner's hooks and the stage interface.

A stage (:class:`Stage`) says whether it applies to a state and transforms it; the runner
(:mod:`hope_rs.pipeline.runner`) runs a list of them in order. Stages that cooperate (the
spectral pass solving its eigenbases while HOPE refines, the shared-face finish ending the
refinement early) do so through named events of :class:`Hooks`, never through each other's
fields.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..shape import Shape
from .config import MatchConfig
from .progress import StageLog

__all__ = ["EVENTS", "QUIET", "Hooks", "Iteration", "MatchState", "Stage", "StepClock"]

#: The events of :class:`Hooks` and their arguments. "stop_refining" is a question: the
#: refinement ends after the current pass when any subscriber answers True.
EVENTS = {
    "refine_start": "(state) before the refinement's first step",
    "last_pass": "(f, n_pass) once the first step of the refinement's last pass has run",
    "stop_refining": "(f) -> bool at the start of every pass from the second on",
    "refine_end": "(state, result) when the refinement returned (result None: it raised)",
    "stage_end": "(state, name) after each stage of the runner's list, run or skipped",
}

#: :meth:`Stage.skip_reason`'s answer for a stage that is off and not worth a record (the
#: multiscale stage when ``multiscale=False``).
QUIET = object()


@dataclass
class Iteration:
    """What one refinement step did."""

    #: Hop radius of the step; 0 for a global repair step.
    k: int
    witness_fraction: float
    changed: int
    seconds: float
    #: The 0-based pass the step belongs to (the polish: the last pass that ran).
    n_pass: int = 0
    #: The final polishing step (see ``polish_k``), not a step of a pass.
    polish: bool = False
    #: Of ``seconds``, those spent building the overlap cost and solving its assignment (0 for
    #: a repair step and for the polish, which is not one to one).
    cost_seconds: float = 0.0
    assign_seconds: float = 0.0


@dataclass
class StepClock:
    """Seconds the HOPE steps of a stage spent in their two halves, summed over its steps:
    building the overlap cost (parallel) and solving the assignment (sequential)."""

    cost: float = 0.0
    assign: float = 0.0
    steps: int = 0

    def add(self, cost: float, assign: float) -> None:
        self.cost += cost
        self.assign += assign
        self.steps += 1

    def record(self, timings: dict, stage: str) -> None:
        """Adds ``stage + ".cost"`` and ``stage + ".assign"`` to ``timings`` when a step ran."""
        if self.steps:
            timings[f"{stage}.cost"] = self.cost
            timings[f"{stage}.assign"] = self.assign


class Hooks:
    """Named events (see :data:`EVENTS`) that stages publish and subscribe to."""

    def __init__(self):
        self._subscribers: dict[str, list[Callable]] = defaultdict(list)

    def on(self, event: str, fn: Callable) -> None:
        if event not in EVENTS:
            raise ValueError(f"unknown event {event!r}; the events are {', '.join(EVENTS)}")
        self._subscribers[event].append(fn)

    def emit(self, event: str, *args) -> None:
        for fn in self._subscribers[event]:
            fn(*args)

    def any(self, event: str, *args) -> bool:
        """Whether any subscriber answers True (all are asked, in order, until one does)."""
        return any(fn(*args) for fn in self._subscribers[event])

    def has(self, event: str) -> bool:
        return bool(self._subscribers[event])


@dataclass
class MatchState:
    """A match in progress, in the shapes' internal numbering (see :class:`~hope_rs.Shape`).

    Attributes
    ----------
    a, b : Shape
    config : MatchConfig
        The settings in force (a stage may narrow them for the stages after it, as the
        multiscale stage narrows the refinement's passes).
    init : str or ndarray
        A descriptor kind, or the caller's initial map.
    log : StageLog
        Records, logs and reports each stage.
    hooks : Hooks
    callback : callable or None
        The caller's per-step callback.
    run : callable
        The runner itself, ``run(a, b, init, config, progress=..., landmarks=...,
        on_stage=...)`` → MatchResult, for stages that match other shapes (the multiscale
        stage's coarse copies, the partial stage's reverse match).
    f0, f : ndarray or None
        The initial map, and the current map.
    hope_map : ndarray or None
        The refinement's output.
    history : list of Iteration
    timings : dict
        Seconds per stage.
    settled : bool
        The refinement reached a fixed point that LMD trusts everywhere.
    done : str or None
        Why the map needs no further stage, once a stage found that out.
    coarse : MatchResult or None
        The multiscale stage's match of the coarse copies.
    zoomout : ndarray or None
        The spectral pass's ZoomOut map, when it computed one.
    confidence : ndarray or None
        Per vertex of A, the confidence in the final map (the confidence stage).
    landmarks : (m, 2) ndarray of int or None
        The caller's landmarks (vertex of A, vertex of B), rows sorted by A's vertex; ``None``
        when there are none.
    partial : PartialInfo or None
        Which shape is a part of the other, when the partial stage found one is.
    """

    a: Shape
    b: Shape
    config: MatchConfig
    init: Any
    log: StageLog
    hooks: Hooks = field(default_factory=Hooks)
    callback: Callable | None = None
    run: Callable | None = None
    f0: np.ndarray | None = None
    f: np.ndarray | None = None
    hope_map: np.ndarray | None = None
    history: list[Iteration] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    settled: bool = False
    done: str | None = None
    coarse: Any = None
    zoomout: np.ndarray | None = None
    confidence: np.ndarray | None = None
    landmarks: np.ndarray | None = None
    partial: Any = None


class Stage:
    """One stage of the pipeline.

    Subclasses set :attr:`name` (one of :data:`hope_rs.pipeline.progress.STAGES`) and
    implement :meth:`run`; the others have defaults. The runner calls :meth:`attach` on every
    stage before the first runs, then for each in order :meth:`skip_reason` and, when it is
    ``None``, :meth:`run`; :meth:`close` on every stage on every exit, an error included.
    """

    name: str = ""

    def attach(self, state: MatchState) -> None:
        """Subscribe to the events of ``state.hooks`` this stage needs."""

    def skip_reason(self, state: MatchState):
        """``None`` when the stage runs on ``state``, else why not (recorded as skipped), or
        :data:`QUIET` (not recorded)."""
        return

    def run(self, state: MatchState) -> None:
        """Transform ``state`` (and record the stage in ``state.log``)."""
        raise NotImplementedError

    def close(self, state: MatchState) -> None:
        """Stop any background work (called on every exit)."""
