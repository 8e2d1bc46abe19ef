"""Feedback from a running :func:`hope_rs.match`: the package logger, stage records and
progress events.

* ``logging.getLogger("hope_rs")`` logs one INFO line per stage (with its seconds, or why it
  was skipped) and one DEBUG line per refinement step. It has a ``NullHandler``, so nothing is
  printed unless the application configures logging (``hope-rs -v`` / ``-vv`` does).
* :class:`StageInfo` records whether a stage ran, why (or why not), and its seconds;
  :attr:`hope_rs.MatchResult.stages` lists them in the order they ran.
* :class:`ProgressEvent` is what ``match(..., progress=fn)`` passes to ``fn`` as the match
  goes: a start event and a done event per stage, and one event per refinement step between.
  ``progress=True`` draws them with :class:`ProgressBar` on stderr.
"""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable

__all__ = ["STAGES", "ProgressBar", "ProgressEvent", "StageInfo", "Tried", "logger"]

#: The package logger; silent until the application configures logging.
logger = logging.getLogger("hope_rs")
logger.addHandler(logging.NullHandler())

#: Every stage name a match can report, in the order they run. "denoise" appears only when a
#: shape is noisy, "coarse" and "lift" only with ``multiscale=True``, "resolution" only when
#: one shape is much denser than the other, "landmarks" only with landmarks, "deform" only
#: between non-isometric shapes; "polish" is the refinement's last, not one-to-one step.
STAGES = (
    "shapes",
    "denoise",
    "partial",
    "resolution",
    "descriptors",
    "init",
    "coarse",
    "lift",
    "landmarks",
    "refine",
    "polish",
    "spectral",
    "faces",
    "orient",
    "confidence",
    "deform",
)


@dataclass
class Tried:
    """One trial of a stage's choice among candidate matches
    (:mod:`hope_rs.pipeline.trials`): its label, its score (``None``: not scored), whether
    it is the one kept, and the wall time of its match in seconds (0 for the stage's own
    map, which is not matched again)."""

    label: str
    score: float | None = None
    kept: bool = False
    seconds: float = 0.0


@dataclass
class StageInfo:
    """One stage of a match: whether it ran, why or why not, and its wall time.

    Attributes
    ----------
    name : str
        One of :data:`STAGES`.
    ran : bool
        Whether the stage ran.
    reason : str
        What it did when it ran, why it was skipped otherwise.
    seconds : float
        Wall time of the stage (0 when skipped). "refine" excludes the polish step here,
        while ``MatchResult.timings["refine"]`` counts it.
    trials : list of Tried
        The candidate matches the stage tried, in order, the kept one marked (the partial
        stage's scales; the orient stage's own map, its hypotheses scored by minus their
        cost, and unscored the matches they derive from; empty for most stages).
    """

    name: str
    ran: bool
    reason: str = ""
    seconds: float = 0.0
    trials: list[Tried] = field(default_factory=list)

    def __str__(self) -> str:
        if self.ran:
            return f"{self.name}: {self.seconds:.2f} s" + (
                f" ({self.reason})" if self.reason else ""
            )
        return f"{self.name}: skipped ({self.reason})"


@dataclass
class ProgressEvent:
    """A progress report from a running match.

    Attributes
    ----------
    stage : str
        The stage (one of :data:`STAGES`).
    step : int
        Steps of the stage done so far (refinement steps for "refine"; 0 at a stage's start).
    total : int or None
        Steps the stage takes at most (``None``: no steps to count). For "refine" it is the
        step count of ``max_passes`` passes; the refinement often stops sooner.
    elapsed : float
        Seconds since the match started.
    done : bool
        This is the stage's last event (it finished, or it was skipped).
    ran : bool
        ``False`` on the done event of a skipped stage (usually its only event; the spectral
        pass may have announced its start before HOPE's map turned out to be settled).
    detail : str
        One line for people: the step ("pass 2/4 k=5 witnesses 93.1% changed 120"), or when
        done the stage's :attr:`StageInfo.reason`.
    iteration : hope_rs.pipeline.state.Iteration or None
        For refinement and polish steps, the record ``callback`` also receives.
    seconds : float
        On a done event of a stage that ran, the stage's wall time.
    """

    stage: str
    step: int
    total: int | None
    elapsed: float
    done: bool = False
    ran: bool = True
    detail: str = ""
    iteration: Any = None
    seconds: float = 0.0


def step_detail(it, n_passes: int) -> str:
    """One line about a refinement step (an :class:`~hope_rs.pipeline.state.Iteration`)."""
    what = "polish" if it.polish else f"pass {it.n_pass + 1}/{n_passes}"
    kind = "repair" if it.k == 0 and not it.polish else f"k={it.k}"
    return f"{what} {kind} witnesses {100 * it.witness_fraction:4.1f}% changed {it.changed:6d}"


