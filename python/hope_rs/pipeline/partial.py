"""Partial shapes: when one shape is a part of the other (a cut, holes, a partial scan).

Every distance of a match is measured in units of the shape's own sqrt(area): the SHOT radius,
LMD's 2-ring distances, the global repair's geodesics. A part's sqrt(area) is smaller than the
whole's, so on a part all of them would shrink (by 1/sqrt(0.5) for half a shape) and no
distance of the part would agree with its counterpart on the whole. The "partial" stage
detects a part by its boundary and measures it at the other shape's scale when that is the
larger (see :meth:`hope_rs.Shape.at_scale`); shapes of the same units then compare as they are.

A shape is a part when its boundary is longer than the other shape's by at least
``PartialConfig.min_boundary_excess`` and the other's is at most
``PartialConfig.max_whole_boundary`` (both in units of their own sqrt(area)); closed shapes,
pairs with boundaries of about the same length and pairs of two cut shapes are matched
exactly as before.

Which region of the whole a part's refinement settles on can change with a few percent of
its scale: with nothing on the part competing for the whole's missing side, a region of the
part can settle there. So a part is matched at the guessed scale and at the multiples
``PartialConfig.scale_trials`` of it, once more from the merge of those maps (each vertex
from the map of highest smoothed confidence there), when none of these maps reaches a mean
confidence of ``PartialConfig.wide_below`` also at the wider multiples
``PartialConfig.wide_trials``, and the map of highest mean confidence is kept (a wider
scale's only when it beats the others by ``PartialConfig.wide_margin``). These are rounds of
:func:`~hope_rs.pipeline.trials.run_trials`, recorded in ``res.stage("partial").trials``.

Matching a whole A to its part B asks every vertex of A for a partner, also where B has
none, and the refinement's overlaps then pull the vertices that do have one off their place.
So the stage matches B → A instead (a part to a whole, which works) and inverts that map:
each vertex of A takes the vertex of B whose image lies nearest to it, and has a counterpart
(``PartialInfo.counterpart``) when that image lies within ``PartialConfig.counterpart_edges``
mean edge lengths of it or it lies in a small gap among the images
(``PartialConfig.counterpart_gaps``) (``PartialConfig.whole_to_part="reverse"``). A given
map A → B starts that match inverted (:func:`invert_given_map`).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.mesh import boundary_edge_lengths
from ..geometry.roughness import umbrella_smoothed
from ..geometry.sites import nearest_members, owner_means
from ..shape import Shape
from .anchors import masked_components
from .config import MatchConfig, PartialConfig
from .landmarks import input_landmarks
from .part_info import PartialInfo
from .placement import placement_regions, region_start
from .resolution import density
from .state import QUIET, Halt, MatchState, Stage
from .trials import (
    Candidate,
    Trial,
    adopt,
    carried_confidence,
    mean_confidence,
    run_trial,
    run_trials,
)

__all__ = [
    "PartialInfo",
    "PartialStage",
    "boundary_length",
    "covered_share",
    "covering_rings",
    "detect_part",
    "invert_given_map",
    "invert_part_map",
    "mean_edge",
    "part_match_config",
    "part_scale",
]


def boundary_length(shape: Shape) -> float:
    """Total length of the edges of one face only, in units of the shape's own sqrt(area)."""
    _, lengths = boundary_edge_lengths(shape.internal.vertices, shape.internal.faces)
    return float(lengths.sum() / shape.internal.scale)


def mean_edge(shape: Shape) -> float:
    """Mean edge length of the shape's internal mesh (its own units)."""
    e, p = shape.edges, shape.points
    return float(np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1).mean())


