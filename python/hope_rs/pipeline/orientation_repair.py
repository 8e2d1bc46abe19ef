"""Repairing a map that turns a shape over: the "orient" stage.

Both shapes are oriented outward before matching, so a right map keeps the winding of A's
triangles on B (:mod:`hope_rs.pipeline.turned`). A map that carries a region onto its mirror
image (a left leg onto the right one, a whole body onto its mirror image) keeps every geodesic
distance, so the refinement and LMD cannot see it, but it turns that region's triangles over.
When the final map turns more than ``OrientConfig.min_turned`` of A's area over, or turns
less over but the confidence's rule flags it (``OrientConfig.on_failed``,
:func:`~hope_rs.pipeline.confidence.map_quality`), or the two shapes differ in topology
(``OrientConfig.on_topology``: a topological shortcut leads the k-hop balls and geodesic
distances across it, and the map can put a region near it on the wrong side), or the map tears
a region off the rest (``OrientConfig.on_torn``, :mod:`hope_rs.pipeline.torn`: a region
carried to the wrong place with its orientation and 2-rings kept; the one trigger for a part A
matched to a whole, whose refined hypotheses are matched at the partial stage's scale with its
settings), this stage builds
alternative maps (hypotheses), refines them through the rest of the pipeline and keeps
whichever of them and the map it started from scores best (:func:`map_cost`: turned-over
share plus LMD inconsistency plus the share torn off). Each refined hypothesis is a trial of
:mod:`hope_rs.pipeline.trials` (recorded in ``res.stage("orient").trials`` with minus its
cost as score, the kept one marked); the kept one becomes the state's map.

The hypotheses (``OrientConfig.hypotheses``; ``torn_hypotheses`` and ``topology_hypotheses``
when only a torn-off region or the topology calls for the stage):

* ``"mirror"``: the map composed with B's intrinsic left/right symmetry, everywhere;
* ``"mirror_turned"``: the same, on the turned-over regions only;
* ``"reseed"``: the turned-over vertices placed by their geodesic distances to anchors in the
  orientation-keeping rest (:func:`~hope_rs.pipeline.anchors.anchor_step`);
* ``"torn"``: the vertices off the map's core (in each mesh component, the largest piece it
  keeps in one, see :mod:`hope_rs.pipeline.torn`) placed by their geodesic distances to
  anchors in that core (:func:`~hope_rs.pipeline.torn.replaced`);
* ``"wks"``: the pipeline from the WKS initial map instead (a swapped pair of limbs, which
  the others keep);
* ``"reverse"``: the pipeline from the match of B to A, inverted;
* ``"reverse_wks"``: the same with B to A matched from the WKS initial map (a human to a
  gorilla, whose SHOT and WKS starts both fail in that direction, while WKS from the gorilla
  keeps the orientation); kept only when it passes the stop rule below, never derived from.

The derived hypotheses are unrefined maps; of "mirror", "mirror_turned" and "reseed" the one
turning the least over is refined, and "torn" is refined when the map tears a region off. The
other starts follow in the order of the hypotheses tried (a start the stage's own match
used is not tried again); after each, while no refined map passes the stop rule, the maps
derived from that start's refined map (if it beats the stage's own, or turns more than
``OrientConfig.again_turned`` of A over: a whole mirror image) are tried too
(``OrientConfig.again``). When the map turns more than ``min_turned`` over or is flagged,
between shapes far from isometric (their spectra, from this match's spectral pass, differ by
more than ``OrientConfig.starts_first_mismatch``), the first other start comes before the
maps derived from the stage's own, which follow only if no map tried so far passes the stop
rule. The stop rule: the stage stops at the first refined map that turns at most
``min_turned`` over, costs at least ``min_gain`` less than the stage's own and
(``on_failed``) is not flagged by the confidence's rule.

After a lift from a common resolution (:mod:`hope_rs.pipeline.resolution`) every refined
hypothesis is matched at that resolution too, from its map carried to the copy, and carries
that match's confidence, on which the confidence's rule judges it and which the kept map
keeps (with the confidence turned off, the rule judges no map of a dense A). For a dense A
the LMD term of the cost and the turned regions the derived maps change are measured on the
copy of A the stage's map was made at (``state.common_a``, the same copy for every
hypothesis), and so is the turned-over share when A is rough at its own resolution (a noisy
scan): at full resolution a right many-to-one map keeps few 2-rings' distances and its turned
triangles scatter, on a noisy scan at random.

B's symmetry is the match of B's mirror image (coordinates reflected in a plane through its
centroid) to B itself: vertex ``i`` of the mirror image is vertex ``i`` of B reflected, so the
orientation-keeping match of the two sends each vertex to its mirror partner. The identity
(vertex ``i`` onto vertex ``i``) keeps every distance too, and from the midline, where the
two agree, it can take over a whole side of a posed body, which it turns over; such regions
are placed again by their geodesic distances to anchors in the rest, and the match repeated
(``OrientConfig.symmetry_rounds``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.mesh import Mesh
from ..shape import Shape
from .anchors import anchor_step, firm_regions
from .confidence import map_quality, match_quality
from .config import DeformConfig, RepairConfig
from .deform import spectral_mismatch
from .lmd import local_map_distortion
from .partial import part_match_config
from .progress import ProgressEvent
from .state import QUIET, MatchState, Stage
from .torn import TornRegions, replaced
from .trials import (
    Candidate,
    Trial,
    adopt,
    carried_confidence,
    choose,
    current,
    run_trial,
    run_trials,
)
from .turned import OPEN_BOUNDARY, TurnedFaces, is_open

__all__ = [
    "PART_HYPOTHESES",
    "OrientStage",
    "map_cost",
    "mirror_image",
    "reseeded",
    "turned_regions",
]


#: How many of the shapes' first non-zero eigenvalues ``OrientConfig.starts_first_mismatch``
#: compares: as many as the deform stage's gate does by default.
_MISMATCH_EIGENVALUES = DeformConfig.n_eigenvalues

#: The hypotheses tried on a part A (of ``OrientConfig.torn_hypotheses``): B's symmetry and
#: the reverse match are whole-shape matches, which the part's settings do not make.
PART_HYPOTHESES = ("torn", "reseed", "wks")


def mirror_image(s: Shape) -> Shape:
    """``s``'s mesh reflected through the plane x = mean x (input numbering kept; the shape
    orients its faces outward again), at ``s``'s scale (a reflection keeps the area)."""
    v = s.mesh.vertices.copy()
    v[:, 0] = 2.0 * v[:, 0].mean() - v[:, 0]
    return s.derived(Mesh(v, s.mesh.faces[:, ::-1]), orient=True)


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


