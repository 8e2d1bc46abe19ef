"""How far to trust each vertex's match: the "confidence" stage.

It runs before the deformation pass (:mod:`hope_rs.pipeline.deform`), which moves each image by
a smooth displacement, not onto another region: the confidence and the pair-level flag judge
the map that pass starts from (its nearest-point map is less consistent locally, which the
features read as doubt where the pass made the map better).

A wrong region of a map is often consistent locally (a limb carried onto its mirror image
keeps its 2-rings), so no one feature tells. The confidence combines what the pipeline knows
about the map ``f``, each in the shapes' internal numbering (see
:data:`~hope_rs.pipeline.config.CONFIDENCE_FEATURES`):

* LMD of ``f`` (:mod:`hope_rs.pipeline.lmd`): its consistent share and mean distortion;
* long-range agreement: geodesic distances to farthest-point anchors among the consistent
  vertices (:mod:`hope_rs.pipeline.anchors`) kept or bent by ``f``;
* agreement between stages: how far on B HOPE's map and ZoomOut's land from ``f`` (a lower
  bound of the geodesic distance, from the anchors' distance fields);
* smoothness: the B/A ratio of edge lengths under ``f``;
* the pair's mean consistent share (a pair that went wrong as a whole);

averaged over a few rings so that regions, not single vertices, lose confidence, and combined
by a logistic model (:class:`~hope_rs.pipeline.config.ConfidenceConfig`), then lowered where
the map turns the surroundings over (:func:`turned_factor`); a shape too small to judge
(``ConfidenceConfig.min_vertices``) gets 0 (:func:`vertex_confidence`). The stage reads the
maps only: ``MatchResult.map`` is the same with or without it.

The pair-level summary (:class:`MatchQuality`) also measures the share of A's area whose
triangles the map turns over (:func:`flipped_share`). A region carried onto a swapped branch
(a part's torso onto a leg, the leg onto the torso) can keep its distances and its 2-rings,
so its confidence stays middling, but its triangles land on B wound the other way.
"""

from __future__ import annotations

import time

import numpy as np

from ..shape import Shape
from .anchors import (
    agree,
    distance_fields,
    drop_disagreeing_anchors,
    farthest_witnesses,
    reachable,
    shift_lower_bound,
)
from .config import CONFIDENCE_FEATURES, ConfidenceConfig, MatchConfig, RefineConfig, RepairConfig
from .lmd import local_map_distortion
from .result import MatchQuality
from .state import CommonView, MatchState, Stage
from .turned import TurnedFaces

__all__ = [
    "ConfidenceStage",
    "MatchQuality",
    "confidence_features",
    "flipped_share",
    "judged_shapes",
    "map_quality",
    "match_quality",
    "predict_confidence",
    "state_quality",
    "turned_factor",
    "vertex_confidence",
]


def match_quality(
    confidence: np.ndarray, config: ConfidenceConfig = ConfidenceConfig(), *, flipped: float = 0.0
) -> MatchQuality:
    """The :class:`MatchQuality` of a per-vertex ``confidence`` and a map's
    :func:`flipped_share` under ``config``'s rule.

    Examples
    --------
    >>> import numpy as np
    >>> match_quality(np.array([0.9, 0.8, 0.7]), flipped=0.05).likely_failed
    False
    >>> match_quality(np.array([0.9, 0.8, 0.7]), flipped=0.45).likely_failed
    True
    """
    c = np.asarray(confidence, dtype=np.float64)
    mean = float(c.mean()) if c.size else 0.0
    share = float((c >= config.threshold).mean()) if c.size else 0.0
    failed = (
        mean < config.failed_mean or share < config.failed_share or flipped > config.failed_flipped
    )
    return MatchQuality(mean, share, bool(failed), float(flipped))


