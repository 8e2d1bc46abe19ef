"""Which shape of a pair is a part of the other, as the partial stage found it
(:mod:`hope_rs.pipeline.partial`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PartialInfo"]


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
        The scale the part is measured at: the larger sqrt(area) of the two.
    counterpart : (n_a,) bool ndarray or None
        Per vertex of A (internal numbering), whether it has a counterpart on B: all True when
        A is the part; when B is, those whose image the reverse match places near them or
        that lie in a small gap among those images (see :mod:`hope_rs.pipeline.partial`);
        ``None`` until known.
    """

    part: str
    boundary: tuple[float, float]
    scale: float
    counterpart: np.ndarray | None = None
