"""One HOPE step and its parts: the overlap assignment at hop radius k, the polish's best
overlap, the voters and the global repair.

The refinement (:mod:`hope_rs.pipeline.refine`) runs them as the steps of its passes
(:mod:`hope_rs.pipeline.refine_steps`); the shared-face finish runs :func:`assign_by_overlap`
after each of its rounds. Maps are in the shapes' internal numbering.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .. import _core
from ..kernels.maps import hint_rows, injective_completion
from ..shape import Shape
from .anchors import anchor_step
from .config import RefineConfig, RepairConfig
from .lmd import LmdTracker
from .state import StepClock

__all__ = ["assign_by_overlap", "best_overlap", "global_repair", "hop_limit", "voters"]


def hop_limit(a: Shape, b: Shape, k_max: int | None) -> int:
    """The largest hop radius a refinement of ``a`` and ``b`` runs: ``k_max`` (the match's
    setting), at most the radius both shapes hold balls for."""
    held = min(a.k_max, b.k_max)
    return held if k_max is None else min(int(k_max), held)


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