def map_quality(
    a: Shape,
    b: Shape,
    f: np.ndarray,
    hope: np.ndarray | None,
    zoomout: np.ndarray | None,
    config: MatchConfig,
    *,
    flipped: float | None = None,
) -> MatchQuality:
    """The :class:`MatchQuality` the confidence stage would give the map ``f`` of two whole
    shapes, with HOPE's and ZoomOut's maps ``hope`` and ``zoomout`` (internal numbering;
    ``None``: not available), under ``config``'s confidence and refinement settings (whether
    or not ``config`` asks for a confidence); ``flipped``: the map's :func:`flipped_share`
    when the caller has measured it."""
    cfg = config.confidence
    if flipped is None:
        flipped = flipped_share(a, b, f)
    a, b = judged_shapes(a, b, cfg)
    x = confidence_features(
        a,
        b,
        f,
        hope,
        zoomout,
        cfg,
        min_consistent=config.refine.min_consistent,
        repair=config.refine.repair,
    )
    confidence = vertex_confidence(a, b, f, x, cfg)
    return match_quality(confidence, cfg, flipped=flipped)


def judged_shapes(a: Shape, b: Shape, config: ConfidenceConfig) -> tuple[Shape, Shape]:
    """The shapes as the confidence measures a map between them: a noisy one (one umbrella
    smoothing takes more than ``config.noisy`` of its normal roughness out,
    :meth:`~hope_rs.Shape.smoothing_drop`) more than ``config.denser`` times as dense as the
    other (vertices per unit area in the units matched in) smoothed ``config.rough_smoothing``
    times (:meth:`~hope_rs.Shape.smoothed`, same numbering). The images of a sparser shape's
    2-rings and anchors lie many short edges apart on a dense scan, whose noisy edge paths
    zigzag: its geodesic distances run long and a right map reads as distorted. At like
    densities the model reads noise as it reads it on its own (the pair matched at a common
    resolution is judged on copies of like density). The features and the per-vertex turned
    factor (a right map turns a noisy scan's own small triangles over at random) are measured
    on them; the pair's turned-over share is not: it stays at full resolution, where the
    orient stage's trigger and the flag were set."""
    n = config.rough_smoothing

    def judged(s: Shape, other: Shape) -> Shape:
        if n == 0 or s.density <= config.denser * other.density:
            return s
        return s.smoothed(n) if s.smoothing_drop > config.noisy else s

    return judged(a, b), judged(b, a)


def state_quality(state: MatchState) -> MatchQuality | None:
    """The :class:`MatchQuality` of the state's map and confidence (``None`` without a
    confidence; a map lifted from a common resolution has that match's confidence, carried
    to each vertex); a whole's vertices without a counterpart on the part (the partial
    stage's ``counterpart``) have no right match to find, and the pair is judged on the
    others."""
    if state.confidence is None:
        return None
    assert state.f is not None  # a confidence comes with a map
    counterpart = None if state.partial is None else state.partial.counterpart
    judged = state.confidence if counterpart is None else state.confidence[counterpart]
    view = state.common_a if counterpart is None else None
    flipped = flipped_share(state.a, state.b, state.f, among=counterpart, view=view)
    return match_quality(judged, state.config.confidence, flipped=flipped)


def flipped_share(
    a: Shape,
    b: Shape,
    f: np.ndarray,
    among: np.ndarray | None = None,
    view: CommonView | None = None,
) -> float:
    """The share of A's area whose triangles ``f`` turns over
    (:class:`~hope_rs.pipeline.turned.TurnedFaces`: triangles whose image is degenerate count
    on neither side, and in a group with an open component the smaller side counts as turned,
    at most half of it).

    On remeshed pairs a right map turns a few percent of the area over, where the two
    triangulations disagree; a region carried onto a mirror image or a swapped branch turns
    over as a whole.

    Parameters
    ----------
    a, b : Shape
        The shapes (a view at another scale reads the same mesh).
    f : (n_a,) ndarray of int
        The map, internal numbering.
    among : (n_a,) bool ndarray, optional
        The vertices of A (internal numbering) whose triangles count.
    view : CommonView, optional
        A dense A's copy the map was made at (:mod:`~hope_rs.pipeline.resolution`): when A
        is rough at its own resolution (``view.rough``, a noisy scan, whose triangles a
        right map turns over at random) the share is measured on the copy, ``f`` read at
        its vertices. Not with ``among``.

    Returns
    -------
    float
        In [0, 1]; 0 when no triangle counts.
    """
    if view is not None and view.rough:
        assert among is None  # a part is not matched at a common resolution
        return TurnedFaces(view.shape, b).share(view.of(f))
    return TurnedFaces(a, b, among).share(f)


