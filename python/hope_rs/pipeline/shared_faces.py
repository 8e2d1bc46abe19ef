"""Finishing rounds for shapes that share most of their triangulation.

Where A and B are one triangulation in two poses (FAUST registrations, the TOSCA cat) or a part
of one, the true map sends faces onto faces. HOPE's k-hop overlaps cannot see an error of a few
edges where a pose stretches the surface: there HOPE's map drifts smoothly by a few edges, a
drift that the overlaps of drifted witnesses reproduce.

Each round takes as handles the vertices whose faces all map onto faces of B (with their
orientation) and whose image no other vertex shares, deforms A as rigidly as possible (ARAP,
Sorkine and Alexa 2007) so that the handles sit on their images, moves every other vertex to
the vertex of B nearest its deformed position, and then runs a few HOPE steps at a fixed hop
radius with every vertex voting, which pull the moved vertices onto a one-to-one map. Rounds
repeat while the handle patches that can seed the growth grow. Last,
:func:`hope_rs.pipeline.growth.grow` rebuilds the map from its trusted patches outward. See
docs/decisions.md#shared-faces and docs/decisions.md#growth for the variants measured.

Shapes without shared faces (independently remeshed shapes have few handles) do not qualify
(see ``FinishConfig.min_handles``).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from scipy.spatial import cKDTree

from .. import _core
from .._blas import with_single_threaded_blas
from ..shape import Shape
from .config import FinishConfig, RefineConfig
from .growth import grow
from .handles import face_handles, large_patches
from .overlap import assign_by_overlap, hop_limit
from .state import MatchState, Stage, StepClock


def applies(a: Shape, b: Shape, config: FinishConfig = FinishConfig()) -> bool:
    """Whether the finishing rounds may run on these shapes (both at most
    ``config.max_vertices`` vertices, when set)."""
    return config.max_vertices is None or max(a.n_vertices, b.n_vertices) <= config.max_vertices


def qualifies(a: Shape, b: Shape, f: np.ndarray, config: FinishConfig = FinishConfig()) -> bool:
    """Whether the map ``f`` (internal numbering) has at least ``config.min_handles`` of A's
    vertices as handles (see :func:`face_handles`)."""
    return bool(face_handles(a, b, f).mean() >= config.min_handles)


def arap_to_handles(
    points: np.ndarray,
    edges: np.ndarray,
    start: np.ndarray,
    handles: np.ndarray,
    config: FinishConfig = FinishConfig(),
) -> np.ndarray:
    """Positions of A's vertices after deforming ``points`` as rigidly as possible (uniform
    edge weights) with the ``handles`` held at ``start``; ``start`` also seeds the rotations
    and weakly anchors the free vertices (``config.anchor_weight``)."""
    return _Arap(points, edges, config).fit(start, handles)


class _Arap:
    """The parts of :func:`arap_to_handles` that depend on the mesh alone, built once for all
    the rounds of a finish."""

    def __init__(self, points: np.ndarray, edges: np.ndarray, config: FinishConfig):
        self.config = config
        n = self.n = len(points)
        i = self.i = np.concatenate([edges[:, 0], edges[:, 1]])  # every edge both ways
        j = self.j = np.concatenate([edges[:, 1], edges[:, 0]])
        w = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
        self.lap = (sp.diags(np.asarray(w.sum(axis=1)).ravel()) - w).tocsr()
        # Sums over each vertex's edges as one sparse product (faster than np.add.at).
        self.per_vertex = sp.csr_matrix(
            (np.ones(len(i)), (i, np.arange(len(i)))), shape=(n, len(i))
        )
        # Each vertex's edges in order, for the rotations' sums (``_core.edge_rotations``).
        self.edge_ptr = self.per_vertex.indptr.astype(np.int64)
        self.edge_ids = self.per_vertex.indices.astype(np.int64)
        self.ex = points[i] - points[j]

    def fit(self, start: np.ndarray, handles: np.ndarray) -> np.ndarray:
        i, j, ex, per_vertex = self.i, self.j, self.ex, self.per_vertex
        free = ~handles
        weight = self.config.anchor_weight
        lff = (self.lap[free][:, free] + weight * sp.eye(int(free.sum()))).tocsc()
        lfh = self.lap[free][:, handles]
        solve = sla.splu(lff).solve
        y = np.array(start, dtype=np.float64)
        for _ in range(self.config.arap_iterations):
            # The closest rotation to each vertex's sum of ex eyᵀ over its edges, in one pass.
            rot = _core.edge_rotations(self.edge_ptr, self.edge_ids, ex, y[i] - y[j])
            rhs = per_vertex @ (0.5 * np.einsum("nij,nj->ni", rot[i] + rot[j], ex))
            rhs = rhs[free] - lfh @ y[handles] + weight * start[free]
            y[free] = np.column_stack([solve(np.ascontiguousarray(rhs[:, c])) for c in range(3)])
        return y


# SuperLU's solves call BLAS; one thread keeps their bits, and so the map, the same whatever
# the process's thread count (a Ray worker runs with one).
@with_single_threaded_blas
def finish(
    a: Shape,
    b: Shape,
    f: np.ndarray,
    config: FinishConfig = FinishConfig(),
    *,
    refine: RefineConfig = RefineConfig(),
    clock: StepClock | None = None,
    k_max: int | None = None,
) -> tuple[np.ndarray, int]:
    """The map after the finishing rounds and, if any ran, the growth from their trusted
    patches (:func:`hope_rs.pipeline.growth.grow`), in the internal numbering; and how many
    rounds ran. ``refine``: the settings of the HOPE steps after each round (``top_k``...);
    ``clock``: adds up those steps' seconds (see :func:`~hope_rs.pipeline.overlap.assign_by_overlap`);
    ``k_max``: the match's largest hop radius (``MatchConfig.k_max``), which caps ``step_k``."""
    cfg = config
    f = np.asarray(f, dtype=np.int64)
    n_a = a.n_vertices
    k = min(cfg.step_k, hop_limit(a, b, k_max))
    every = np.ones(n_a, dtype=bool)
    arap = tree = None  # built by the first round that runs
    last = 0.0
    done = 0
    for _ in range(cfg.rounds):
        handles = face_handles(a, b, f)
        seeded = large_patches(a, handles, cfg.growth.seed_share, cfg.growth.seed_irregular).mean()
        if handles.mean() < cfg.min_handles or seeded < last + cfg.min_growth or handles.all():
            break
        last = seeded
        if arap is None:
            # In B's units, so that a scaled copy deforms by rotations alone.
            arap = _Arap(a.points * (b.scale / a.scale), a.edges, cfg)
            tree = cKDTree(b.points)
        assert tree is not None  # built with arap
        g = tree.query(arap.fit(b.points[f], handles))[1].astype(np.int64)
        g[handles] = f[handles]
        for _ in range(cfg.steps):
            g = assign_by_overlap(a, b, k, g, every, config=refine, clock=clock)
        f = g
        done += 1
    if done:
        f = grow(a, b, f, cfg.growth)
    return f, done


