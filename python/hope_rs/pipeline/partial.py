"""Partial shapes: when one shape is a part of the other (a cut, holes, a partial scan).

Every distance of a match is measured in units of the shape's own sqrt(area): the SHOT radius,
LMD's 2-ring distances, the global repair's geodesics. A part's sqrt(area) is smaller than the
whole's, so on a part all of them would shrink (by 1/sqrt(0.5) for half a shape) and no
distance of the part would agree with its counterpart on the whole. The "partial" stage
detects a part by its boundary and measures it at the other shape's scale (see
:meth:`hope_rs.Shape.at_scale`); shapes of the same units then compare as they are.

A shape is a part when its boundary is longer than the other shape's by at least
``PartialConfig.min_boundary_excess`` (both in units of their own sqrt(area)); closed shapes,
and pairs with boundaries of about the same length, are matched exactly as before.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..shape import Shape
from .config import PartialConfig
from .state import QUIET, MatchState, Stage

__all__ = ["PartialInfo", "PartialStage", "boundary_length", "detect_part"]


def boundary_length(shape: Shape) -> float:
    """Total length of the edges of one face only, in units of the shape's own sqrt(area)."""
    f = shape.internal.faces
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    u, count = np.unique(e, axis=0, return_counts=True)
    b = u[count == 1]
    p = shape.internal.vertices
    return float(np.linalg.norm(p[b[:, 0]] - p[b[:, 1]], axis=1).sum() / shape.internal.scale)


@dataclass(frozen=True)
class PartialInfo:
    """Which shape of a pair is a part of the other.

    Attributes
    ----------
    part : {"a", "b"}
        The shape that is a part.
    boundary : tuple of float
        Boundary lengths of A and B, each in units of its own sqrt(area).
    scale : float
        The scale both shapes are measured at (the whole's sqrt(area)).
    """

    part: str
    boundary: tuple[float, float]
    scale: float


def detect_part(a: Shape, b: Shape, config: PartialConfig | None = None) -> PartialInfo | None:
    """:class:`PartialInfo` when A or B is a part of the other (see the module notes), else
    ``None``; ``config`` defaults to ``PartialConfig()``."""
    config = PartialConfig() if config is None else config
    la, lb = boundary_length(a), boundary_length(b)
    if la - lb >= config.min_boundary_excess and a.scale < b.scale:
        return PartialInfo("a", (la, lb), b.scale)
    if lb - la >= config.min_boundary_excess and b.scale < a.scale:
        return PartialInfo("b", (la, lb), a.scale)
    return None


class PartialStage(Stage):
    """The "partial" stage: when one shape is a part of the other, both are measured at the
    whole's scale from here on (``state.a``/``state.b`` become :meth:`~hope_rs.Shape.at_scale`
    views) and ``state.partial`` says which is the part. Not recorded when neither is."""

    name = "partial"

    def __init__(self):
        self.info: PartialInfo | None = None

    def skip_reason(self, state: MatchState):
        cfg = state.config.partial
        if not cfg.enabled:
            return QUIET
        self.info = detect_part(state.a, state.b, cfg)
        return QUIET if self.info is None else None

    def run(self, state: MatchState) -> None:
        info = self.info
        assert info is not None
        la, lb = info.boundary
        detail = (
            f"{info.part.upper()} is a part (boundary {la:.2f} vs {lb:.2f} sqrt(area)): "
            "matched at the whole's scale"
        )
        t = state.log.start("partial", detail=detail)
        if info.part == "a":
            state.a = state.a.at_scale(info.scale)
        else:
            state.b = state.b.at_scale(info.scale)
        state.partial = info
        state.timings["partial"] = time.perf_counter() - t
        state.log.ran("partial", state.timings["partial"], detail)