def confidence_features(
    a: Shape,
    b: Shape,
    f: np.ndarray,
    hope: np.ndarray | None = None,
    zoomout: np.ndarray | None = None,
    config: ConfidenceConfig = ConfidenceConfig(),
    *,
    min_consistent: float = RefineConfig.min_consistent,
    repair: RepairConfig = RepairConfig(),
    among: np.ndarray | None = None,
) -> np.ndarray:
    """The features of :data:`~hope_rs.pipeline.config.CONFIDENCE_FEATURES` per vertex of A,
    (n_a, n_features) float64, for the map ``f`` and the stages' maps ``hope`` and ``zoomout``
    (internal numbering; ``None``: not available). ``repair`` says when two geodesic
    distances agree; ``min_consistent`` which vertices can be anchors. ``among`` (bool per
    vertex of A, or ``None`` for all): the vertices that can be anchors and that the pair-level
    feature averages over (a whole's vertices with a counterpart on the part; the others have
    no right match)."""
    f = np.asarray(f, dtype=np.int64)
    n = a.n_vertices
    mean, consistent = local_map_distortion(a, b, f)
    mean = mean.astype(np.float64)
    consistent = consistent.astype(np.float64)
    # Anchors among the consistent vertices; the anchors whose own images are wrong drop out.
    among = np.ones(n, dtype=bool) if among is None else np.asarray(among, dtype=bool)
    cand = np.flatnonzero((consistent >= min_consistent) & among)
    if cand.size < 4:
        cand = np.arange(n)
    anchors, da = farthest_witnesses(a, cand, config.n_anchors)
    db = distance_fields(b, f[anchors])
    anchors, da, db = drop_disagreeing_anchors(f, anchors, da, db, repair)
    da, db = reachable(da, repair), reachable(db, repair)
    dbf = db[:, f]
    anchor_agreement = agree(da, dbf, repair).mean(axis=0)
    anchor_error = np.abs(da - dbf).mean(axis=0)
    hope_shift = np.zeros(n) if hope is None else shift_lower_bound(db, f, hope)
    zoom_shift = np.zeros(n) if zoomout is None else shift_lower_bound(db, f, zoomout)
    # Edge stretch: |f(i) f(j)| on B over |i j| on A, both in sqrt(area) units.
    e = a.edges
    la = np.linalg.norm(a.points[e[:, 0]] - a.points[e[:, 1]], axis=1) / a.scale
    lb = np.linalg.norm(b.points[f[e[:, 0]]] - b.points[f[e[:, 1]]], axis=1) / b.scale
    ratio = lb / np.maximum(la, 1e-12)
    deg = np.bincount(e.ravel(), minlength=n).astype(np.float64)
    stretch: np.ndarray = np.bincount(e.ravel(), weights=np.repeat(ratio, 2), minlength=n)
    stretch = stretch / np.maximum(deg, 1.0)

    ring = a.ring_average()

    def smooth(x):
        for _ in range(config.rings):
            x = ring @ x
        return x

    fl = config.floor
    cols = {
        "consistent": consistent,
        "consistent_smooth": smooth(consistent),
        "log_distortion_smooth": smooth(np.log(fl + mean)),
        "anchor_agreement": anchor_agreement,
        "log_anchor_error_smooth": smooth(np.log(fl + anchor_error)),
        "log_hope_shift_smooth": smooth(np.log(fl + hope_shift)),
        "log_zoomout_shift_smooth": smooth(np.log(fl + zoom_shift)),
        "log_stretch_smooth": smooth(np.log(fl + stretch)),
        "pair_consistent": np.full(n, consistent[among].mean() if among.any() else 0.0),
    }
    return np.column_stack([cols[name] for name in CONFIDENCE_FEATURES])