class StageLog:
    """Records the stages of one match (:class:`StageInfo`), logs them and passes
    :class:`ProgressEvent` objects to ``progress`` (a callable, or ``None``)."""

    def __init__(self, progress: Callable[[ProgressEvent], Any] | None = None, t0=None):
        self.stages: list[StageInfo] = []
        #: Per stage, the trials recorded while it runs (:meth:`tried`).
        self.trials: dict[str, list[Tried]] = {}
        self.progress = progress
        self.t0 = time.perf_counter() if t0 is None else t0
        # A nested match (the coarse one of a multiscale match) logs as "coarse refine: ...".
        self.prefix = getattr(progress, "log_prefix", "")

    def relay(self, stage: str) -> _Relay:
        """A ``progress`` callable for a nested match: its events become steps of ``stage``."""
        return _Relay(self, stage)

    def _emit(self, stage: str, step: int, total, **kw) -> None:
        if self.progress is not None:
            elapsed = time.perf_counter() - self.t0
            self.progress(ProgressEvent(stage, step, total, elapsed, **kw))

    def start(self, stage: str, total: int | None = None, detail: str = "") -> float:
        """Announces a stage; returns its start time (``time.perf_counter()``)."""
        self._emit(stage, 0, total, detail=detail)
        return time.perf_counter()

    def step(self, stage: str, step: int, total, detail: str, iteration=None) -> None:
        seconds = getattr(iteration, "seconds", 0.0)
        logger.debug("%s%s: %s (%.2f s)", self.prefix, stage, detail, seconds)
        self._emit(stage, step, total, detail=detail, iteration=iteration)

    def tried(self, stage: str, record: Tried) -> None:
        """Records a trial of ``stage``, listed in its :class:`StageInfo` when it ran."""
        self.trials.setdefault(stage, []).append(record)

    def ran(self, stage: str, seconds: float, reason: str = "", step: int = 0, total=None):
        info = StageInfo(stage, True, reason, seconds, self.trials.pop(stage, []))
        self.stages.append(info)
        logger.info("%s%s", self.prefix, info)
        self._emit(stage, step, total, done=True, detail=reason, seconds=seconds)

    def skipped(self, stage: str, reason: str) -> None:
        info = StageInfo(stage, False, reason)
        self.stages.append(info)
        logger.info("%s%s", self.prefix, info)
        self._emit(stage, 0, None, done=True, ran=False, detail=reason)


class _Relay:
    """Passes a nested match's events on as steps of one stage of the outer match; ``last``
    is the time of the latest one (``time.perf_counter()``)."""

    def __init__(self, log: StageLog, stage: str, label: str = ""):
        self.outer, self.stage, self.last = log, stage, time.perf_counter()
        self.log_prefix = log.prefix + stage + " " + (label + " " if label else "")

    def labelled(self, label: str) -> _Relay:
        """The same relay, its nested match's log lines also headed by ``label`` (a trial's)."""
        return _Relay(self.outer, self.stage, label)

    def __call__(self, ev: ProgressEvent) -> None:
        self.last = time.perf_counter()
        state = "skipped: " if not ev.ran else ("done " if ev.done else "")
        detail = f"{ev.stage} {state}{ev.detail}"
        self.outer._emit(self.stage, ev.step, ev.total, detail=detail, iteration=ev.iteration)


class ProgressBar:
    """Draws :class:`ProgressEvent` objects on a stream (stderr by default).

    On a terminal or in a notebook: one line, rewritten at every event (stage, a bar over the
    stage's steps where it has any, the step, elapsed seconds). Elsewhere (a log file, a pipe):
    one line per stage when it finishes or is skipped, so logs stay short. Call :meth:`close`
    at the end (``match`` does, for the bar it makes with ``progress=True``).

    Parameters
    ----------
    stream : file-like, optional
        Where to write (default ``sys.stderr`` at the time of each write).
    live : bool, optional
        Rewrite one line (``True``) or print one line per stage (``False``); default: whether
        the stream is a terminal or a Jupyter output.
    width : int
        Characters of the rewritten line.
    """

    def __init__(self, stream=None, *, live: bool | None = None, width: int = 100):
        self._stream, self.width, self._open = stream, width, False
        self.live = _is_live(self.stream) if live is None else live

    @property
    def stream(self):
        return sys.stderr if self._stream is None else self._stream

    def __call__(self, ev: ProgressEvent) -> None:
        if self.live:
            self._rewrite(ev)
        elif ev.done:
            self.stream.write(_stage_line(ev) + "\n")
            self.stream.flush()

    def _rewrite(self, ev: ProgressEvent) -> None:
        bar = ""
        if ev.total:
            fill = int(16 * min(ev.step, ev.total) / ev.total) if not ev.done else 16
            bar = f"[{'#' * fill}{'.' * (16 - fill)}] "
        state = "skipped: " if not ev.ran else ("done " if ev.done else "")
        line = f"hope_rs {ev.stage:<11} {bar}{state}{ev.detail}"
        line = f"{line[: self.width - 8]:<{self.width - 8}}{ev.elapsed:7.1f}s"
        self.stream.write("\r" + line)
        self.stream.flush()
        self._open = True

    def close(self) -> None:
        """Ends the rewritten line (a newline), if one was drawn."""
        if self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = False


def _stage_line(ev: ProgressEvent) -> str:
    if not ev.ran:
        return f"hope_rs: {ev.stage}: skipped ({ev.detail})"
    return f"hope_rs: {ev.stage}: {ev.seconds:.2f} s" + (f" ({ev.detail})" if ev.detail else "")


def _is_live(stream) -> bool:
    """A terminal, or a Jupyter output stream (not a TTY, but it honours carriage returns)."""
    try:
        if stream.isatty():
            return True
    except (AttributeError, ValueError):
        return False
    return type(stream).__module__.startswith("ipykernel")
