"""Matching at a common resolution: the denser shape coarsened to the sparser one's
vertex density, the pair matched there, the map lifted to the dense mesh.

A k-hop ball is a number of edges, so on a mesh with edges five times shorter the same k
covers a patch twenty-five times smaller, and the overlap cost compares unlike
neighbourhoods. Each shape is measured in its own sqrt(area), so its vertex count is its
density (:func:`density`; a part measured at its whole's scale covers less than unit area):
when one shape has more than ``ResolutionConfig.max_ratio`` times the other's density, the
"resolution" stage

1. coarsens the denser shape to the sparser one's density (its count for two whole shapes;
   :func:`common_count`), the copies measured in the shape's units
   (:meth:`hope_rs.Shape.derived`: a part's at its whole's scale): the sites of a uniform
   grid sized for that count, every other vertex merged into the site nearest it along the surface by
   edge collapses that keep the copy a valid manifold
   (:func:`hope_rs.geometry.collapse.collapse_to_count`; each coarse vertex is a vertex of
   the dense mesh, and owns the dense vertices merged into it; plain clustering glues
   non-manifold edges and turns faces over, which misleads the coarse match); when the
   collapses fall well short of the count (a noisy scan, whose faces turn over at the
   noise's scale, refuses them: ``ResolutionConfig.collapse_excess``) they are made again
   on the mesh smoothed, the copy keeping its vertices' own positions; when B is the
   denser shape and its copy is much rougher along its normals than A (a noisy scan as the
   target: ``ResolutionConfig.smooth_rougher``, :func:`rougher_than`), each of its vertices
   moves to the mean of the dense vertices it owns (:func:`smoothed`);
2. matches the pair at that common resolution with the whole stage list (descriptors,
   refinement, spectral pass, finish), or from a given initial map carried to the copy
   (:func:`coarse_start`; the orient stage's hypotheses after a lift are such maps); a clean
   copy's SHOT is the dense mesh's at its vertices (``ResolutionConfig.dense_shot``: the
   copy's few, irregular faces bend its normals and reference frames);
3. lifts the map (:func:`hope_rs.pipeline.multiscale.lift_map`, ``centred``): each vertex
   of A (when A is the dense shape, the coarse vertex of its cell) is carried by the local
   linear map of its ring's edges onto their images, anchored at the ring's centroid and the
   centroid of its images, and takes the vertex of B nearest that point: the coarse map's
   offsets of up to a coarse edge average out over the ring.

   When A is the denser shape and its lifted map passes (at most ``OrientConfig.min_turned``
   turned over, not flagged on the carried confidence), the pair is matched once more at a
   copy of A collapsed to sites placed as B's vertices lie under that map (for each vertex of
   B it reaches, the dense vertex sent there nearest their centroid:
   :func:`sites_like`), and that lift is kept when it passes too
   (``ResolutionConfig.follow_density``): a uniform copy against a template denser at its
   hands and face compares k-hop balls of unlike areas there.

4. refines the lifted map at full resolution (``ResolutionConfig.refine``): the sparser
   shape is subdivided (:func:`hope_rs.geometry.subdivide.subdivide`, each face into four)
   to about the denser one's density, so that k-hop balls on both cover like patches; the pair
   is matched from the lifted map with one short pass of HOPE steps and the shared-face
   finish (which makes a shape and its subdivided copy exact), and each vertex of the
   subdivided shape is carried back to the nearest vertex of the sparser one (an original
   vertex is itself). Run only when the lifted map's handles cluster in patches
   (:meth:`ResolutionStage.shares_faces`: shapes remeshed independently share no faces, and
   their few handles are scattered), and kept only when the finish ran: without shared
   faces the HOPE steps alone did worse than the lift.

The map is final, and its confidence is the coarse match's (each dense vertex of A takes its
coarse vertex's): a dense A's many-to-one map to a sparse B keeps few of its 2-rings'
distances however right it is. The pair is judged (``MatchResult.quality``) on that
confidence and the share of A the lifted map turns over, measured on A's copy when A is a
noisy scan (more than ``ResolutionConfig.judge_rougher`` times as rough at its own
resolution as B: :func:`rough_scan`), whose own triangles a right map turns over at random.
The stages after it do not run, but for the orient stage, which runs on that judgement; its
hypotheses are matched through this stage too, each from its map carried to the common
resolution, and a map it adopts carries its own match's confidence
(docs/decisions.md#resolution).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from typing import Callable

import numpy as np
from scipy.spatial import cKDTree

from ..features.descriptors import shot_at
from ..geometry.coarsen import Coarse
from ..geometry.collapse import collapse_to_count, collapse_to_sites
from ..geometry.mesh import Mesh, unique_edges
from ..geometry.numbering import canonical_mesh
from ..geometry.roughness import at_owner_means, rougher, umbrella_smoothed
from ..geometry.sites import cell_sites
from ..geometry.subdivide import subdivide
from ..shape import Shape
from .confidence import flipped_share, match_quality
from .config import ResolutionConfig
from .handles import edge_large_patches, mesh_face_handles
from .landmarks import coarse_landmarks
from .multiscale import lift_map
from .result import MatchResult
from .shared_faces import qualifies
from .state import QUIET, CommonView, Halt, MatchState, Stage

__all__ = [
    "ResolutionStage",
    "coarse_start",
    "common_count",
    "denser_side",
    "density",
    "subdivisions",
]


def density(s: Shape) -> float:
    """Vertices per unit area, in the units the shape is matched in (its own sqrt(area) for a
    whole shape; a part viewed at the whole's scale has less than unit area)."""
    return s.density


def common_count(dense: Shape, sparse: Shape) -> int:
    """Vertices of a copy of ``dense`` at ``sparse``'s density (:func:`density`): the sparser
    shape's count for two whole shapes; for a part (viewed at the whole's scale) against
    its whole, scaled by the ratio of their areas, so that a whole coarsened to a part's
    density keeps more vertices than the part has."""
    return max(3, int(round(density(sparse) * dense.unit_area)))


def denser_side(a: Shape, b: Shape, max_ratio: float) -> str | None:
    """ "a" or "b" when that shape has more than ``max_ratio`` times the other's vertex
    density (:func:`density`), else ``None``."""
    da, db = density(a), density(b)
    if da > max_ratio * db:
        return "a"
    if db > max_ratio * da:
        return "b"
    return None


def subdivisions(sparse: float, dense: float) -> int:
    """How many times to subdivide a mesh of ``sparse`` vertices (each time about 4x) to come
    nearest ``dense`` (or of one density to come nearest another): at least once."""
    return max(1, round(np.log(dense / sparse) / np.log(4.0)))


def sites_like(f: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Vertices of a dense A placed as B's vertices lie under the many-to-one map ``f`` (A →
    B, internal numberings): for each vertex of B that ``f`` reaches, the vertex sent there
    nearest the centroid of those sent there (:func:`~hope_rs.geometry.sites.cell_sites`
    with B's vertices as the cells), sorted."""
    return np.sort(cell_sites(points, f)[0])


def coarse_start(state: MatchState, side: str, coarse: Coarse):
    """The start of the match at the common resolution: the descriptor kind, or a given map
    (``state.init``, internal numbering) in the input numbering of the copy's match: when A
    is the denser shape each coarse vertex takes its site's image, else each vertex of A the
    coarse vertex owning its image."""
    init = state.init
    if isinstance(init, str):
        return init
    f = np.asarray(init, dtype=np.int64)
    if side == "a":
        return state.b.order[f[coarse.sites]]
    return coarse.owner[f[state.a.rank]]


def coarse_copy(
    shape: Shape, n_target: int, tolerance: float, excess: float = math.inf, smoothing: int = 0
) -> tuple[Coarse, Shape] | None:
    """(Coarse, its Shape) of ``shape``'s internal mesh with about ``n_target`` vertices, by
    manifold-keeping edge collapses (:func:`hope_rs.geometry.collapse.collapse_to_count`), or
    ``None`` when ``shape`` has no more vertices or the copy has no face. The copy keeps the
    oriented faces as they come. ``excess``, ``smoothing``: see :func:`_collapsed`."""
    c, _ = _collapsed(
        shape, n_target, tolerance, excess, lambda: umbrella_smoothed(shape.internal, smoothing)
    )
    return None if c is None else (c, shape.derived(c.mesh))


def _collapsed(
    shape: Shape, n_target: int, tolerance: float, excess: float, denoised: Callable[[], Mesh]
) -> tuple[Coarse | None, bool]:
    """The Coarse of :func:`coarse_copy`, before its Shape is built, and whether it was made
    again on the mesh smoothed (``excess``, ``denoised``: see :func:`_made_again`)."""
    c, again = _made_again(
        shape.internal,
        n_target,
        lambda m: collapse_to_count(m, n_target, tolerance=tolerance),
        excess,
        denoised,
    )
    return c, again


def _made_again(
    mesh: Mesh,
    n_target: int,
    collapse: Callable[[Mesh], Coarse | None],
    excess: float,
    denoised: Callable[[], Mesh],
) -> tuple[Coarse | None, bool]:
    """``collapse(mesh)``, or when it keeps more than ``excess`` times ``n_target`` vertices
    (``ResolutionConfig.collapse_excess``), ``collapse`` of ``denoised()`` (the mesh smoothed:
    :func:`~hope_rs.geometry.roughness.umbrella_smoothed`) with its kept vertices at
    their own positions, when that keeps fewer: a noisy scan's faces turn over at the
    noise's scale, so the collapses that would turn one over are refused and the copy keeps
    vertices off its sites. Also whether the second one was kept."""
    c = collapse(mesh)
    if c is None or c.mesh.n_vertices <= excess * n_target:
        return c, False
    again = collapse(denoised())
    if again is None or again.mesh.n_vertices >= c.mesh.n_vertices:
        return c, False
    return dataclasses.replace(again, mesh=Mesh(mesh.vertices[again.sites], again.mesh.faces)), True


def rougher_than(coarse: Coarse, like: Shape, times: float) -> float | None:
    """How many times as rough along its normals as ``like`` the copy ``coarse`` is
    (:func:`~hope_rs.geometry.roughness.rougher`), when more than ``times`` times
    (``ResolutionConfig.smooth_rougher``); else ``None``. A noisy dense scan keeps its noise at
    the vertices a copy keeps, where it is no longer small against the edges; a copy of a
    clean dense surface is about as rough as the sparser shape or smoother."""
    if not math.isfinite(times):
        return None
    ratio = rougher(coarse.mesh, like.internal)
    return ratio if ratio > times else None


def smoothed(coarse: Coarse, dense: Shape) -> Coarse:
    """``coarse`` (a copy of ``dense``) with each vertex at the mean of the dense vertices it
    owns: the mean takes most of a noisy scan's noise out."""
    mesh = at_owner_means(coarse.mesh, dense.internal.vertices, coarse.owner)
    return dataclasses.replace(coarse, mesh=mesh)


def _view(coarse: Coarse, cs: Shape, rough: bool) -> CommonView:
    """The copy ``cs`` of a dense A (made from ``coarse``) as a :class:`CommonView`;
    ``rough``: A is rough at its own resolution (:func:`rough_scan`)."""
    return CommonView(cs, coarse.sites[cs.order], cs.rank[coarse.owner], rough)


def rough_scan(a: Shape, b: Shape, times: float) -> bool:
    """Whether A is more than ``times`` times as rough along its normals as B, each at its
    own resolution (:func:`~hope_rs.geometry.roughness.normal_roughness`;
    ``ResolutionConfig.judge_rougher``): a noisy scan, whose own triangles a right map turns
    over at random. A clean dense surface is smoother than a sparser one."""
    return math.isfinite(times) and rougher(a.internal, b.internal) > times


class ResolutionStage(Stage):
    """The "resolution" stage (see the module notes): runs only when one shape is more than
    ``ResolutionConfig.max_ratio`` times denser than the other and no part was detected. A
    given initial map starts the match at the common resolution (:func:`coarse_start`)."""

    name = "resolution"
    runs_on_final_map = False

    def __init__(self):
        self.side: str | None = None
        self.start_handles = 0.0  # share of handles of the refinement's start
        self.start_patched = 0.0  # share of the vertices: handles in patches that count
        self.rough = False  # A is a noisy dense scan (rough_scan)

    def skip_reason(self, state: MatchState):
        cfg = state.config.resolution
        if not cfg.enabled or state.partial is not None:
            return QUIET
        self.side = denser_side(state.a, state.b, cfg.max_ratio)
        return QUIET if self.side is None else None

    def run(self, state: MatchState) -> Halt | None:
        a, b, cfg = state.a, state.b, state.config
        assert self.side is not None  # skip_reason found the denser side
        dense, sparse = (a, b) if self.side == "a" else (b, a)
        name = self.side.upper()
        detail = (
            f"{name} ({dense.n_vertices} vertices) is more than {cfg.resolution.max_ratio:g} "
            f"times denser than the other ({sparse.n_vertices})"
        )
        if not (dense.at_own_scale and sparse.at_own_scale):
            # A part: its count is not its density.
            detail += f" per unit area ({density(dense):.0f} against {density(sparse):.0f})"
        t = state.log.start("resolution", detail=detail)
        rc = cfg.resolution
        self.rough = self.side == "a" and rough_scan(a, b, rc.judge_rougher)
        # Smoothed once, when a copy first needs it (the second copy may too).
        denoised = functools.cache(lambda: umbrella_smoothed(dense.internal, rc.collapse_smoothing))
        coarse, made_again = _collapsed(
            dense, common_count(dense, sparse), rc.count_tolerance, rc.collapse_excess, denoised
        )
        if coarse is None:
            state.timings["resolution"] = time.perf_counter() - t
            why = f"{detail}, but clustering it leaves no face: matched at full resolution"
            state.log.ran("resolution", state.timings["resolution"], why)
            return None
        # A noisy dense B only: on a noisy dense A it was measured worse (decisions.md).
        ratio = None
        if self.side == "b":
            ratio = rougher_than(coarse, sparse, cfg.resolution.smooth_rougher)
        if ratio is not None:
            coarse = smoothed(coarse, dense)
        cs = self.copy_shape(state, dense, coarse, clean=ratio is None and not made_again)
        nested = dataclasses.replace(
            cfg,
            resolution=dataclasses.replace(cfg.resolution, enabled=False),
            multiscale=dataclasses.replace(cfg.multiscale, enabled=False),
        )
        res, f, lift = self.lifted(state, coarse, cs, nested)
        counts = f"{cs.n_vertices} vertices" + (
            " (its collapses redone on the mesh denoised: its noise refused them)"
            if made_again
            else ""
        )
        counts += f" (smoothed: {ratio:.1f} times as rough as A)" if ratio is not None else ""
        if self.rough:
            counts += " (a rough scan: its turned-over share measured on the copy)"
        if (
            self.side == "a"
            and cfg.resolution.follow_density
            and self.trusted(state, res, coarse, cs, f)
        ):
            # Again at a copy of A whose vertices lie as densely as B's do where the map sends
            # them: a uniform copy against a template denser at its hands and face compares
            # unlike k-hop balls there, and can put a hand on a thigh. Only from a map that
            # passes (a wrong one places the density wrongly), and kept only if it passes too.
            sites = sites_like(f, dense.points)
            second, redone = _made_again(
                dense.internal,
                sites.size,
                lambda m: collapse_to_sites(m, sites),
                rc.collapse_excess,
                denoised,
            )
            if second is not None:
                cs2 = self.copy_shape(state, dense, second, clean=not redone)
                state.timings["resolution.first"] = time.perf_counter() - t
                again = self.lifted(state, second, cs2, nested)
                if self.trusted(state, again[0], second, cs2, again[1]):
                    coarse, cs, (res, f, lift) = second, cs2, again
                    counts += f", then at {cs.n_vertices} placed as densely as B's" + (
                        " (collapses redone on the mesh denoised)" if redone else ""
                    )
                else:
                    counts += f" (not at {cs2.n_vertices} placed as densely as B's: that map fails)"
        f = f.astype(np.int64)
        note = ""
        if cfg.resolution.refine:
            fine = self.refined(state, f, dense, sparse, None if self.side == "b" else lift)
            h = (
                f"{self.start_handles:.1%} of the vertices handles at the start, "
                f"{self.start_patched:.1%} in patches"
            )
            if fine is None:
                note = f"; no shared faces to refine at full resolution ({h})"
            else:
                f, note = fine, f", refined at full resolution ({h})"
        state.f = state.hope_map = f
        if self.side == "a":
            state.common_a = _view(coarse, cs, self.rough)
        if isinstance(state.init, str):
            state.f0 = f  # a given initial map stays the result's init_map
        if res.confidence is not None:
            # Measured where the map was made: a dense A's many-to-one map to a sparse B keeps
            # few of its 2-rings' distances however right it is.
            c = res.confidence
            state.confidence = c[coarse.owner] if self.side == "a" else c[a.order]
        state.timings.update({f"resolution.{k}": v for k, v in res.timings.items()})
        state.timings["resolution"] = time.perf_counter() - t
        state.log.ran(
            "resolution",
            state.timings["resolution"],
            f"{detail}: {name} clustered to {counts}, matched there, lifted{note}",
        )
        return Halt(f"the map is lifted from the match at {cs.n_vertices} vertices of {name}")

    def copy_shape(self, state: MatchState, dense: Shape, coarse: Coarse, clean: bool) -> Shape:
        """The Shape of ``coarse``, a copy of ``dense``; with ``ResolutionConfig.dense_shot``,
        a ``clean`` copy (neither smoothed nor collapsed on the mesh smoothed: its dense mesh
        is not noisy) of a shape that is not a rough scan takes the dense mesh's SHOT at its
        vertices (every dense vertex voting). A view of the copy at another scale computes
        its own."""
        cs = dense.derived(coarse.mesh)
        if state.config.resolution.dense_shot and clean and not self.rough:
            cs.set_descriptors("shot", shot_at(dense.internal, coarse.sites, dense.shot_radius()))
        return cs

    def trusted(
        self, state: MatchState, res: MatchResult, coarse: Coarse, cs: Shape, f: np.ndarray
    ) -> bool:
        """Whether the lifted map ``f`` of a dense A passes: it turns at most
        ``OrientConfig.min_turned`` of A's area over (for a rough A measured on the copy
        ``cs``, of ``coarse``, it was made at), and the confidence's rule, on the confidence carried over
        from the match ``res`` there, does not flag it."""
        view = _view(coarse, cs, self.rough)
        share = flipped_share(state.a, state.b, f, view=view)
        if share > state.config.orient.min_turned:
            return False
        if res.confidence is None:
            return True
        carried = res.confidence[coarse.owner]
        return not match_quality(carried, state.config.confidence, flipped=share).likely_failed

    def lifted(
        self, state: MatchState, coarse: Coarse, cs: Shape, nested
    ) -> tuple[MatchResult, np.ndarray, Callable[[np.ndarray], np.ndarray] | None]:
        """The pair matched with the denser shape's copy ``cs`` (of ``coarse``) and the map
        lifted to full resolution: ``(the nested result, the lifted map (internal
        numbering), the lift onto given points of B when A is the denser shape)``."""
        a, b, cfg = state.a, state.b, state.config
        lm = None
        if state.landmarks is not None:
            ident_a, ident_b = np.arange(a.n_vertices), np.arange(b.n_vertices)
            owner_a = coarse.owner if self.side == "a" else ident_a
            owner_b = coarse.owner if self.side == "b" else ident_b
            lm = coarse_landmarks(state.landmarks, owner_a, owner_b)
            if lm is not None and self.side != "a":
                lm[:, 0] = a.order[lm[:, 0]]  # A keeps its own input numbering
            if lm is not None and self.side != "b":
                lm[:, 1] = b.order[lm[:, 1]]
        pa, pb = (cs, b) if self.side == "a" else (a, cs)
        assert self.side is not None  # skip_reason found the denser side
        init = coarse_start(state, self.side, coarse)
        assert state.run is not None  # the runner gives every state its nested runner
        res = state.run(pa, pb, init, nested, callback=state.callback, landmarks=lm)
        ridge = cfg.multiscale.lift_ridge
        if self.side == "b":
            # Each vertex of A is its own coarse vertex; its image a vertex of the coarse B.
            g = res.map[a.order]
            ident = np.arange(a.n_vertices)
            f = lift_map(a.internal, coarse.mesh, g, a.points, ident, b.points, ridge, True)
            return res, f.astype(np.int64), None
        g = b.rank[res.map]  # coarse vertex (the copy's input numbering) -> B internal

        def lift(points_b: np.ndarray) -> np.ndarray:
            return lift_map(
                coarse.mesh, b.internal, g, a.points, coarse.owner, points_b, ridge, True
            )

        return res, lift(b.points).astype(np.int64), lift

    def shares_faces(self, edges: np.ndarray, handles: np.ndarray, rc: ResolutionConfig) -> bool:
        """Whether the lifted map's ``handles`` (bool per vertex of the side of the pair at
        full resolution whose faces are tested; ``edges``: that side's undirected edges,
        internal numbering) are enough for the pass at full
        resolution: ``rc.refine_min_handles`` of the vertices, and ``rc.refine_min_patched``
        in patches of at least ``rc.refine_patch_share`` of them. Records both shares."""
        self.start_handles = float(handles.mean())
        self.start_patched = float(edge_large_patches(edges, handles, rc.refine_patch_share).mean())
        return (
            self.start_handles >= rc.refine_min_handles
            and self.start_patched >= rc.refine_min_patched
        )

    def refined(
        self,
        state: MatchState,
        f: np.ndarray,
        dense: Shape,
        sparse: Shape,
        lift: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> np.ndarray | None:
        """The lifted map ``f`` (internal numbering) refined at full resolution (see the
        module notes, step 4), or ``None`` when the refined map does not share faces
        (:func:`~hope_rs.pipeline.shared_faces.qualifies`; no shared triangulation): then the HOPE steps alone, on shapes remeshed
        independently, moved the lifted map away from the truth (docs/decisions.md#resolution).
        ``lift``: the lift of the coarse match onto given points of B (used when B is the
        shape subdivided)."""
        a, b, cfg = state.a, state.b, state.config
        times = subdivisions(density(sparse), density(dense))
        # The copy's own numbering: the sparser shape's vertices first (internal numbering).
        mesh = subdivide(sparse.internal, times)
        # Its internal mesh and numbering as its Shape has them (repeated faces dropped),
        # without the Shape's k-hop graph: the check below decides whether the pass runs.
        internal, order, rank = canonical_mesh(mesh, orient=False)
        nested = dataclasses.replace(
            cfg,
            partial=dataclasses.replace(cfg.partial, enabled=False),
            resolution=dataclasses.replace(cfg.resolution, enabled=False),
            multiscale=dataclasses.replace(cfg.multiscale, enabled=False),
            refine=dataclasses.replace(
                cfg.refine, schedule=cfg.resolution.refine_schedule, max_passes=1
            ),
            spectral=dataclasses.replace(cfg.spectral, enabled=False),
            orient=dataclasses.replace(cfg.orient, enabled=False),
            confidence=dataclasses.replace(cfg.confidence, enabled=False),
            finish=dataclasses.replace(
                cfg.finish,
                growth=dataclasses.replace(
                    cfg.finish.growth, seed_share=cfg.resolution.refine_seed_share
                ),
            ),
        )
        assert state.run is not None
        points = mesh.vertices
        if self.side == "b":
            # A subdivided: its new vertices take the lift of the map by their ring's edges.
            owner = cKDTree(a.points).query(points)[1]
            init = lift_map(a.internal, b.internal, f, points, owner, b.points, centred=True)
            init[: a.n_vertices] = f
            handles = mesh_face_handles(internal, b.internal, init[order])
            if not self.shares_faces(unique_edges(internal.faces), handles, cfg.resolution):
                return None
            up = sparse.derived(mesh)
            # The landmarks in the nested shapes' input numbering: A's vertices come first in
            # the subdivided copy, in A's internal numbering.
            lm = None
            if state.landmarks is not None:
                lm = np.column_stack([state.landmarks[:, 0], b.order[state.landmarks[:, 1]]])
            res = state.run(up, b, b.order[init], nested, callback=state.callback, landmarks=lm)
            if not qualifies(up, b, b.rank[res.map[up.order]], cfg.finish):
                return None
            return b.rank[res.map[: a.n_vertices]].astype(np.int64)
        # B subdivided: its first vertices are B's own (internal numbering). The start is the
        # lift onto the subdivided B (the lift onto B itself maps many vertices to one).
        assert lift is not None
        f = lift(points)
        if not self.shares_faces(
            a.edges, mesh_face_handles(a.internal, internal, rank[f]), cfg.resolution
        ):
            return None
        up = sparse.derived(mesh)
        lm = None
        if state.landmarks is not None:
            # B's vertices come first in its subdivided copy, in B's internal numbering.
            lm = np.column_stack([a.order[state.landmarks[:, 0]], state.landmarks[:, 1]])
        res = state.run(a, up, f[a.rank], nested, callback=state.callback, landmarks=lm)
        if not qualifies(a, up, up.rank[res.map[a.order]], cfg.finish):
            return None
        back = cKDTree(b.points).query(points)[1]
        back[: b.n_vertices] = np.arange(b.n_vertices)
        return back[res.map[a.order]].astype(np.int64)