def predict_confidence(features: np.ndarray, config: ConfidenceConfig = ConfidenceConfig()):
    """The logistic model of ``config`` on ``features`` (n, n_features): (n,) in [0, 1]."""
    w = np.asarray(config.weights, dtype=np.float64)
    if w.size != features.shape[1]:
        raise ValueError(
            f"features must have one column per feature of ConfidenceConfig.weights "
            f"({', '.join(CONFIDENCE_FEATURES)}): {w.size}, got {features.shape[1]}"
        )
    z = features @ w + config.intercept
    return 1.0 / (1.0 + np.exp(-np.clip(z, -60.0, 60.0)))


def vertex_confidence(
    a: Shape, b: Shape, f: np.ndarray, features: np.ndarray, config: ConfidenceConfig
) -> np.ndarray:
    """The confidence stage's per-vertex confidence of ``f`` from its
    :func:`confidence_features`, (n_a,) in [0, 1]: :func:`predict_confidence` times
    :func:`turned_factor`; 0 everywhere when A or B has fewer than ``config.min_vertices``
    vertices (too small for any feature to tell a right map from a wrong one)."""
    if min(a.n_vertices, b.n_vertices) < config.min_vertices:
        return np.zeros(a.n_vertices)
    return predict_confidence(features, config) * turned_factor(a, b, f, config)


def turned_factor(a: Shape, b: Shape, f: np.ndarray, config: ConfidenceConfig) -> np.ndarray:
    """Per vertex of A, the factor in [0, 1] its confidence is multiplied by for the map
    ``f`` turning its surroundings over: ``1 - config.turned_weight * t``, ``t`` the turned-over
    share of its triangles' area (:meth:`TurnedFaces.vertex_shares`) averaged over
    ``config.rings`` 1-rings. A mirrored region keeps its distances, so the model's features
    score it high; its triangles land on B wound the other way."""
    if config.turned_weight == 0.0:
        return np.ones(a.n_vertices)
    t = TurnedFaces(a, b).vertex_shares(f)
    ring = a.ring_average()
    for _ in range(config.rings):
        t = ring @ t
    return np.clip(1.0 - config.turned_weight * t, 0.0, 1.0)


class ConfidenceStage(Stage):
    """The "confidence" stage: ``state.confidence`` from :func:`confidence_features` of the
    map (final but for the deformation pass), HOPE's and ZoomOut's (``state.zoomout``), by :func:`predict_confidence`; 0 on
    the vertices of a whole that the partial stage found without a counterpart on the part
    (``state.partial.counterpart``) and on vertices in no face."""

    name = "confidence"
    runs_on_final_map = True

    def skip_reason(self, state: MatchState):
        if not state.config.confidence.enabled:
            return "turned off (confidence=False)"
        if state.confidence is not None:
            # The "resolution" stage carries it over from the match at a common resolution.
            return "carried over from the match at a common resolution"
        return None

    def run(self, state: MatchState) -> None:
        cfg = state.config.confidence
        t = state.log.start("confidence", detail="per-vertex confidence of the map")
        counterpart = None if state.partial is None else state.partial.counterpart
        assert state.f is not None  # the stages before it made the map
        a, b = judged_shapes(state.a, state.b, cfg)
        x = confidence_features(
            a,
            b,
            state.f,
            state.hope_map,
            state.zoomout,
            cfg,
            min_consistent=state.config.refine.min_consistent,
            repair=state.config.refine.repair,
            among=counterpart,
        )
        state.confidence = vertex_confidence(a, b, state.f, x, cfg)
        if counterpart is not None:
            # A vertex of the whole without a counterpart on the part has no right match.
            state.confidence = np.where(counterpart, state.confidence, 0.0)
        # A vertex in no face has no surface around it to match by: its target is arbitrary.
        in_face = np.zeros(state.confidence.shape[0], dtype=bool)
        in_face[state.a.internal.faces.ravel()] = True
        state.confidence = np.where(in_face, state.confidence, 0.0)
        state.timings["confidence"] = time.perf_counter() - t
        share = float((state.confidence >= cfg.threshold).mean())
        state.log.ran(
            "confidence",
            state.timings["confidence"],
            f"{share:.0%} of the vertices at confidence >= {cfg.threshold}",
        )
