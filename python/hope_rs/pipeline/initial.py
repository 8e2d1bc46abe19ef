"""The initial map from per-vertex descriptors: each vertex's nearest descriptor."""

from __future__ import annotations

import time

import numpy as np

from .. import _core
from ..kernels.maps import injective_completion
from ..kernels.search import SearchConfig, nearest_candidates, nearest_descriptor
from ..shape import Shape
from .state import MatchState, Stage


def initial_map(
    da: np.ndarray,
    db: np.ndarray,
    *,
    one_to_one: bool = False,
    n_candidates: int = 32,
    search: SearchConfig = SearchConfig(),
) -> np.ndarray:
    """Map A → B from descriptors: each vertex's nearest descriptor.

    With ``one_to_one``, the assignment of least total descriptor distance among each vertex's
    ``n_candidates`` nearest descriptors instead (vertices it cannot place take their nearest).
    That is not the default: forcing SHOT matches apart made every measured initial map worse
    and cost seconds more (docs/decisions.md#initial-map).
    """
    if not one_to_one:
        return nearest_descriptor(da, db, search)
    idx, dist = nearest_candidates(da, db, n_candidates, search)
    n_a, n_b = da.shape[0], db.shape[0]
    cost = np.sqrt(dist.astype(np.float64))
    # A fallback arc per row (an injective completion of the nearest neighbours, at a price above
    # any candidate) guarantees a full assignment even when candidate sets crowd together.
    extra = injective_completion(idx[:, 0], n_b)
    cols = np.concatenate([idx, extra[:, None]], axis=1)
    vals = np.concatenate([cost, np.full((n_a, 1), 2.0 * cost.max() + 1.0)], axis=1)
    dup = (cols[:, :-1] == extra[:, None]).any(axis=1)
    vals[dup, -1] = np.inf  # already a candidate: drop the fallback copy below
    keep = np.isfinite(vals)
    indptr = np.concatenate([[0], np.cumsum(keep.sum(axis=1))]).astype(np.int64)
    g = _core.auction_assignment_float(
        indptr, cols[keep].astype(np.int32), vals[keep], n_a, n_b, False
    )
    missing = g < 0
    g[missing] = idx[missing, 0]
    return g


def shapes_initial_map(
    sa: Shape,
    sb: Shape,
    da: np.ndarray,
    db: np.ndarray,
    kind: str,
    search: SearchConfig = SearchConfig(),
) -> np.ndarray:
    """:func:`initial_map` between two :class:`~hope_rs.Shape` objects, from their descriptors
    ``da``, ``db`` of ``kind`` in the internal numbering (the map is in it too). Where the
    vertices of a grid cell share one descriptor (SHOT on dense meshes, see
    :mod:`hope_rs.geometry.sites`), only the cells' sites are searched and each vertex of A follows
    its site."""
    site_a, site_b = sa.descriptor_sites(kind), sb.descriptor_sites(kind)
    rows_a = site_a[0] if site_a is not None else slice(None)
    rows_b = site_b[0] if site_b is not None else slice(None)
    g = initial_map(da[rows_a], db[rows_b], search=search)
    if site_b is not None:
        g = site_b[0][g]
    return g[site_a[1]] if site_a is not None else g


class DescriptorStage(Stage):
    """The "descriptors" stage: both shapes' descriptors of the kind ``state.init`` names."""

    name = "descriptors"
    runs_on_final_map = False

    def skip_reason(self, state: MatchState):
        return _given_start(state)

    def run(self, state: MatchState) -> None:
        kind = state.init
        assert isinstance(kind, str)  # skip_reason skips the stage for a given map
        t = state.log.start("descriptors", detail=kind.upper())
        # In the shapes' internal numbering, like everything up to the result.
        state.a.internal_descriptors(kind), state.b.internal_descriptors(kind)
        state.timings["descriptors"] = time.perf_counter() - t
        state.log.ran("descriptors", state.timings["descriptors"], kind.upper())


class InitialStage(Stage):
    """The "init" stage: ``state.f0``, each vertex's nearest descriptor."""

    name = "init"
    runs_on_final_map = False

    def skip_reason(self, state: MatchState):
        return _given_start(state)

    def run(self, state: MatchState) -> None:
        a, b, kind = state.a, state.b, state.init
        assert isinstance(kind, str)  # skip_reason skips the stage for a given map
        detail = f"nearest {kind.upper()} descriptors"
        t = state.log.start("init", detail=detail)
        da, db = a.internal_descriptors(kind), b.internal_descriptors(kind)
        state.f0 = shapes_initial_map(a, b, da, db, kind, state.config.initial.search)
        state.timings["init"] = time.perf_counter() - t
        state.log.ran("init", state.timings["init"], detail)


def _given_start(state: MatchState) -> str | None:
    """Why the descriptor stages do not run: the map to refine is there already."""
    if state.coarse is not None:
        return "multiscale: the lifted coarse map is the start"
    if not isinstance(state.init, str):
        return "an initial map was given (init=...)"
    return None