def reseeded(
    a: Shape, b: Shape, f: np.ndarray, region: np.ndarray, repair: RepairConfig
) -> np.ndarray | None:
    """``f`` (internal numbering) with the vertices of ``region`` (bool per vertex of A, a
    map's turned-over regions) placed by their geodesic distances to anchors in the largest
    connected region outside it (:func:`~hope_rs.pipeline.anchors.anchor_step`); None when
    that region has fewer than 4 vertices."""
    label, sizes = firm_regions(a, ~region)
    if not sizes.size or sizes.max() < 4:
        return None
    return anchor_step(a, b, f, label == int(np.argmax(sizes)), config=repair)


class _Judge:
    """How the stage judges a map of A: the share of A's area it turns over and the LMD
    inconsistency on A. For a dense A matched at a common resolution the LMD is measured on
    the copy the stage's map was made at (``state.common_a``, the same for every
    hypothesis), its vertices read off the map, and so are the turned regions the derived
    maps change (:meth:`turned`, each vertex of A taking its copy vertex's): at full
    resolution a right many-to-one map keeps few 2-rings' distances and lands most small
    triangles degenerate. So is the turned share when A is rough at its own resolution
    (``CommonView.rough``, :func:`~hope_rs.pipeline.confidence.flipped_share`). The share
    torn off (:attr:`torn`), the cost's third term, is measured on A at full resolution."""

    def __init__(self, state: MatchState):
        self.b = state.b
        cfg = state.config.orient
        #: The regions a map tears off (on A at full resolution: a lifted map keeps its
        #: neighbours' images near each other however dense A is).
        self.torn = TornRegions(state.a, self.b, cfg.tear_length, cfg.tear_edges, cfg.min_torn)
        self.view = state.common_a
        self.full = TurnedFaces(state.a, self.b)
        self.shape = state.a if self.view is None else self.view.shape
        self.tf = self.full if self.view is None else TurnedFaces(self.shape, self.b)

    def _of(self, f: np.ndarray) -> np.ndarray:
        """A map of A (internal numbering) on the shape it is judged on."""
        return f if self.view is None else self.view.of(f)

    def share(self, f: np.ndarray) -> float:
        """The share of A's area ``f`` (internal numbering) turns over."""
        if self.view is not None and self.view.rough:
            return self.tf.share(self._of(f))
        return self.full.share(f)

    def cost(self, f: np.ndarray, weight: float) -> float:
        """:func:`map_cost` of ``f``, its LMD measured where the map was made."""
        return map_cost(self.shape, self.b, self._of(f), self.share(f), weight, self.torn.share(f))

    def turned(self, f: np.ndarray, rings: int) -> np.ndarray:
        """Bool per vertex of A: in a region ``f`` turns over (more than half of a vertex's
        triangles' area, grown by ``rings`` 1-rings: a region's seam turns over only in
        part)."""
        region = turned_regions(self.shape, self.tf.vertices(self._of(f), 0.5), rings)
        return region if self.view is None else region[self.view.owner]


