"""What the stages of a match share: the match state, the stage interface and its outcomes.

A stage (:class:`Stage`) says whether it applies to a state and transforms it; the runner
(:mod:`hope_rs.pipeline.runner`) runs a list of them in order and owns the control flow
between them:

* a stage that finds the map final returns :class:`Halt` from :meth:`Stage.run` (the partial
  stage's inverse, a settled refinement), or says so when the runner asks it after an earlier
  stage ran (:meth:`Stage.final_after`: the shared-face finish after the refinement); the
  runner then skips every later stage that would change the map, giving the halt's reason;
* work a stage runs in threads while an earlier stage runs (the spectral pass's eigenbases
  during the refinement) is a :class:`Background` the runner enters before that stage and
  leaves after it, on every exit (:attr:`Stage.alongside`);
* events inside a stage that another stage acts on (the refinement's last pass, the question
  whether to stop refining) go through :class:`Hooks`, never through each other's fields.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..shape import Shape
from .config import MatchConfig
from .iteration import Iteration, StepClock
from .part_info import PartialInfo
from .progress import StageLog
from .result import MatchResult

__all__ = [
    "EVENTS",
    "QUIET",
    "Background",
    "CommonView",
    "Halt",
    "Hooks",
    "Iteration",
    "MatchState",
    "Stage",
    "StepClock",
]

#: The events of :class:`Hooks` and their arguments. "stop_refining" is a question: the
#: refinement ends after the current pass when any subscriber answers True.
EVENTS = {
    "last_pass": "(f, n_pass) once the first k-hop step of the refinement's last pass has run",
    "stop_refining": "(f) -> bool at the start of every pass from the second on",
    "stage_end": "(state, name) after each stage of the runner's list, run or skipped",
}

#: :meth:`Stage.skip_reason`'s answer for a stage that is off and not worth a record (the
#: multiscale stage when ``multiscale=False``).
QUIET = object()


@dataclass(frozen=True)
class Halt:
    """A stage's outcome: the map is final. The runner skips every later stage that would
    remake it (those with :attr:`Stage.runs_on_final_map` False), recording ``reason``."""

    reason: str


class Background:
    """Work a stage runs in threads while an earlier stage runs (:attr:`Stage.alongside`).

    The runner enters it before that stage and leaves it after, on every exit: with
    :attr:`keep` True (the default) leaving waits for the work, whose results the stage
    then uses; the runner sets it False when that stage raised or halted (:class:`Halt`), and
    leaving then stops the work first.
    """

    keep: bool = True

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.stop(keep=self.keep and exc_type is None)

    def start(self) -> None:
        """Starts the work."""

    def stop(self, keep: bool) -> None:
        """Ends the work (see the class notes)."""


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


@dataclass(frozen=True, eq=False)
class CommonView:
    """A dense A's copy at a common resolution (vertices of A, far fewer), where the local
    distortion of its maps to a sparser B and their turned-over regions are measured: at full
    resolution a right many-to-one map keeps few 2-rings' distances.

    Attributes
    ----------
    shape : Shape
        The copy.
    sites : (n_copy,) int ndarray
        Per internal vertex of the copy, the vertex of A (internal numbering) it is.
    owner : (n_a,) int ndarray
        Per internal vertex of A, the copy's internal vertex it was merged into.
    rough : bool
        A is rough at its own resolution (a noisy scan,
        ``ResolutionConfig.judge_rougher``): the share of A a map turns over is measured on
        the copy too, where A's own triangles turn over at random.
    """

    shape: Shape
    sites: np.ndarray
    owner: np.ndarray
    rough: bool = False

    def of(self, f: np.ndarray) -> np.ndarray:
        """A map of A (internal numbering) read at the copy's vertices."""
        return np.asarray(f)[self.sites]


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
        stage's coarse copies; the trials of :mod:`hope_rs.pipeline.trials`).
    f0, f : ndarray or None
        The initial map, and the current map.
    hope_map : ndarray or None
        The refinement's output.
    history : list of Iteration
    timings : dict
        Seconds per stage.
    settled : bool
        The refinement reached a fixed point that LMD trusts everywhere.
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
    common_a : CommonView or None
        When A was matched at a common resolution with a sparser B (the resolution stage):
        the copy of A it was matched at, where a lifted many-to-one map's local distortion
        is measured.
    """

    a: Shape
    b: Shape
    config: MatchConfig
    init: str | np.ndarray
    log: StageLog
    hooks: Hooks = field(default_factory=Hooks)
    callback: Callable | None = None
    run: Callable[..., MatchResult] | None = None
    f0: np.ndarray | None = None
    f: np.ndarray | None = None
    hope_map: np.ndarray | None = None
    history: list[Iteration] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    settled: bool = False
    coarse: MatchResult | None = None
    zoomout: np.ndarray | None = None
    confidence: np.ndarray | None = None
    landmarks: np.ndarray | None = None
    partial: PartialInfo | None = None
    common_a: CommonView | None = None


class Stage:
    """One stage of the pipeline.

    Subclasses set :attr:`name` (one of :data:`hope_rs.pipeline.progress.STAGES`) and
    implement :meth:`run`; the others have defaults. The runner calls :meth:`attach` on every
    stage before the first runs, then for each in order :meth:`skip_reason` and, when it is
    ``None`` and no earlier stage made the map final (or the stage runs on a final map),
    :meth:`run`; after a stage ran, it asks the later ones :meth:`final_after`; and
    :meth:`close` on every stage on every exit, an error included.
    """

    name: str = ""
    #: Whether the stage still runs once a stage made the map final (:class:`Halt`). The
    #: stages that make a map set it False; a stage that reads or post-processes the final
    #: map (the confidence, the landmarks' re-pinning, a caller's own stage) keeps True.
    runs_on_final_map: bool = True
    #: The name of an earlier stage while which this stage's :meth:`background` work runs.
    alongside: str | None = None

    def attach(self, state: MatchState) -> None:
        """Subscribe to the events of ``state.hooks`` this stage needs."""

    def skip_reason(self, state: MatchState) -> object:
        """``None`` when the stage runs on ``state``, else why not (recorded as skipped), or
        :data:`QUIET` (not recorded)."""
        return None

    def run(self, state: MatchState) -> Halt | None:
        """Transform ``state`` (and record the stage in ``state.log``); a :class:`Halt` when
        the map is final."""
        raise NotImplementedError

    def final_after(self, state: MatchState, name: str) -> str | None:
        """Asked after the earlier stage ``name`` ran: why the map is final now (as if that
        stage had returned a :class:`Halt`), or ``None``."""
        return None

    def background(self, state: MatchState) -> Background | None:
        """The work to run while the stage :attr:`alongside` runs, or ``None`` (asked just
        before that stage runs)."""
        return None

    def close(self, state: MatchState) -> None:
        """Release what the stage holds (called on every exit)."""
