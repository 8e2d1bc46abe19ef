"""Repairing a map that turns a shape over: the "orient" stage.

Both shapes are oriented outward before matching, so a right map keeps the winding of A's
triangles on B (:mod:`hope_rs.pipeline.turned`). A map that carries a region onto its mirror
image (a left leg onto the right one, a whole body onto its mirror image) keeps every geodesic
distance, so the refinement and LMD cannot see it, but it turns that region's triangles over.
When the final map turns more than ``OrientConfig.min_turned`` of A's area over, this stage
builds alternative maps (hypotheses), refines them through the rest of the pipeline and keeps
whichever of them and the map it started from scores best (:func:`map_cost`: turned-over
share plus LMD inconsistency).

The hypotheses (``OrientConfig.hypotheses``):

* ``"mirror"``: the map composed with B's intrinsic left/right symmetry, everywhere;
* ``"mirror_turned"``: the same, on the turned-over regions only;
* ``"reseed"``: the turned-over vertices placed by their geodesic distances to anchors in the
  orientation-keeping rest (:func:`~hope_rs.pipeline.anchors.anchor_step`);
* ``"wks"``: the pipeline from the WKS initial map instead (a swapped pair of limbs, which
  the others keep);
* ``"reverse"``: the pipeline from the match of B to A, inverted.

The derived hypotheses are unrefined maps; the one turning the least over is refined. The
stage stops at the first refined map that turns at most ``min_turned`` over and costs less.

B's symmetry is the match of B's mirror image (coordinates reflected in a plane through its
centroid) to B itself: vertex ``i`` of the mirror image is vertex ``i`` of B reflected, so the
orientation-keeping match of the two sends each vertex to its mirror partner.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.mesh import Mesh, boundary_edges
from ..shape import Shape
from .anchors import anchor_step, firm_regions
from .lmd import local_map_distortion
from .progress import ProgressEvent
from .state import QUIET, MatchState, Stage
from .turned import TurnedFaces

__all__ = [
    "OrientStage",
    "map_cost",
    "mirror_image",
    "reverse_map",
    "symmetry_map",
    "turned_regions",
]


def mirror_image(s: Shape) -> Shape:
    """``s``'s mesh reflected through the plane x = mean x (input numbering kept; the shape
    orients its faces outward again)."""
    v = s.mesh.vertices.copy()
    v[:, 0] = 2.0 * v[:, 0].mean() - v[:, 0]
    return Shape(Mesh(v, s.mesh.faces[:, ::-1]), k_max=s.k_max, config=s.config)


def symmetry_map(state: MatchState, b: Shape) -> np.ndarray:
    """B's intrinsic left/right symmetry, (n_b,) in B's internal numbering: the match of its
    mirror image to B (:func:`mirror_image`) by the runner, without this stage, the spectral
    pass and the finish."""
    mirror = mirror_image(b)
    # One triangulation on both sides: the refinement alone finds the map (as on FAUST
    # registrations); the spectral pass and the shared-face finish are not needed.
    cfg = _nested_config(state)
    cfg = dataclasses.replace(
        cfg,
        spectral=dataclasses.replace(cfg.spectral, enabled=False),
        finish=dataclasses.replace(cfg.finish, enabled=False),
    )
    assert state.run is not None  # the runner gives every state its nested runner
    res = state.run(mirror, b, state.config.initial.descriptor, cfg, progress=_Relay(state))
    # res.map is in input numbering: input vertex v of the mirror image is input vertex v of B.
    return b.rank[np.asarray(res.map)[b.order]]


def reverse_map(state: MatchState) -> np.ndarray:
    """The match of B to A by the runner (without this stage), inverted: each vertex of A
    onto the vertex of B whose image lies nearest it in space (internal numbering)."""
    a, b = state.a, state.b
    assert state.run is not None  # the runner gives every state its nested runner
    res = state.run(
        b,
        a,
        state.config.initial.descriptor,
        _nested_config(state),
        progress=_Relay(state),
    )
    g = b.map_in(a, res.map)
    return cKDTree(a.points[g]).query(a.points)[1].astype(np.int64)


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


class _Relay:
    """A nested match's progress as steps of the "orient" stage (logged under its prefix);
    its refinement steps are not the outer match's, so their iterations are not passed on."""

    def __init__(self, state: MatchState):
        self._relay = state.log.relay("orient")
        self.log_prefix = self._relay.log_prefix

    def __call__(self, ev: ProgressEvent) -> None:
        self._relay(dataclasses.replace(ev, iteration=None))


def _nested_config(state: MatchState):
    """The settings of a nested match: this stage and the confidence off."""
    cfg = state.config
    return dataclasses.replace(
        cfg,
        orient=dataclasses.replace(cfg.orient, enabled=False),
        confidence=dataclasses.replace(cfg.confidence, enabled=False),
    )


def _derived(state: MatchState, f: np.ndarray, tf: TurnedFaces, sym: np.ndarray | None) -> dict:
    """The unrefined maps derived from ``f`` (internal numbering) by the derived hypotheses
    of ``OrientConfig.hypotheses`` ("mirror", "mirror_turned", "reseed")."""
    cfg = state.config.orient
    a, b = state.a, state.b
    region = turned_regions(a, tf.vertices(f, 0.5), cfg.seam_rings)
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


