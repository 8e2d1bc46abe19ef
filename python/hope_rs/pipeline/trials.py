"""Trials: match several candidates, score each, keep one.

Some choices cannot be made before matching: at which scale a part of a shape settles on the
right region of the whole (the partial stage), which of several hypotheses keeps a map's
orientation. A stage makes such a choice with the runner's own match of each candidate: a
:class:`Candidate` names the shapes, the start and the settings of one match,
:func:`run_trials` runs the candidates with ``state.run`` (the runner, with fresh stages),
scores each with the caller's function and returns the kept :class:`Trial`, and
:func:`adopt` makes the kept match the state's. Every trial is recorded with its score in the
stage's :class:`~hope_rs.pipeline.progress.StageInfo` (``res.stage(name).trials``), the kept
one marked.

Example: keep the best of a map and two alternative starts by a score of the result::

    def score(t: Trial) -> float:
        return -distortion(t.result) - orientation_penalty(t.result)

    cands = [
        Candidate(label, state.a, state.b, state.a.map_out(state.b, f), config)
        for label, f in (("as is", state.f), ("mirrored", g), ("reseeded", h))
    ]
    kept = run_trials(state, "repair", cands, score).kept
    adopt(state, kept)

Several rounds refine a choice: a round given ``against`` (a trial kept before) keeps its
own best only when that beats it (strictly, or by at least ``margin``), each scored by the
round's function; :func:`run_trial` runs one candidate unscored (a first match whose result
decides the next candidates). Trials of several rounds are compared at once with
:func:`choose`, and :func:`current` stands for the state's own map (a trial not run) where
a stage keeps it unless a candidate beats it.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..shape import Shape
from .config import MatchConfig
from .progress import Tried
from .result import MatchResult
from .state import MatchState

__all__ = [
    "Candidate",
    "Trial",
    "Trials",
    "adopt",
    "carried_confidence",
    "choose",
    "current",
    "mean_confidence",
    "run_trial",
    "run_trials",
]


@dataclass(frozen=True)
class Candidate:
    """One match to try.

    Attributes
    ----------
    label : str
        How the trial is recorded ("x0.95", "mirrored").
    a, b : Shape
        The shapes (views such as :meth:`~hope_rs.Shape.at_scale` included).
    init : str or ndarray
        A descriptor kind, or a start map in the shapes' input numbering
        (``a.map_out(b, f)`` of a map ``f`` in their internal numbering).
    config : MatchConfig
        The settings of the match; turn off the stage that runs the trials in it (as the
        partial stage does) or it runs them again.
    landmarks : (m, 2) ndarray or None
        Landmarks in the shapes' input numbering.
    """

    label: str
    a: Shape
    b: Shape
    init: str | np.ndarray
    config: MatchConfig
    landmarks: np.ndarray | None = None


@dataclass
class Trial:
    """A candidate's match and its score (``None`` until scored); ``zoomout``: the match's
    ZoomOut map (internal numbering of the candidate's shapes), when its spectral pass made
    one."""

    candidate: Candidate
    result: MatchResult
    score: float | None
    record: Tried
    zoomout: np.ndarray | None = None


@dataclass
class Trials:
    """A round of :func:`run_trials`: the kept trial and the trials it ran, in order."""

    kept: Trial
    tried: list[Trial]


def run_trial(
    state: MatchState,
    stage: str,
    candidate: Candidate,
    progress: Callable | None = None,
    *,
    callback: Callable | None = None,
) -> Trial:
    """The match of ``candidate`` (the runner's stages, fresh), recorded under ``stage``
    unscored; the trial is kept until a later round keeps another. ``progress`` receives
    the nested match's events (``state.log.relay(stage)`` logs them under the stage), and
    ``callback`` each of its steps (a stage whose kept trial's steps become the match's
    history passes the caller's)."""
    c = candidate
    assert state.run is not None  # the runner sets it
    last: dict = {}
    labelled = getattr(progress, "labelled", None)
    if labelled is not None:  # a relay: the trial's log lines headed by its label
        progress = labelled(c.label)

    def grab(s: MatchState, name: str) -> None:
        last["zoomout"] = s.zoomout

    t = time.perf_counter()
    result = state.run(
        c.a,
        c.b,
        c.init,
        c.config,
        callback=callback,
        progress=progress,
        landmarks=c.landmarks,
        on_stage=grab,
    )
    record = Tried(c.label, seconds=time.perf_counter() - t)
    trial = Trial(c, result, None, record, last.get("zoomout"))
    state.log.tried(stage, trial.record)
    _mark_kept(state, stage, trial)
    return trial


def current(state: MatchState, stage: str, label: str) -> Trial:
    """The state's own map as a trial (not run again), recorded under ``stage``: pass it as
    ``against`` so a round keeps it unless a candidate beats it."""
    assert state.f is not None and state.f0 is not None and state.hope_map is not None
    a, b = state.a, state.b
    init = state.init if isinstance(state.init, str) else a.map_out(b, state.init)
    result = MatchResult(
        map=a.map_out(b, state.f).astype(np.int64),
        init_map=a.map_out(b, state.f0).astype(np.int64),
        history=state.history,
        timings=dict(state.timings),
        hope_map=a.map_out(b, state.hope_map).astype(np.int64),
        config=state.config,
    )
    trial = Trial(Candidate(label, a, b, init, state.config), result, None, Tried(label))
    trial.zoomout = state.zoomout
    state.log.tried(stage, trial.record)
    return trial


def run_trials(
    state: MatchState,
    stage: str,
    candidates: Sequence[Candidate],
    score: Callable[[Trial], float],
    *,
    against: Trial | None = None,
    margin: float | None = None,
    progress: Callable | None = None,
    callback: Callable | None = None,
) -> Trials:
    """Matches every candidate in order, scores each with ``score`` (higher is better) and
    keeps the first of the highest score. With ``against`` (a trial kept before, scored
    again by ``score``), that one stays kept unless the round's best beats it: by a higher
    score, or with ``margin`` by at least ``margin``. Records every trial under ``stage``."""
    if not candidates:
        raise ValueError("run_trials needs at least one candidate")
    tried = []
    for c in candidates:
        t = run_trial(state, stage, c, progress, callback=callback)
        t.score = t.record.score = float(score(t))
        tried.append(t)
    if against is not None:
        against.score = against.record.score = float(score(against))
    return Trials(choose(state, stage, tried, against=against, margin=margin), tried)


def choose(
    state: MatchState,
    stage: str,
    tried: Sequence[Trial],
    *,
    against: Trial | None = None,
    margin: float | None = None,
) -> Trial:
    """The first of the highest score among ``tried`` (scored trials, of one round or
    several), or ``against`` (scored) unless that best beats it (see :func:`run_trials`);
    marked kept under ``stage``."""
    if not tried and against is None:
        raise ValueError("choose needs at least one trial")
    kept = max(tried, key=_score_of) if tried else against
    assert kept is not None
    if against is not None and kept is not against:
        best_score, against_score = _score_of(kept), _score_of(against)
        beats = (
            best_score > against_score if margin is None else best_score >= against_score + margin
        )
        kept = kept if beats else against
    _mark_kept(state, stage, kept)
    return kept


def _score_of(trial: Trial) -> float:
    assert trial.score is not None  # run_trials scores each trial before comparing it
    return trial.score


def _mark_kept(state: MatchState, stage: str, kept: Trial) -> None:
    for r in state.log.trials.get(stage, []):
        r.kept = r is kept.record


def adopt(state: MatchState, trial: Trial, *, maps_only: bool = False) -> None:
    """Makes ``trial``'s match the state's: its shapes, its maps (initial, final, HOPE's, in
    the shapes' internal numbering) and history, and its stages' seconds within the state's
    timings. With ``maps_only`` the state keeps its initial map, history and timings (a
    stage after the refinement replacing the map: the caller's callback saw the state's
    refinement, not the trial's). The ZoomOut map (``trial.zoomout``) is the caller's to
    take: a part matched at another scale (the partial stage) leaves the whole's confidence
    without it."""
    c, r = trial.candidate, trial.result
    assert r.hope_map is not None  # run_match always sets it
    state.a, state.b = c.a, c.b
    state.f = c.a.map_in(c.b, r.map)
    state.hope_map = c.a.map_in(c.b, r.hope_map)
    if maps_only:
        return
    state.f0 = c.a.map_in(c.b, r.init_map)
    state.history = r.history
    state.timings.update({k: v for k, v in r.timings.items() if k != "total"})


def carried_confidence(state: MatchState, trial: Trial) -> np.ndarray | None:
    """The confidence of ``trial``'s match in the state's internal numbering of A, when that
    match was lifted from a common resolution (its confidence carried over from there:
    measured on a dense shape's many-to-one map at full resolution, it flags right maps) and
    the state's settings ask for a confidence; else ``None`` (the confidence stage measures
    the adopted map). The trial's A is ``state.a`` or a view of it at another scale."""
    conf = trial.result.confidence
    lifted = any(s.name == "resolution" and s.ran for s in trial.result.stages)
    if conf is None or not lifted or not state.config.confidence.enabled:
        return None
    return conf[state.a.order]


def mean_confidence(trial: Trial) -> float:
    """The mean confidence of a trial's match (its config must compute one)."""
    confidence = trial.result.confidence
    assert confidence is not None  # the trials' config turns the confidence on
    return float(np.mean(confidence))