def map_cost(
    a: Shape, b: Shape, f: np.ndarray, turned: float, weight: float, torn: float = 0.0
) -> float:
    """What the stage minimises: ``turned``, the share of A's area the map ``f`` turns over,
    plus ``weight`` times the share of A's vertices whose 2-ring LMD finds inconsistent, plus
    ``torn``, the share of A's area it tears off (:mod:`hope_rs.pipeline.torn`). A right map
    keeps all three low; a mirror image keeps distances but turns over, a region shifted
    along the surface keeps both but tears off; a scrambled map shatters into pieces too small
    to count as torn off, and LMD sees it."""
    _, consistent = local_map_distortion(a, b, f)
    return float(turned) + weight * float(1.0 - np.mean(consistent)) + float(torn)


def _judged_by_confidence(state: MatchState) -> bool:
    """Whether the confidence's rule judges the maps (``OrientConfig.on_failed``): not for a
    dense A matched at a common resolution when that match measured no confidence (the
    confidence turned off): measured on the many-to-one map at full resolution, the rule
    flags it however right; nor for a part (its rule is the confidence stage's, which knows
    the part's counterpart on the whole)."""
    lifted_without = state.common_a is not None and state.confidence is None
    whole = state.partial is None
    return state.config.orient.on_failed and not lifted_without and whole


class _Relay:
    """A nested match's progress as steps of the "orient" stage (logged under its prefix);
    its refinement steps are not the outer match's, so their iterations are not passed on."""

    def __init__(self, state: MatchState):
        self._relay = state.log.relay("orient")
        self.log_prefix = self._relay.log_prefix

    def __call__(self, ev: ProgressEvent) -> None:
        self._relay(dataclasses.replace(ev, iteration=None))


def _nested_config(state: MatchState, *, confidence: bool = False):
    """The settings of a nested match: this stage and the deformation pass off (the pass runs
    once, on the map this stage keeps: its nearest-point maps turn more triangles over than
    the maps it starts from); the confidence only with ``confidence``. A part A is matched
    at the scale the partial stage chose, with that stage's settings for it."""
    cfg = state.config if state.partial is None else part_match_config(state.config)
    return dataclasses.replace(
        cfg,
        orient=dataclasses.replace(cfg.orient, enabled=False),
        deform=dataclasses.replace(cfg.deform, enabled=False),
        confidence=dataclasses.replace(
            cfg.confidence, enabled=confidence and cfg.confidence.enabled
        ),
    )


