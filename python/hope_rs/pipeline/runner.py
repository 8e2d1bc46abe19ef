"""The stage runner: a match as a list of stages run in order on one state.

:func:`run_match` takes two :class:`~hope_rs.Shape` objects and an initial map or descriptor
kind, translates to the shapes' internal numbering, runs the stages
(:func:`~hope_rs.pipeline.stages.default_stages` by default) and translates the result back.

:func:`run_stages` owns the flow between the stages (see :mod:`hope_rs.pipeline.state`):
a :class:`~hope_rs.pipeline.state.Halt` a stage returns, or a later stage declares after it
(:meth:`~hope_rs.pipeline.state.Stage.final_after`), skips the stages after it that would
change the map; each stage's :class:`~hope_rs.pipeline.state.Background` work runs alongside
the stage it names and ends with it on every exit, and every stage's
:meth:`~hope_rs.pipeline.state.Stage.close` runs on every exit, so no background work
outlives the match.
"""

from __future__ import annotations

import dataclasses
import time
from contextlib import ExitStack
from typing import Callable, cast

import numpy as np

from ..shape import Shape
from .confidence import state_quality
from .config import MatchConfig
from .progress import StageLog
from .result import MatchResult
from .stages import default_stages
from .state import QUIET, Halt, MatchState, Stage

__all__ = ["run_match", "run_stages"]


def run_stages(state: MatchState, stages: list[Stage]) -> MatchState:
    """Runs ``stages`` on ``state`` in order (see :class:`~hope_rs.pipeline.state.Stage`)."""
    halt: Halt | None = None
    try:
        for stage in stages:
            stage.attach(state)
        for i, stage in enumerate(stages):
            reason = stage.skip_reason(state)
            if reason is None and halt is not None and not stage.runs_on_final_map:
                reason = halt.reason
            if reason is None:
                halt = _run_one(state, stage, stages[i + 1 :]) or halt
            elif reason is not QUIET:
                # Any answer but None and QUIET is the reason, a str (Stage.skip_reason).
                state.log.skipped(stage.name, cast(str, reason))
            state.hooks.emit("stage_end", state, stage.name)
    finally:
        for stage in reversed(stages):
            stage.close(state)
    return state


def _run_one(state: MatchState, stage: Stage, later: list[Stage]) -> Halt | None:
    """Runs ``stage`` with the background work of the ``later`` stages that runs alongside
    it; the stage's halt, or the first later stage's verdict that the map is final now."""
    with ExitStack() as stack:
        work = []
        for s in later:
            bg = s.background(state) if s.alongside == stage.name else None
            if bg is not None:
                work.append(stack.enter_context(bg))
        halt = stage.run(state)
        if halt is None:
            reasons = (s.final_after(state, stage.name) for s in later)
            reason = next((r for r in reasons if r is not None), None)
            halt = None if reason is None else Halt(reason)
        for bg in work:
            bg.keep = halt is None
    return halt


def run_match(
    a: Shape,
    b: Shape,
    init,
    config: MatchConfig,
    *,
    callback=None,
    progress: Callable | None = None,
    log: StageLog | None = None,
    stages: list[Stage] | None = None,
    on_stage: Callable | None = None,
    timings: dict[str, float] | None = None,
    landmarks: np.ndarray | None = None,
) -> MatchResult:
    """The match of ``a`` to ``b``: ``init`` is a descriptor kind or a map in the shapes' input
    numbering; ``progress`` receives the stages' events (or pass ``log``, which has them);
    ``on_stage(state, name)`` is called after each stage (the benches sample memory there);
    ``timings`` (seconds per stage) is filled in and returned as the result's; ``landmarks``
    (checked (m, 2) rows of input vertex indices, or None) are translated like ``init``.
    Options are not checked here (:func:`hope_rs.match` does)."""
    t0 = time.perf_counter() if log is None else log.t0
    log = StageLog(progress) if log is None else log
    if not isinstance(init, str):
        init = a.map_in(b, init)
    state = MatchState(a, b, config, init, log, callback=callback, run=_nested_run(stages))
    state.timings = {} if timings is None else timings
    if not isinstance(init, str):
        state.f0 = init
    if landmarks is not None:
        lm = np.stack([a.rank[landmarks[:, 0]], b.rank[landmarks[:, 1]]], axis=1)
        state.landmarks = lm[np.argsort(lm[:, 0])]
    if on_stage is not None:
        state.hooks.on("stage_end", on_stage)
    run_stages(state, default_stages() if stages is None else stages)
    state.timings["total"] = time.perf_counter() - t0
    confidence = None if state.confidence is None else state.confidence[a.rank]
    quality = state_quality(state)
    assert state.f is not None and state.f0 is not None and state.hope_map is not None
    return MatchResult(
        map=a.map_out(b, state.f).astype(np.int64),
        init_map=a.map_out(b, state.f0).astype(np.int64),
        history=state.history,
        timings=state.timings,
        coarse=state.coarse,
        hope_map=a.map_out(b, state.hope_map).astype(np.int64),
        stages=log.stages,
        config=state.config,
        confidence=confidence,
        quality=quality,
    )


def _nested_run(stages: list[Stage] | None) -> Callable:
    """:func:`run_match` for a stage that matches other shapes, with fresh stages."""

    def run(
        a: Shape,
        b: Shape,
        init,
        config: MatchConfig,
        *,
        callback=None,
        progress=None,
        landmarks=None,
        on_stage=None,
    ):
        fresh = None if stages is None else [type(s)() for s in stages]
        # The outer match decided which shapes to denoise: the nested match's shapes are
        # those, or copies of them (a mirror image, a coarse copy), not smoothed again.
        config = dataclasses.replace(
            config, denoise=dataclasses.replace(config.denoise, enabled=False)
        )
        return run_match(
            a,
            b,
            init,
            config,
            callback=callback,
            progress=progress,
            stages=fresh,
            landmarks=landmarks,
            on_stage=on_stage,
        )

    return run
