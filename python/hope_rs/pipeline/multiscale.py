"""Coarse-to-fine matching for large meshes: HOPE on coarse copies, lifted, then a few fine passes.

A refinement step costs about linearly in the vertex count, and a k-hop ball of a dense mesh
covers a small patch, so dense pairs run every pass of the schedule and take minutes.
``match(..., multiscale=True)`` instead

1. clusters each dense mesh's vertices on a grid of cells at most ``CoarsenConfig.spacing`` ×
   sqrt(area) wide (:mod:`hope_rs.geometry.coarsen`; the Morton grid of :mod:`hope_rs.geometry.sites`, whose cells halve until they fit;
   vertex clustering, Rossignac & Borrel 1993: one vertex per cell, faces relabelled, collapsed
   ones dropped): about 14k vertices on a human body whatever the density, 8k on the TOSCA cat;
2. matches the coarse copies with the full method (SHOT computed on the fine mesh at the
   coarse vertices);
3. lifts the coarse map: each fine vertex of A is moved by the local linear map that best
   carries the coarse edges around its cell's vertex onto their images on B, and takes the
   fine vertex of B nearest that point;
4. runs :func:`fine_passes` passes of the usual refinement on the fine meshes (two up to 60k
   vertices, else one pass of a short schedule, :func:`fine_config`).

Both shapes must be dense enough to halve, else :func:`hope_rs.match` takes the default path
(a coarse copy matched against a sparser shape did worse than it). It trades accuracy for time
and is off by default; see docs/decisions.md#multiscale for the measurements and the variants
that did not pay.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..features.descriptors import shot_at
from ..geometry.mesh import Mesh, unique_edges
from ..shape import Shape
from .config import MatchConfig, MultiscaleConfig
from .landmarks import coarse_landmarks
from .spectral import applies as spectral_applies
from .state import QUIET, MatchState, Stage


def fine_passes(n_a: int, n_b: int, config: MultiscaleConfig = MultiscaleConfig()) -> int:
    """Passes of the refinement on fine meshes of ``n_a`` and ``n_b`` vertices after the
    lift: a second pass pays on smaller meshes and costs too much time on larger ones
    (docs/decisions.md#multiscale)."""
    if max(n_a, n_b) <= config.fine_passes_small_vertices:
        return config.fine_passes_small
    return config.fine_passes


def fine_config(cfg: MatchConfig, n_a: int, n_b: int) -> MatchConfig:
    """The settings of the stages after the lift on fine meshes of ``n_a`` and ``n_b``
    vertices: :func:`fine_passes` passes; above ``fine_passes_small_vertices`` a short
    schedule and smaller seed patches for the finish (``MultiscaleConfig.fine_schedule``,
    ``fine_seed_share``)."""
    ms = cfg.multiscale
    passes = min(cfg.refine.max_passes, fine_passes(n_a, n_b, ms))
    refine = dataclasses.replace(cfg.refine, max_passes=passes)
    if max(n_a, n_b) <= ms.fine_passes_small_vertices:
        return dataclasses.replace(cfg, refine=refine)
    growth = dataclasses.replace(cfg.finish.growth, seed_share=ms.fine_seed_share)
    return dataclasses.replace(
        cfg,
        refine=dataclasses.replace(refine, schedule=ms.fine_schedule or cfg.refine.schedule),
        finish=dataclasses.replace(cfg.finish, growth=growth),
    )


def _edges(faces: np.ndarray) -> np.ndarray:
    """Every edge of ``faces`` in both directions, once each."""
    e = unique_edges(faces)
    return np.concatenate([e, e[:, ::-1]])


def lift_map(
    coarse_a: Mesh,
    coarse_b: Mesh,
    g: np.ndarray,
    points_a: np.ndarray,
    owner_a: np.ndarray,
    points_b: np.ndarray,
    ridge: float = MultiscaleConfig.lift_ridge,
    centred: bool = False,
) -> np.ndarray:
    """A map of fine vertices from the coarse map ``g`` (coarse A → coarse B vertices).

    Fine vertex ``i`` of A, at ``points_a[i]``, belongs to coarse vertex ``c = owner_a[i]``.
    The linear map ``T_c`` that best carries the coarse edges of the 2-ring of ``c`` onto the
    edges between their images (least squares, with a small ``ridge`` (relative to the mean
    squared edge) so that a degenerate
    neighbourhood shrinks towards zero instead of blowing up) moves ``i`` to
    ``coarse_b.vertices[g[c]] + T_c (points_a[i] - x_c)``, and ``i`` takes the fine vertex of
    B (``points_b``) nearest that point. With ``centred`` the anchor ``(x_c, image of c)`` is
    the mean of the closed 1-ring of ``c`` and of its images instead: a coarse map off by up
    to a coarse edge here and there is averaged over the ring (the match at a common
    resolution lifts a map onto a denser B this way, each vertex of A its own coarse vertex)."""
    xa, yb = coarse_a.vertices, coarse_b.vertices
    n = xa.shape[0]
    e = _edges(coarse_a.faces)
    da = xa[e[:, 1]] - xa[e[:, 0]]
    db = yb[g[e[:, 1]]] - yb[g[e[:, 0]]]

    ring = sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))

    def moments(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Sum over each vertex's edges of u v^T, then over its 1-ring: the 2-ring's edges
        (a 1-ring's edges alone are often nearly coplanar, or two)."""
        outer = (u[:, :, None] * v[:, None, :]).reshape(-1, 9)
        own = np.stack([np.bincount(e[:, 0], outer[:, k], minlength=n) for k in range(9)], 1)
        return (own + ring @ own).reshape(n, 3, 3)

    p, q = moments(da, da), moments(db, da)
    damp = ridge * np.trace(p, axis1=1, axis2=2) / 3.0
    # A vertex without edges gets a unit ridge only: its fine vertices go to its image.
    damp = np.where(damp > 0, damp, 1.0)
    t = q @ np.linalg.inv(p + damp[:, None, None] * np.eye(3))
    anchor_a, anchor_b = xa, yb[g]
    if centred:
        degree = np.asarray(ring.sum(axis=1)).ravel() + 1.0
        anchor_a = (xa + ring @ xa) / degree[:, None]
        anchor_b = (yb[g] + ring @ yb[g]) / degree[:, None]
    target = anchor_b[owner_a] + np.einsum("nij,nj->ni", t[owner_a], points_a - anchor_a[owner_a])
    return cKDTree(points_b).query(target)[1].astype(np.int64)


def coarse_level(shape: Shape, kind: str | None):
    """(Coarse, coarse Shape) of ``shape`` (which must be dense enough to coarsen), with SHOT
    descriptors when ``kind`` is "shot"; the coarse Shape computes other kinds itself."""
    level = shape.coarse_level()
    if level is None:
        raise ValueError("the shape is not dense enough to coarsen (see coarse_mesh)")
    if kind == "shot" and not level[1].has_descriptors("shot"):
        # On the fine mesh, at the coarse vertices: the coarse surface would describe coarser.
        # The radius is the shape's (a part's view stretches it to the whole's scale).
        radius = shape.shot_radius()
        level[1].set_descriptors("shot", shot_at(shape.internal, level[0].sites, radius))
    return level


def too_sparse(a: Shape, b: Shape) -> str | None:
    """Why the multiscale path does not apply to these shapes, or ``None`` when it does."""
    for name, s in (("A", a), ("B", b)):
        if s.coarse_level() is None:
            return (
                f"{name} ({s.n_vertices} vertices) is too sparse to halve by vertex clustering "
                "(see hope_rs.geometry.coarsen.coarse_mesh)"
            )
    return None


class MultiscaleStage(Stage):
    """The "coarse" and "lift" stages: the stage list run on coarse copies of both shapes,
    the coarse map lifted to the fine vertices as ``state.f0``, and the refinement narrowed
    to :func:`fine_passes` passes.

    Both shapes must be dense enough to halve, else the default path runs: a coarse copy
    matched against a sparser shape did worse than it (docs/decisions.md#multiscale). The
    spectral pass runs once, at the finest level it affords: on the coarse copies only when
    the fine shapes are too large for it (docs/decisions.md#spectral).
    """

    name = "coarse"
    runs_on_final_map = False

    def skip_reason(self, state: MatchState):
        cfg = state.config.multiscale
        n = max(state.a.n_vertices, state.b.n_vertices)
        if cfg.enabled is False:
            if n > cfg.auto_vertices:
                return f"multiscale=False: the full path on {n} vertices"
            return QUIET
        if cfg.enabled is None and n <= cfg.auto_vertices:
            return QUIET
        sparse = too_sparse(state.a, state.b)
        return None if sparse is None else f"multiscale not applied: {sparse}"

    @staticmethod
    def why(state: MatchState) -> str:
        """Why the path ran: asked for, or chosen by size."""
        cfg = state.config.multiscale
        if cfg.enabled:
            return "multiscale=True"
        n = max(state.a.n_vertices, state.b.n_vertices)
        return f"chosen by size: {n} vertices > {cfg.auto_vertices}"

    def run(self, state: MatchState) -> None:
        a, b, cfg, log = state.a, state.b, state.config, state.log
        t = log.start("coarse", detail="matching coarse copies of both shapes")
        relay = log.relay("coarse")
        kind = state.init if isinstance(state.init, str) else None
        (ca, csa), (cb, csb) = coarse_level(a, kind), coarse_level(b, kind)
        init = state.init
        if kind is None:
            # The caller's map (internal numbering), in the coarse copies' own numbering.
            init = cb.owner[np.asarray(init)[ca.sites]]
        spectral = dataclasses.replace(
            cfg.spectral, enabled=cfg.spectral.enabled and not spectral_applies(a, b, cfg.spectral)
        )
        coarse_cfg = dataclasses.replace(
            cfg,
            spectral=spectral,
            multiscale=dataclasses.replace(cfg.multiscale, enabled=False),
        )
        lm = None
        if state.landmarks is not None:
            lm = coarse_landmarks(state.landmarks, ca.owner, cb.owner)
        assert state.run is not None  # the runner sets it
        res = state.run(
            csa, csb, init, coarse_cfg, callback=state.callback, progress=relay, landmarks=lm
        )
        state.f0 = lift_map(
            ca.mesh, cb.mesh, res.map, a.points, ca.owner, b.points, cfg.multiscale.lift_ridge
        )
        state.coarse = res
        state.timings["coarse"] = time.perf_counter() - t
        log.ran(
            "coarse",
            relay.last - t,
            f"coarse copies of {csa.n_vertices} and {csb.n_vertices} vertices matched "
            f"({self.why(state)})",
        )
        log.ran("lift", time.perf_counter() - relay.last, "coarse map carried to every vertex")
        state.config = fine_config(cfg, a.n_vertices, b.n_vertices)