def _start_kind(state: MatchState) -> str:
    """The descriptor kind the stage's own match started from (the settings' when the caller
    passed a map)."""
    return state.init if isinstance(state.init, str) else state.config.initial.descriptor


def _symmetry_config(state: MatchState):
    """The settings of B's symmetry match: one triangulation on both sides, so the
    refinement alone finds the map (as on FAUST registrations); without the spectral pass
    and the shared-face finish."""
    cfg = _nested_config(state)
    return dataclasses.replace(
        cfg,
        spectral=dataclasses.replace(cfg.spectral, enabled=False),
        finish=dataclasses.replace(cfg.finish, enabled=False),
    )


class _Hypotheses:
    """The stage's candidates: the maps derived from the state's map and the other starts,
    each refined as a trial; scored by minus :meth:`_Judge.cost`."""

    def __init__(self, state: MatchState, judge: _Judge, names: tuple[str, ...]):
        self.state, self.judge = state, judge
        self.cfg = state.config.orient
        #: The hypotheses tried (``OrientConfig.hypotheses``, ``.topology_hypotheses`` or
        #: ``.torn_hypotheses``).
        self.names = names
        #: Whether the map was lifted from a match at a common resolution (its confidence
        #: carried over): so is every refined hypothesis, each matched there through the
        #: resolution stage, and each carries its own confidence the same way.
        self.lifted = state.confidence is not None
        self.nested = _nested_config(state, confidence=self.lifted)
        #: The settings of the unscored matches (B to A), whose confidence nothing reads.
        self.unscored = _nested_config(state)
        self.progress: Callable = _Relay(state)
        #: Turned-over share per trial label (the notes of the stage's reason).
        self.turned: dict[str, float] = {}
        #: Per trial label, whether the confidence's rule flags the map (``on_failed`` only).
        self.failed: dict[str, bool] = {}
        #: Whether a refined map is judged by the confidence's rule on its own confidence:
        #: after a lift, on the one it carries over.
        self.judged = _judged_by_confidence(state)
        self.notes: list[str] = []
        self.sym: np.ndarray | None = None
        #: The descriptor kind the stage's own match started from (the settings' when the
        #: caller passed a map): "reverse" matches B to A from it too.
        self.start = _start_kind(state)

    def internal(self, t: Trial) -> np.ndarray:
        c = t.candidate
        return c.a.map_in(c.b, t.result.map)

    def score(self, t: Trial) -> float:
        a, b = self.state.a, self.state.b
        f = self.internal(t)
        label = t.candidate.label
        self.turned[label] = self.judge.share(f)
        if self.judged and self.lifted:
            # The stage's own map (a trial not run, without a result's confidence) carries
            # the state's.
            carried = t.result.confidence
            carried = self.state.confidence if carried is None else carried
            assert carried is not None  # lifted: the state's map carries one
            q = match_quality(carried, self.state.config.confidence, flipped=self.turned[label])
            self.failed[label] = q.likely_failed
        elif self.judged:
            c = t.candidate
            hope = None if t.result.hope_map is None else c.a.map_in(c.b, t.result.hope_map)
            q = map_quality(a, b, f, hope, t.zoomout, self.state.config, flipped=self.turned[label])
            self.failed[label] = q.likely_failed
        return -self.judge.cost(f, self.cfg.distortion_weight)

    def good_enough(self, t: Trial, min_score: float) -> bool:
        """Whether a scored trial turns at most ``min_turned`` over, scores at least
        ``min_score`` and (``on_failed``) is not flagged by the confidence's rule."""
        label = t.candidate.label
        return (
            self.turned[label] <= self.cfg.min_turned
            and t.score is not None
            and t.score >= min_score
            and not self.failed.get(label, False)
        )

    def candidate(self, label: str, init) -> Candidate:
        """The pipeline from ``init`` (a descriptor kind or a map in internal numbering)."""
        a, b = self.state.a, self.state.b
        if not isinstance(init, str):
            init = a.map_out(b, init)
        return Candidate(label, a, b, init, self.nested)

    def refine(self, cands: list[Candidate]) -> list[Trial]:
        return run_trials(self.state, "orient", cands, self.score, progress=self.progress).tried

    def symmetry(self) -> np.ndarray:
        """B's intrinsic left/right symmetry, (n_b,) in B's internal numbering: the match
        of its mirror image to B (unscored trials). Where that match turns a region over
        (the identity, which keeps every distance, grows from the midline), the region is
        re-placed from the rest and matched again while the share turned over falls
        (``OrientConfig.symmetry_rounds``, ``symmetry_turned``)."""
        if self.sym is None:
            b, cfg = self.state.b, self.cfg
            mirror = mirror_image(b)
            settings = _symmetry_config(self.state)
            turned = TurnedFaces(mirror, b)

            def matched(label: str, init) -> tuple[np.ndarray, float]:
                c = Candidate(label, mirror, b, init, settings)
                t = run_trial(self.state, "orient", c, self.progress)
                g = mirror.map_in(b, t.result.map)
                return g, turned.share(g)

            # From SHOT whatever the match's start: WKS and HKS are intrinsic, the same on a
            # mirror image, so from them the "symmetry" comes out as the identity.
            f, share = matched("B's symmetry", "shot")
            shares = [share]
            for n in range(cfg.symmetry_rounds):
                if share <= cfg.symmetry_turned:
                    break
                region = turned_regions(mirror, turned.vertices(f, 0.5), cfg.seam_rings)
                g = reseeded(mirror, b, f, region, self.state.config.refine.repair)
                if g is None:
                    break
                g, now = matched(f"B's symmetry re-placed {n + 1}", mirror.map_out(b, g))
                shares.append(now)
                if now >= share:
                    break
                f, share = g, now
            last = " (the last not kept)" if shares[-1] != share else ""
            shown = " → ".join(f"{x:.0%}" for x in shares)
            self.notes.append(f"B's symmetry {shown} turned{last}")
            # Input vertex v of the mirror image is input vertex v of B.
            self.sym = f[mirror.rank[b.order]]
        return self.sym

    def derived(self, f: np.ndarray) -> dict[str, np.ndarray]:
        """The unrefined maps derived from ``f`` (internal numbering) by the derived
        hypotheses tried ("mirror", "mirror_turned", "reseed", "torn")."""
        cfg, a, b = self.cfg, self.state.a, self.state.b
        regional = any(h in ("mirror_turned", "reseed") for h in self.names)
        region = self.judge.turned(f, cfg.seam_rings) if regional else None
        out = {}
        for name in self.names:
            if name in ("mirror", "mirror_turned"):
                sym = self.symmetry()
                if name == "mirror":
                    out[name] = sym[f]
                else:
                    assert region is not None  # computed for the regional hypotheses
                    out[name] = np.where(region, sym[f], f)
            elif name == "reseed":
                assert region is not None  # computed for the regional hypotheses
                g = reseeded(a, b, f, region, self.state.config.refine.repair)
                if g is not None:
                    out[name] = g
            elif name == "torn":
                g = replaced(a, b, f, self.judge.torn, self.state.config.refine.repair)
                if g is not None:
                    out[name] = g
        return out

    def from_derived(self, f: np.ndarray, share: float, base: str = "") -> list[Trial]:
        """The least turned-over map derived from ``f`` by "mirror", "mirror_turned" or
        "reseed" refined, when it turns less over than ``f`` (``share``), and the one derived
        by "torn" refined, when ``f`` tears a region off; labelled ``base + "+" +
        hypothesis`` when derived from a trial ``base``."""
        raw = self.derived(f)
        prefix = f"{base}+" if base else ""
        cands = []
        torn = raw.pop("torn", None)
        if torn is not None:
            if base:
                self.notes.append(f"{base}: {self.judge.torn.share(f):.0%} torn off")
            cands.append(self.candidate(prefix + "torn", torn))
        if raw:
            shares = {k: self.judge.share(g) for k, g in raw.items()}
            self.notes.append(
                f"{prefix}unrefined " + ", ".join(f"{k} {v:.0%}" for k, v in shares.items())
            )
            best = min(shares, key=lambda k: shares[k])
            if shares[best] < share:
                cands.append(self.candidate(prefix + best, raw[best]))
        return self.refine(cands) if cands else []

    def reverse(self, label: str = "reverse") -> list[Trial]:
        """The pipeline from the match of B to A (unscored trial) inverted: each vertex of
        A onto the vertex of B whose image lies nearest it in space; ``"reverse_wks"``: B to
        A from the WKS initial map."""
        a, b = self.state.a, self.state.b
        init = "wks" if label == "reverse_wks" else self.start
        name = "B to A" + (" (wks)" if label == "reverse_wks" else "")
        c = Candidate(name, b, a, init, self.unscored)
        t = run_trial(self.state, "orient", c, self.progress)
        g = b.map_in(a, t.result.map)
        f = cKDTree(a.points[g]).query(a.points)[1].astype(np.int64)
        return self.refine([self.candidate(label, f)])


