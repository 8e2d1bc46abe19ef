"""Repairing a map that turns a shape over: the "orient" stage.

Both shapes are oriented outward before matching, so a right map keeps the winding of A's
triangles on B (:mod:`hope_rs.pipeline.turned`). A map that carries a region onto its mirror
image (a left leg onto the right one, a whole body onto its mirror image) keeps every geodesic
distance, so the refinement and LMD cannot see it, but it turns that region's triangles over.
When the final map turns more than ``OrientConfig.min_turned`` of A's area over, this stage
builds alternative maps (hypotheses), refines the most promising one through the rest of the
pipeline and keeps whichever of it and the map it started from scores better
(:func:`map_cost`: turned-over share plus LMD inconsistency).

The hypotheses (``OrientConfig.hypotheses``):

* ``"mirror"``: the map composed with B's intrinsic left/right symmetry, everywhere;
* ``"mirror_turned"``: the same, on the turned-over regions only;
* ``"reseed"``: the turned-over vertices placed by their geodesic distances to anchors in the
  orientation-keeping rest (:func:`~hope_rs.pipeline.anchors.anchor_step`).

B's symmetry is the match of B's mirror image (coordinates reflected in a plane through its
centroid) to B itself: vertex ``i`` of the mirror image is vertex ``i`` of B reflected, so the
orientation-keeping match of the two sends each vertex to its mirror partner.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..geometry.mesh import Mesh
from ..shape import Shape
from .anchors import anchor_step, firm_regions
from .lmd import local_map_distortion
from .state import QUIET, MatchState, Stage
from .turned import TurnedFaces

__all__ = ["OrientStage", "map_cost", "mirror_image", "symmetry_map", "turned_regions"]


def mirror_image(s: Shape) -> Shape:
    """``s``'s mesh reflected through the plane x = mean x (input numbering kept; the shape
    orients its faces outward again)."""
    v = s.mesh.vertices.copy()
    v[:, 0] = 2.0 * v[:, 0].mean() - v[:, 0]
    return Shape(Mesh(v, s.mesh.faces[:, ::-1]), k_max=s.k_max, config=s.config)


def symmetry_map(state: MatchState, b: Shape) -> np.ndarray:
    """B's intrinsic left/right symmetry, (n_b,) in B's internal numbering: the match of its
    mirror image to B (:func:`mirror_image`) by the runner, without this stage."""
    mirror = mirror_image(b)
    res = state.run(mirror, b, state.config.initial.descriptor, _nested_config(state))
    # res.map is in input numbering: input vertex v of the mirror image is input vertex v of B.
    return b.rank[np.asarray(res.map)[b.order]]


def turned_regions(a: Shape, turned: np.ndarray, rings: int) -> np.ndarray:
    """``turned`` (bool per vertex of A) grown by ``rings`` 1-rings: a turned region's seam
    turns over only in part."""
    e = a.edges
    out = turned.copy()
    for _ in range(rings):
        grow = out.copy()
        grow[e[out[e[:, 0]], 1]] = True
        grow[e[out[e[:, 1]], 0]] = True
        out = grow
    return out


def map_cost(a: Shape, b: Shape, f: np.ndarray, turned: TurnedFaces, weight: float) -> float:
    """What the stage minimises: the share of A's area ``f`` turns over plus ``weight`` times
    the share of A's vertices whose 2-ring LMD finds inconsistent (a right map keeps both
    low; a mirror image keeps distances but turns over, a scrambled map does neither)."""
    _, consistent = local_map_distortion(a, b, f)
    return float(turned.share(f)) + weight * float(1.0 - np.mean(consistent))


def _nested_config(state: MatchState):
    """The settings of a nested match: this stage and the confidence off."""
    cfg = state.config
    return dataclasses.replace(
        cfg,
        orient=dataclasses.replace(cfg.orient, enabled=False),
        confidence=dataclasses.replace(cfg.confidence, enabled=False),
    )


def _hypotheses(state: MatchState, tf: TurnedFaces, sym: np.ndarray | None) -> dict:
    """The candidate maps (internal numbering) of ``OrientConfig.hypotheses``, unrefined."""
    cfg = state.config.orient
    a, b, f = state.a, state.b, state.f
    turned = tf.vertices(f, 0.5)
    region = turned_regions(a, turned, cfg.seam_rings)
    out = {}
    for name in cfg.hypotheses:
        if name == "mirror" and sym is not None:
            out[name] = sym[f]
        elif name == "mirror_turned" and sym is not None:
            out[name] = np.where(region, sym[f], f)
        elif name == "reseed":
            # The largest orientation-keeping region holds the anchors.
            label, sizes = firm_regions(a, ~region)
            if sizes.size and sizes.max() >= 4:
                core = label == int(np.argmax(sizes))
                out[name] = anchor_step(a, b, f, core, config=state.config.refine.repair)
    return out


class OrientStage(Stage):
    """The "orient" stage (see the module notes); runs when the map turns more than
    ``OrientConfig.min_turned`` of A's area over, on whole shapes without landmarks."""

    name = "orient"

    def skip_reason(self, state: MatchState):
        cfg = state.config.orient
        if not cfg.enabled:
            return QUIET
        if state.landmarks is not None:
            return "landmarks given"
        if state.partial is not None:
            return "a part: its orientation is the partial stage's"
        if state.f is None or state.run is None:
            return "no map"
        return None

    def run(self, state: MatchState) -> None:
        cfg = state.config.orient
        t = time.perf_counter()
        a, b = state.a, state.b
        tf = TurnedFaces(a, b)
        share = tf.share(state.f)
        if share <= cfg.min_turned:
            state.timings["orient"] = time.perf_counter() - t
            state.log.ran("orient", state.timings["orient"], f"{share:.0%} turned over: kept")
            return
        state.log.start("orient", detail=f"{share:.0%} of A turned over: trying other maps")
        needs_sym = any(h.startswith("mirror") for h in cfg.hypotheses)
        sym = symmetry_map(state, b) if needs_sym else None
        raw = _hypotheses(state, tf, sym)
        # The unrefined hypotheses are ranked by turned-over share alone (distortion is the
        # refinement's to fix); the best is refined through the rest of the pipeline.
        tried = {"kept": (share, map_cost(a, b, state.f, tf, cfg.distortion_weight))}
        shares = {name: tf.share(g) for name, g in raw.items()}
        chosen = "kept"
        if shares:
            best = min(shares, key=lambda k: shares[k])
            nested: dict = {}

            def grab(s, stage_name):
                if stage_name == "faces":
                    nested["state"] = s

            state.run(a, b, a.map_out(b, raw[best]), _nested_config(state), on_stage=grab)
            g = nested["state"]
            cost = map_cost(a, b, g.f, tf, cfg.distortion_weight)
            tried[best] = (tf.share(g.f), cost)
            if cost < tried["kept"][1] - cfg.min_gain:
                chosen = best
                state.f, state.hope_map, state.zoomout = g.f, g.hope_map, g.zoomout
        state.timings["orient"] = time.perf_counter() - t
        detail = "; ".join(f"{k}: {v[0]:.0%} turned, cost {v[1]:.3f}" for k, v in tried.items())
        raw_detail = ", ".join(f"{k} {v:.0%}" for k, v in shares.items())
        state.log.ran(
            "orient",
            state.timings["orient"],
            f"unrefined {raw_detail or 'none'}; {detail}; chose {chosen}",
        )