class FinishStage(Stage):
    """The "faces" stage: :func:`finish` on shapes that share most of their triangulation.

    Answers the refinement's "stop_refining" question (a map with enough handles is the
    finish's to improve) and, after the refinement, finds the map final when it already
    sends every face of A onto a face of B one to one (the spectral pass's region choice
    would keep it, and the finish has nothing to do).
    """

    name = "faces"
    runs_on_final_map = False

    def __init__(self):
        self.attached = False

    def attach(self, state: MatchState) -> None:
        cfg = state.config.finish
        self.attached = cfg.enabled and applies(state.a, state.b, cfg)
        if self.attached:
            state.hooks.on("stop_refining", lambda f: qualifies(state.a, state.b, f, cfg))

    def final_after(self, state: MatchState, name: str) -> str | None:
        if not (self.attached and name == "refine"):
            return None
        assert state.f is not None  # the refinement, which just ran, set it
        if face_handles(state.a, state.b, state.f).all():
            return "HOPE's map already sends every face of A onto a face of B, one to one"
        return None

    def skip_reason(self, state: MatchState):
        cfg = state.config.finish
        if not cfg.enabled:
            return "turned off (shared_faces=False)"
        if not applies(state.a, state.b, cfg):
            return f"a shape has more than {cfg.max_vertices} vertices"
        return None

    def run(self, state: MatchState) -> None:
        a, b, cfg = state.a, state.b, state.config.finish
        t = state.log.start("faces", detail="shared-face finish")
        clock = StepClock()
        f, rounds = finish(
            a, b, state.f, cfg, refine=state.config.refine, clock=clock, k_max=state.config.k_max
        )
        if rounds:
            state.timings["faces"] = time.perf_counter() - t
            clock.record(state.timings, "faces")
            state.log.ran(
                "faces",
                state.timings["faces"],
                f"{rounds} rounds, then growth from trusted patches",
            )
            state.f = f
            return
        share = float(face_handles(a, b, f).mean())
        state.log.skipped(
            "faces",
            f"not applicable: {share:.1%} of A's vertices have all their faces mapped "
            f"onto faces of B (the finish needs {cfg.min_handles:.0%} and patches to grow from)",
        )