class _Trials:
    """The maps tried by the stage, refined through the rest of the pipeline and scored."""

    def __init__(self, state: MatchState, tf: TurnedFaces):
        self.state, self.tf = state, tf
        self.cfg = state.config.orient
        self.sym: np.ndarray | None = None
        f = state.f
        assert f is not None  # the stage runs on a final map
        #: name -> (turned share, cost, nested state or None for the stage's own map)
        self.scored: dict = {"kept": (tf.share(f), self.cost(f), None)}
        self.notes: list[str] = []
        #: Seconds per nested match (B's symmetry, each refined hypothesis).
        self.seconds: dict[str, float] = {}

    def cost(self, f: np.ndarray) -> float:
        return map_cost(self.state.a, self.state.b, f, self.tf, self.cfg.distortion_weight)

    def run(self, name: str, init) -> np.ndarray:
        """The pipeline from ``init`` (a descriptor kind or a map, internal numbering), scored
        as ``name``; returns its map."""
        state, a, b = self.state, self.state.a, self.state.b
        nested: dict = {}

        def grab(s, stage_name):
            if stage_name == "faces":
                nested["state"] = s

        t = time.perf_counter()
        if not isinstance(init, str):
            init = a.map_out(b, init)
        assert state.run is not None  # the runner gives every state its nested runner
        state.run(a, b, init, _nested_config(state), on_stage=grab, progress=_Relay(state))
        g = nested["state"]
        self.scored[name] = (self.tf.share(g.f), self.cost(g.f), g)
        self.seconds[name] = time.perf_counter() - t
        return g.f

    def derive(self, base: str, f: np.ndarray) -> None:
        """Refines the least turned-over of the maps derived from ``f`` when it turns less
        over than ``f`` does."""
        if self.sym is None and any(h.startswith("mirror") for h in self.cfg.hypotheses):
            t = time.perf_counter()
            self.sym = symmetry_map(self.state, self.state.b)
            self.seconds["symmetry"] = time.perf_counter() - t
        raw = _derived(self.state, f, self.tf, self.sym)
        if not raw:
            return
        shares = {k: self.tf.share(g) for k, g in raw.items()}
        self.notes.append(
            f"from {base} unrefined " + ", ".join(f"{k} {v:.0%}" for k, v in shares.items())
        )
        best = min(shares, key=lambda k: shares[k])
        if shares[best] < self.scored[base][0]:
            self.run(best if base == "kept" else f"{base}+{best}", raw[best])

    def good_enough(self) -> bool:
        """Whether a tried map turns at most ``min_turned`` over and beats the stage's own."""
        kept = self.scored["kept"][1]
        return any(
            v[0] <= self.cfg.min_turned and v[1] < kept - self.cfg.min_gain
            for k, v in self.scored.items()
            if k != "kept"
        )

    def best(self) -> str:
        name = min(self.scored, key=lambda k: self.scored[k][1])
        if name != "kept" and self.scored[name][1] >= self.scored["kept"][1] - self.cfg.min_gain:
            return "kept"
        return name


class OrientStage(Stage):
    """The "orient" stage (see the module notes); runs when the map turns more than
    ``OrientConfig.min_turned`` of A's area over, on whole closed shapes without landmarks."""

    name = "orient"
    #: A map another stage found final can still be a mirror image (LMD trusts it everywhere).
    runs_on_final_map = True

    def attach(self, state: MatchState) -> None:
        #: The turned-over triangles of A on B, built when the stage decides whether to run.
        self._turned: TurnedFaces | None = None

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
        if any(boundary_edges(s.internal.faces).size for s in (state.a, state.b)):
            # Which side of an open surface is outward is a guess (see turned.py), and the
            # partial stage's nested matches of a part are open.
            return "an open surface"
        t = time.perf_counter()
        self._turned = TurnedFaces(state.a, state.b)
        share = self._turned.share(state.f)
        state.timings["orient"] = time.perf_counter() - t
        if share <= cfg.min_turned:
            return f"{share:.0%} of A's area turned over (at most {cfg.min_turned:.0%})"
        return None

    def run(self, state: MatchState) -> None:
        cfg = state.config.orient
        t = time.perf_counter()
        tf, f = self._turned, state.f
        assert tf is not None and f is not None  # skip_reason measured the final map
        share = tf.share(f)
        state.log.start("orient", detail=f"{share:.0%} of A turned over: trying other maps")
        trials = _Trials(state, tf)
        # The maps derived from the stage's own first; then other starts (a swapped pair of
        # limbs comes back neither mirrored nor re-seeded).
        trials.derive("kept", f)
        if not trials.good_enough() and "wks" in cfg.hypotheses:
            trials.run("wks", "wks")
        if not trials.good_enough() and "reverse" in cfg.hypotheses:
            t_rev = time.perf_counter()
            g = reverse_map(state)
            trials.seconds["reverse B to A"] = time.perf_counter() - t_rev
            trials.run("reverse", g)
        chosen = trials.best()
        if chosen != "kept":
            g = trials.scored[chosen][2]
            state.f, state.hope_map, state.zoomout = g.f, g.hope_map, g.zoomout
        state.timings["orient"] += time.perf_counter() - t
        tried = "; ".join(
            f"{k}: {v[0]:.0%} turned, cost {v[1]:.3f}" for k, v in trials.scored.items()
        )
        spent = ", ".join(f"{k} {v:.1f} s" for k, v in trials.seconds.items())
        state.log.ran(
            "orient",
            state.timings["orient"],
            f"{'; '.join(trials.notes)}; {tried}; chose {chosen} ({spent})",
        )