class OrientStage(Stage):
    """The "orient" stage (see the module notes); runs when the map turns more than
    ``OrientConfig.min_turned`` of A's area over, is flagged likely failed, the shapes
    differ in topology or the map tears a region off, on whole closed shapes without
    landmarks; on a part A matched to a whole, only when the map tears a region off."""

    name = "orient"
    #: A map another stage found final can still be a mirror image (LMD trusts it everywhere).
    runs_on_final_map = True

    def attach(self, state: MatchState) -> None:
        #: Where maps are judged (A's turned-over triangles on B), built when the stage
        #: decides whether to run.
        self._judge: _Judge | None = None
        #: Why the stage runs (its log line).
        self._why = ""
        #: The hypotheses it tries.
        self._names: tuple[str, ...] = ()
        #: Whether the turned-over share or the confidence's rule calls for the stage (not
        #: only the topology or a torn-off region).
        self._turned = False

    def skip_reason(self, state: MatchState):
        cfg = state.config.orient
        if not cfg.enabled:
            return QUIET
        if state.landmarks is not None:
            return "landmarks given"
        info = state.partial
        part = info is not None
        if info is not None and info.part == "b" and info.counterpart is None:
            return (
                "B is a part matched directly (whole_to_part='direct'): the stage repairs "
                "maps onto a whole"
            )
        if info is not None and info.part == "b":
            return "B is a part: the partial stage's match of it to A has this stage"
        if info is not None and not cfg.on_torn:
            return "a part: its orientation is the partial stage's"
        if state.f is None or state.run is None:
            return "no map"
        if not part and any(is_open(s) for s in (state.a, state.b)):
            # Which side of an open surface is outward is a guess (see turned.py), and the
            # partial stage's nested matches of a part are open.
            return f"an open surface (a boundary longer than {OPEN_BOUNDARY:g} sqrt(area))"
        if part and state.confidence is not None:
            # Lifted from a common resolution: the cost would be measured on the dense
            # part's many-to-one map, which misjudges right maps.
            return "a part matched at a common resolution: its map is the partial stage's"
        t = time.perf_counter()
        self._judge = _Judge(state)
        if part:
            return self._part_reason(state, t)
        share = self._judge.share(state.f)
        self._why = f"{share:.0%} of A turned over"
        self._names = cfg.hypotheses
        flagged = False
        if share <= cfg.min_turned and _judged_by_confidence(state):
            # A map wrong on a whole region can turn little over (a swapped pair of limbs,
            # or a mirror image whose seams tear) yet fail the confidence's rule.
            # A map lifted from a match at a common resolution carries that match's
            # confidence: a dense A's many-to-one map keeps few of its 2-rings' distances
            # however right, so it is not measured again here.
            if state.confidence is not None:
                q = match_quality(state.confidence, state.config.confidence, flipped=share)
            else:
                a, b, f = state.a, state.b, state.f
                q = map_quality(a, b, f, state.hope_map, state.zoomout, state.config, flipped=share)
            flagged = q.likely_failed
            self._why += (", flagged likely failed" if flagged else ", not flagged") + (
                f" (mean confidence {q.mean_confidence:.2f})"
            )
        differ = torn = False
        if share <= cfg.min_turned and not flagged and cfg.on_topology:
            ea, eb = state.a.euler_characteristic, state.b.euler_characteristic
            if ea != eb:
                differ = True
                self._why += (
                    f"; the shapes differ in topology (Euler characteristics {ea} and {eb})"
                )
                self._names = cfg.topology_hypotheses
        if share <= cfg.min_turned and not flagged and not differ and cfg.on_torn:
            # A region carried to the wrong place with its orientation and 2-rings kept. Not
            # when the topologies differ: a weld tears right maps too, and only the topology's
            # hypotheses run there (a re-placed map passing the stop rule first would end the
            # stage before the reverse match).
            torn_share = self._judge.torn.share(state.f)
            if torn_share > 0.0:
                torn = True
                self._why += f"; {torn_share:.0%} of A torn off"
                self._names = cfg.torn_hypotheses
        state.timings["orient"] = time.perf_counter() - t
        self._turned = share > cfg.min_turned or flagged
        if self._turned or torn or differ:
            return None
        return f"{share:.0%} of A's area turned over (at most {cfg.min_turned:.0%})" + (
            ", not flagged" if _judged_by_confidence(state) else ""
        )

    def _part_reason(self, state: MatchState, t: float) -> str | None:
        """A part A's map (the partial stage's, at the whole's scale) is tried again only
        when it tears a region off (``on_torn``, ``torn_hypotheses``): which side of an open
        surface is outward is a guess, so its turned-over share calls for nothing, and the
        confidence's rule for a part is the confidence stage's."""
        assert self._judge is not None and state.f is not None
        torn_share = self._judge.torn.share(state.f)
        state.timings["orient"] = time.perf_counter() - t
        names = tuple(h for h in state.config.orient.torn_hypotheses if h in PART_HYPOTHESES)
        if torn_share == 0.0:
            return "a part, nothing torn off: its orientation is the partial stage's"
        if not names:
            return (
                f"a part, {torn_share:.0%} of it torn off, but no hypothesis of "
                f"torn_hypotheses applies to a part (those of {', '.join(PART_HYPOTHESES)})"
            )
        self._why = f"A is a part; {torn_share:.0%} of it torn off"
        self._names = names
        return None

    def _mismatch(self, state: MatchState) -> float | None:
        """The shapes' spectral mismatch (:func:`~hope_rs.pipeline.deform.spectral_mismatch`),
        which ``OrientConfig.starts_first_mismatch`` compares; ``None`` for a part (its
        spectrum is not the whole's) and when this match's spectral pass made no bases (as
        the deform stage: a basis an earlier match left on the shapes would make the order
        depend on it; solving bases here would cost more than the order saves). Asked on
        the turned-over or flagged trigger only: a torn-off region placed back from the core
        is one cheap refinement that often passes, and the topology's re-placed map keeps
        its place too."""
        a, b = state.a, state.b
        k = _MISMATCH_EIGENVALUES + 1
        if state.partial is not None or state.zoomout is None:
            return None
        if not (a.has_spectral_basis(k) and b.has_spectral_basis(k)):
            return None
        try:
            return spectral_mismatch(a, b, _MISMATCH_EIGENVALUES)
        except RuntimeError:  # an eigenbasis the spectral pass could not read either
            return None

    def run(self, state: MatchState) -> None:
        cfg = state.config.orient
        t = time.perf_counter()
        judge, f = self._judge, state.f
        assert judge is not None and f is not None  # skip_reason measured the final map
        share = judge.share(f)
        # The maps derived from the stage's own first; then other starts (a swapped pair of
        # limbs comes back neither mirrored nor re-seeded), in the order of the hypotheses.
        # Between shapes far from isometric the derived maps come after the first start.
        starts = [h for h in self._names if h in ("wks", "reverse", "reverse_wks")]
        if _start_kind(state) == "wks":
            # "wks" is the stage's own match again, "reverse_wks" the same as "reverse".
            starts = [h for h in starts if h not in ("wks", "reverse_wks")]
        mismatch = self._mismatch(state) if starts and self._turned else None
        later = mismatch is not None and mismatch > cfg.starts_first_mismatch
        if later:
            self._why += f"; spectra differ by {mismatch:.3f}, other starts first"
        state.log.start("orient", detail=f"{self._why}: trying other maps")
        hyp = _Hypotheses(state, judge, self._names)
        own = current(state, "orient", "kept")
        own.score = own.record.score = hyp.score(own)
        min_score = own.score + cfg.min_gain

        def good_enough(tried: list[Trial]) -> bool:
            return any(hyp.good_enough(x, min_score) for x in tried)

        def own_derived() -> list[Trial]:
            """The maps derived from the stage's own, unless a map tried passes already."""
            return [] if good_enough(tried) else hyp.from_derived(f, share)

        tried: list[Trial] = []
        tried += [] if later else own_derived()
        for n, start in enumerate(starts):
            if later and n == 1:  # after the first start, before the second
                tried += own_derived()
            if good_enough(tried):
                break
            if start == "wks":
                new = hyp.refine([hyp.candidate(start, start)])
            else:
                new = hyp.reverse(start)
            if start == "reverse_wks":
                # The last resort, from the other shape's WKS map: it may replace the map only
                # when it passes the stop rule, not merely by costing least, and is not
                # derived from.
                passed = [x for x in new if hyp.good_enough(x, min_score)]
                tried += passed
                hyp.notes += [
                    f"{x.candidate.label}: {hyp.turned[x.candidate.label]:.0%} turned, cost "
                    f"{-(x.score or 0.0):.3f}, not kept (fails the stop rule)"
                    for x in new
                    if x not in passed
                ]
                continue
            tried += new
            # Derived again from this start's own map, not from the best so far: a start that
            # came back nearer may still carry a swapped limb the derived maps set right.
            best = max(new, key=lambda x: -np.inf if x.score is None else x.score)
            label = best.candidate.label
            if (
                cfg.again
                and not good_enough(tried)
                and best.score is not None
                and (best.score > own.score or hyp.turned[label] > cfg.again_turned)
            ):
                # The best refined map can still turn a region over that the derived maps
                # set right (a start that came back nearer, with a limb swapped, or a whole
                # mirror image, which B's symmetry turns back).
                tried += hyp.from_derived(hyp.internal(best), hyp.turned[label], label)
        if later and len(starts) == 1:  # after the only start
            tried += own_derived()
        kept = choose(state, "orient", tried, against=own, margin=cfg.min_gain)
        if kept is not own:
            # The refinement the caller's callback saw stays the state's history.
            adopt(state, kept, maps_only=True)
            if state.partial is None:
                # A part's confidence goes without a ZoomOut map (see trials.adopt).
                state.zoomout = kept.zoomout
            # A confidence carried over from a match at a common resolution belongs to the
            # map replaced here: a lifted hypothesis carries its own; otherwise the confidence
            # stage measures the new map.
            state.confidence = carried_confidence(state, kept)
        state.timings["orient"] += time.perf_counter() - t
        scored = "; ".join(
            f"{x.candidate.label}: {hyp.turned[x.candidate.label]:.0%} turned, "
            f"cost {-(x.score or 0.0):.3f}"
            + (", flagged" if hyp.failed.get(x.candidate.label) else "")
            for x in (own, *tried)
        )
        parts = [self._why, *hyp.notes, scored, f"chose {kept.candidate.label}"]
        state.log.ran("orient", state.timings["orient"], "; ".join(parts))