def invert_part_map(
    a: Shape, g: np.ndarray, radius: float, gaps: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """From ``g``, a map of a part B into the whole A (internal numbering), the map A → B that
    sends each vertex of A to the vertex of B whose image is nearest (in space), and whether
    it has a counterpart on B: that image lies within ``radius`` (A's units) of it, or it lies
    in a connected patch of vertices without one holding fewer than ``gaps`` of A's vertices
    (a locally many-to-one map leaves such gaps among its images; the part's missing side
    and its holes are larger; any patch that small is taken, also one on a separate small
    piece of A)."""
    d, j = cKDTree(a.points[g]).query(a.points, workers=2)
    has = d <= radius
    if gaps > 0.0 and not has.all():
        label, size = masked_components(a.edges, a.n_vertices, ~has)
        has[~has] = size[label[~has]] < gaps * a.n_vertices
    return j.astype(np.int64), has


def invert_given_map(a: Shape, b: Shape, f: np.ndarray) -> np.ndarray:
    """From ``f``, a given map of the whole A onto its part B (internal numbering), a map
    B → A to start the part's match from. A vertex of B that one vertex of A is sent to takes
    it; one that several are sent to (a locally many-to-one map; the part's cut, where a map
    puts the whole's missing side) takes, of those, the one nearest (in space) the mean of what
    its neighbours sent to once took, or without such neighbours nearest their centroid
    (ties: the lowest vertex); any other vertex of B takes what the nearest vertex of B (in
    space) that ``f`` hits took."""
    f = np.asarray(f, dtype=np.int64)
    if f.size == 0:
        raise ValueError("a map of the whole onto its part needs at least one vertex")
    n_b = b.n_vertices
    count = np.bincount(f, minlength=n_b)
    once = count == 1
    pick = np.full(n_b, -1, dtype=np.int64)
    pick[f[once[f]]] = np.flatnonzero(once[f])
    # Where several vertices of A meet: the mean of the once-hit neighbours' picks on A.
    e = b.edges
    e = np.concatenate([e, e[:, ::-1]])
    e = e[(count[e[:, 0]] > 1) & once[e[:, 1]]]
    ref, has_ref = owner_means(a.points[pick[e[:, 1]]], e[:, 0], n_b)
    many = np.flatnonzero(count[f] > 1)  # vertices of A in a group of several
    centroid = owner_means(a.points[many], f[many], n_b)[0]
    ref = np.where(has_ref[:, None], ref, centroid)
    pick[np.unique(f[many])] = many[nearest_members(a.points[many], f[many], ref)]
    hit = count > 0
    if not hit.all():
        _, j = cKDTree(b.points[hit]).query(b.points[~hit], workers=2)
        pick[~hit] = pick[np.flatnonzero(hit)[j]]
    return pick


def covered_share(b: Shape, f: np.ndarray, rings: int = 1) -> float:
    """Share of B's area that the map ``f`` (into B, internal numbering) covers: the faces
    of B whose corners are all images of ``f`` or within ``rings`` rings of one (one ring
    closes the gaps that slightly differing vertex densities leave; on a B ``r`` times
    denser than A the images lie about ``sqrt(r)`` edges apart, and ``sqrt(r) / 2`` rings
    close the gaps)."""
    n = b.n_vertices
    grown = np.zeros(n, dtype=bool)
    grown[f] = True
    e = b.edges
    for _ in range(rings):
        hit = grown.copy()
        grown[e[hit[e[:, 0]], 1]] = True
        grown[e[hit[e[:, 1]], 0]] = True
    faces = b.internal.faces
    return float(b.internal.face_areas[grown[faces].all(axis=1)].sum() / b.internal.area)


def covering_rings(a: Shape, b: Shape) -> int:
    """The rings :func:`covered_share` grows the images of A's vertices by on B: the images on
    a B denser than A lie about sqrt(density ratio) edges apart, closed from both sides; at
    least one (:func:`~hope_rs.pipeline.resolution.density`)."""
    return max(1, int(np.ceil(np.sqrt(density(b) / density(a)) / 2)))


def part_scale(part: Shape, config: PartialConfig) -> float:
    """A shape's sqrt(area) for the guessed scale (the part's, and the whole's it is never
    larger than), in its units: its own, or, when its copy smoothed
    ``config.rough_smoothing`` times has a sqrt(area) smaller by a share more than
    ``config.inflated`` (vertex noise of about its edge length inflates a dense scan's
    area), the smoothed copy's."""
    if config.rough_smoothing == 0:
        return part.scale
    smoothed = umbrella_smoothed(part.internal, config.rough_smoothing)
    shrink = smoothed.scale / part.internal.scale
    return part.scale * shrink if shrink < 1.0 - config.inflated else part.scale


def detect_part(
    a: Shape,
    b: Shape,
    config: PartialConfig | None = None,
    *,
    lengths: tuple[float, float] | None = None,
) -> PartialInfo | None:
    """:class:`PartialInfo` when A or B is a part of the other (see the module notes), else
    ``None``; ``config`` defaults to ``PartialConfig()``, ``lengths`` (A's and B's
    :func:`boundary_length`, when the caller has them) are measured when not given."""
    config = PartialConfig() if config is None else config
    la, lb = (boundary_length(a), boundary_length(b)) if lengths is None else lengths
    # A part is never larger than its whole: when it is larger than the other shape already
    # (a smaller body), its own sqrt(area) is the better guess and it keeps it. Either one's
    # area may be a noisy scan's, inflated by its noise: both are measured without it. (The
    # whole keeps its own units: its noisy edge paths are as much longer as its sqrt(area).)
    # Two parts of one shape (both cut) are not a part and its whole: the whole-shape path.
    if la - lb >= config.min_boundary_excess and lb <= config.max_whole_boundary:
        return PartialInfo("a", (la, lb), max(part_scale(a, config), part_scale(b, config)))
    if lb - la >= config.min_boundary_excess and la <= config.max_whole_boundary:
        return PartialInfo("b", (la, lb), max(part_scale(a, config), part_scale(b, config)))
    return None


def both_open(la: float, lb: float, config: PartialConfig) -> str | None:
    """Why the stage leaves two open shapes alone, for the log, when neither could be a whole
    (both :func:`boundary_length` ``la``, ``lb`` above ``config.max_whole_boundary``); else
    ``None``. Two parts (two partial scans) are matched as wholes, each at its own scale:
    where they cover different regions of the surface, much of the map lands wrong."""
    if min(la, lb) <= config.max_whole_boundary:
        return None
    return (
        f"both shapes are open (boundaries A {la:.2f}, B {lb:.2f} sqrt(area)): matched as two "
        "wholes, each at its own scale; where they cover different regions much of the map "
        "can land wrong, so check res.quality"
    )


def part_match_config(cfg: MatchConfig) -> MatchConfig:
    """The settings of a part's own match at a given scale: this stage off (the part is
    already measured at the whole's scale), the deformation pass off (a part's spectrum is
    not the whole's), the landmarks' trust rule off (``LandmarkConfig.refine_trust``: a
    part's distances to its landmarks run around the missing region, so right matches read
    off and lose their witnesses; docs/decisions.md#landmarks) and, with
    ``PartialConfig.max_turned``, the refinement's witnesses limited to vertices not mostly
    turned over."""
    off = dataclasses.replace(
        cfg,
        partial=dataclasses.replace(cfg.partial, enabled=False),
        deform=dataclasses.replace(cfg.deform, enabled=False),
        landmarks=dataclasses.replace(cfg.landmarks, refine_trust=False),
    )
    if cfg.partial.max_turned is not None:
        off = dataclasses.replace(
            off, refine=dataclasses.replace(cfg.refine, max_turned=cfg.partial.max_turned)
        )
    return off


class PartialStage(Stage):
    """The "partial" stage: when one shape is a part of the other, both are measured at the
    whole's scale from here on (``state.a``/``state.b`` become :meth:`~hope_rs.Shape.at_scale`
    views) and ``state.partial`` says which is the part. Not recorded when neither is."""

    name = "partial"
    runs_on_final_map = False

    def __init__(self):
        self.info: PartialInfo | None = None

    def skip_reason(self, state: MatchState):
        cfg = state.config.partial
        if not cfg.enabled:
            return QUIET
        lengths = boundary_length(state.a), boundary_length(state.b)
        self.info = detect_part(state.a, state.b, cfg, lengths=lengths)
        if self.info is not None:
            return None
        return both_open(*lengths, cfg) or QUIET

    def run(self, state: MatchState) -> Halt | None:
        info = self.info
        assert info is not None
        cfg = state.config.partial
        la, lb = info.boundary
        detail = f"{info.part.upper()} is a part (boundaries A {la:.2f}, B {lb:.2f} sqrt(area))"
        reverse = info.part == "b" and cfg.whole_to_part == "reverse"
        detail += ": matched B -> A and inverted" if reverse else ": matched at the whole's scale"
        t = state.log.start("partial", detail=detail)
        halt = None
        if info.part == "a":
            info = dataclasses.replace(info, counterpart=np.ones(state.a.n_vertices, dtype=bool))
            info = self._rescale_part(state, info)
            halt = Halt("the map is the part's match at the whole's scale")
        elif reverse:
            # The nested match detects B as the part of its pair and scales it itself; a given
            # map of A onto B starts it inverted (in the input numbering, as a caller's map).
            nested: dict = {}
            init = state.init
            start = (
                init
                if isinstance(init, str)
                else state.b.map_out(state.a, invert_given_map(state.a, state.b, init))
            )
            assert state.run is not None  # the runner sets it
            back = state.run(
                state.b,
                state.a,
                start,
                state.config,
                callback=state.callback,  # its steps are this match's
                progress=state.log.relay("partial").labelled("B -> A"),
                landmarks=input_landmarks(state, swap=True),
                on_stage=lambda st, name: nested.update(partial=st.partial),
            )
            radius = cfg.counterpart_edges * mean_edge(state.a)
            f, has = invert_part_map(
                state.a, state.b.map_in(state.a, back.map), radius, cfg.counterpart_gaps
            )
            # The initial map is the caller's, or the nested match's inverted alike.
            f0 = (
                invert_part_map(state.a, state.b.map_in(state.a, back.init_map), radius)[0]
                if isinstance(init, str)
                else np.asarray(init, dtype=np.int64)
            )
            # The scale the nested match measured the part at (it may have rescaled it).
            part = nested.get("partial")
            scale = part.scale if part is not None and part.part == "a" else info.scale
            info = dataclasses.replace(info, counterpart=has, scale=scale)
            assert back.hope_map is not None  # run_match always sets it
            hope, _ = invert_part_map(state.a, state.b.map_in(state.a, back.hope_map), radius)
            state.f0, state.f, state.hope_map = f0, f, hope
            state.history = back.history
            # The stages after this one (the confidence) measure the part at that scale too.
            if scale != state.b.scale:
                state.b = state.b.at_scale(scale)
            state.timings.update({k: v for k, v in back.timings.items() if k != "total"})
            halt = Halt("the map is the inverse of the match of the part B to the whole A")
        elif info.scale != state.b.scale:
            state.b = state.b.at_scale(info.scale)
        state.partial = info
        state.timings["partial"] = time.perf_counter() - t
        if info.part == "a":
            detail += f" ({info.scale / state.a.internal.scale:.3f} x its own sqrt(area))"
        state.log.ran("partial", state.timings["partial"], detail)
        return halt

    @staticmethod
    def _rescale_part(state: MatchState, info: PartialInfo) -> PartialInfo:
        """A (the part) matched at the guessed scale and, when the share of B its map covers
        puts A's whole at a scale off by more than ``rescale_tolerance``, again at that scale.
        With ``scale_trials`` also at those multiples of the guessed scale, once more from
        the merge of these maps (:func:`_merge_candidate`) and, when none reaches
        ``wide_below``, at the multiples ``wide_trials``; the map of highest mean confidence
        wins (a wider scale's by at least ``wide_margin``). Without, of the two maps the one
        whose vertices' descriptors (at the second scale) lie nearer their images' wins: a
        left-right mirror keeps every distance, so only the descriptors, which see
        orientation, tell it from the true map. Sets the map."""
        cfg = state.config
        a, b = state.a, state.b
        trials = cfg.partial.scale_trials
        off = part_match_config(cfg)
        if trials:
            # The trials are compared by their confidence (the map does not depend on it).
            off = dataclasses.replace(
                off, confidence=dataclasses.replace(off.confidence, enabled=True)
            )
        # The nested runs take a given initial map in the input numbering.
        init = state.init if isinstance(state.init, str) else a.map_out(b, state.init)
        guess = a.at_scale(info.scale) if info.scale != a.scale else a
        landmarks = input_landmarks(state)

        def at(view: Shape, label: str) -> Candidate:
            """The part's match at ``view``'s scale."""
            return Candidate(label, view, b, init, off, landmarks)

        def times(t: float) -> str:
            return f"x{t:.3g}"

        # The kept trial's steps become the match's history: the caller's callback sees the
        # steps of every trial, and progress every trial's events.
        relay, callback = state.log.relay("partial"), state.callback
        first = run_trial(state, "partial", at(guess, times(1.0)), relay, callback=callback)
        share = covered_share(b, guess.map_in(b, first.result.map), covering_rings(guess, b))
        scale = a.internal.scale / np.sqrt(max(share, cfg.partial.min_covered))
        kept = first
        rescale = abs(scale / info.scale - 1.0) > cfg.partial.rescale_tolerance
        if trials:
            near = [at(a.at_scale(info.scale * t), times(t)) for t in trials]
            if rescale:
                near.append(at(a.at_scale(scale), f"covered {times(scale / info.scale)}"))
            nearby = run_trials(
                state,
                "partial",
                near,
                mean_confidence,
                against=first,
                progress=relay,
                callback=callback,
            )
            merge = _merge_candidate(state, [first, *nearby.tried], nearby.kept, cfg.partial)
            kept = run_trials(
                state,
                "partial",
                [merge],
                mean_confidence,
                against=nearby.kept,
                progress=relay,
                callback=callback,
            ).kept
            top, margin = kept.score, cfg.partial.wide_margin
            assert top is not None  # run_trials scores the trial it keeps
            # A confidence is at most 1: beyond that no wider map could win.
            if cfg.partial.wide_trials and top < cfg.partial.wide_below and top + margin <= 1.0:
                # The wider scales' maps are not merged (where they went wrong they would pull
                # the merge off the nearby scales' map), and one replaces the choice only when
                # clearly more confident: they lie farther from the guessed scale.
                wide = [at(a.at_scale(info.scale * t), times(t)) for t in cfg.partial.wide_trials]
                kept = run_trials(
                    state,
                    "partial",
                    wide,
                    mean_confidence,
                    against=kept,
                    margin=margin,
                    progress=relay,
                    callback=callback,
                ).kept
            quality = kept.result.quality
            doubtful = (quality is not None and quality.likely_failed) or (
                kept.score is not None and kept.score < cfg.partial.placement_below
            )
            # A given start or landmarks place the part: only a descriptor start is moved.
            placed_by_descriptors = isinstance(state.init, str) and landmarks is None
            if cfg.partial.placement_trials and doubtful and placed_by_descriptors:
                # Another region of the whole, not another scale, may be the part's
                # counterpart: start the kept scale's match from each of several regions.
                view = kept.candidate.a
                share = cfg.partial.placement_share * (a.internal.scale / view.scale) ** 2
                kind = str(state.init)
                placed = [
                    dataclasses.replace(
                        kept.candidate,
                        label=f"region {i}",
                        init=view.map_out(
                            b, region_start(view, b, region, kind, cfg.initial.search)
                        ),
                    )
                    for i, region in enumerate(
                        placement_regions(b, share, cfg.partial.placement_trials)
                    )
                ]
                kept = run_trials(
                    state,
                    "partial",
                    placed,
                    mean_confidence,
                    against=kept,
                    margin=cfg.partial.placement_margin,
                    progress=relay,
                    callback=callback,
                ).kept
            info = dataclasses.replace(info, scale=float(kept.candidate.a.scale))
        elif rescale:
            again = a.at_scale(scale)
            kind = state.init if isinstance(state.init, str) else "shot"
            da, db = again.internal_descriptors(kind), b.internal_descriptors(kind)

            def nearer(t: Trial) -> float:
                """Minus the mean distance of the descriptors (at the second scale) of A's
                vertices to their images'."""
                g = again.map_in(b, t.result.map)
                return -float(np.linalg.norm(da - db[g], axis=1).mean())

            second = at(again, f"covered {times(scale / info.scale)}")
            kept = run_trials(
                state,
                "partial",
                [second],
                nearer,
                against=first,
                margin=0.0,
                progress=relay,
                callback=callback,
            ).kept
            if kept is not first:
                info = dataclasses.replace(info, scale=float(scale))
        # The stages of the kept nested match count as seconds within "partial".
        adopt(state, kept)
        state.confidence = carried_confidence(state, kept)
        return info


def _confidence(t: Trial) -> np.ndarray:
    conf = t.result.confidence
    assert conf is not None  # the trials run with the confidence on
    return conf


def _merge_candidate(state: MatchState, runs: list[Trial], best: Trial, cfg) -> Candidate:
    """The part's match from the merge of the maps of ``runs`` (trials of one part at
    several scales): each vertex takes its image from the map whose confidence, averaged
    over ``cfg.merge_rings`` rounds of 1-ring averaging, is highest there; matched at the
    scale of ``best``, the run of highest mean confidence."""
    a, b = state.a, state.b
    maps = np.stack([t.candidate.a.map_in(b, t.result.map) for t in runs])  # internal numbering
    conf = np.stack([_confidence(t)[a.order] for t in runs], axis=1)
    p = a.ring_average()
    for _ in range(cfg.merge_rings):
        conf = p @ conf
    merged = maps[np.argmax(conf, axis=1), np.arange(a.n_vertices)]
    return dataclasses.replace(best.candidate, label="merge", init=a.map_out(b, merged))
