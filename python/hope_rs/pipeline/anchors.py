"""A global step for HOPE: re-place untrusted vertices by their geodesic distances to witnesses.

HOPE's k-hop steps move a vertex only as far as the witnesses in its k-ball reach, so a region
whose initial matches are all wrong (a limb mapped to the wrong side) is won back a few hops per
pass. Geodesic distance to a spread of trusted correspondences ("anchors") is an intrinsic
coordinate both shapes share, whatever their triangulations: matching untrusted vertices by
these coordinates repairs such regions in one step, and the k-hop steps then sharpen the result.
The same coordinates also expose what LMD cannot see: a region mapped consistently onto its
mirror image keeps its 2-rings but not its distances to the rest of the shape (``global_check``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from .. import _core
from .._blas import single_threaded_blas
from ..shape import Shape
from .config import RepairConfig

__all__ = [
    "AnchorPlacement",
    "agree",
    "anchor_step",
    "core_fields",
    "distance_fields",
    "drop_disagreeing_anchors",
    "farthest_witnesses",
    "firm_regions",
    "masked_components",
    "reachable",
    "shift_lower_bound",
    "swapped_regions",
]


def distance_fields(shape: Shape, sources) -> np.ndarray:
    """Edge-graph distances / sqrt(area) from each source to every vertex, (len(sources), n)."""
    src = np.atleast_1d(np.asarray(sources, dtype=np.int64))
    return shape.graph.distance_fields(src) / shape.scale


def _nearest_region(a: Shape, firm: np.ndarray, label: np.ndarray) -> np.ndarray:
    """The label of the nearest (in hops) firm vertex of every vertex of A; -1 if none."""
    e = a.edges
    n = a.n_vertices
    graph = sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, _, source = dijkstra(
        graph,
        directed=False,
        indices=np.flatnonzero(firm),
        unweighted=True,
        min_only=True,
        return_predecessors=True,
    )
    return np.where(source >= 0, label[np.maximum(source, 0)], -1)


def farthest_witnesses(a: Shape, candidates: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` farthest-point samples of ``candidates`` on A and their distance fields (n, n_a)."""
    # Start at the candidate nearest the centroid: a choice that does not depend on vertex
    # numbering, so relabelling the meshes relabels the result.
    v = a.points[candidates]
    start = int(candidates[np.argmin(((v - v.mean(axis=0)) ** 2).sum(axis=1))])
    # Each next sample is the candidate farthest from all before it (the first of equal ones;
    # other components count as -1), searched in Rust: only the region a new sample takes
    # over is searched to update the nearest-sample distance, and the samples' full fields
    # are then searched in parallel.
    chosen, fields = a.graph.farthest_fields(
        np.ascontiguousarray(candidates, dtype=np.int64), start, n, a.scale
    )
    return chosen, fields / a.scale


def reachable(d: np.ndarray, config: RepairConfig = RepairConfig()) -> np.ndarray:
    """Distance fields with unreachable vertices (other components) at ``config.unreachable``:
    far, not infinitely far."""
    return np.where(np.isfinite(d), d, config.unreachable)


def drop_disagreeing_anchors(
    f: np.ndarray,
    anchors: np.ndarray,
    da: np.ndarray,
    db: np.ndarray,
    config: RepairConfig = RepairConfig(),
):
    """``(anchors, da, db)`` without the anchors whose distances to at least half of the other
    anchors disagree between A and B under ``f`` (mapped wrongly themselves), unless fewer
    than four would remain."""
    good = agree(da[:, anchors], db[:, f[anchors]], config).mean(axis=1) >= 0.5
    if good.sum() >= 4:
        return anchors[good], da[good], db[good]
    return anchors, da, db


def agree(da: np.ndarray, db: np.ndarray, config: RepairConfig = RepairConfig()) -> np.ndarray:
    """Whether geodesic distances on A and their counterparts on B agree (sqrt(area) units):
    within ``config.agree_rel`` of the distance plus ``config.agree_abs``, since poses of one body
    stretch geodesics by a few percent."""
    return np.abs(da - db) < config.agree_rel * da + config.agree_abs


def anchor_step(
    a: Shape,
    b: Shape,
    f: np.ndarray,
    trusted: np.ndarray,
    *,
    global_check: bool = False,
    config: RepairConfig = RepairConfig(),
    fixed: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """``f`` with every untrusted vertex moved to the vertex of B whose geodesic distances to
    the anchors' images are closest to its own distances to the anchors.

    Anchors are ``config.n_anchors`` farthest-point samples among the trusted vertices; distances
    are Dijkstra distances on the edge graphs (searched in parallel in Rust) divided by
    sqrt(area). With fewer than four trusted vertices ``f`` is returned unchanged.

    With ``global_check``, trust must also hold at the scale of the whole shape. LMD looks at
    2-rings only, so a region mapped consistently onto its mirror image (a left arm onto the
    right arm) passes it everywhere. Its distances to the rest of the shape do not survive the
    map, though: anchors whose distances to most other anchors disagree are dropped, and a
    vertex stays trusted only when its distances to at least ``config.global_min_agree`` of the
    remaining anchors agree. The check acts only when it flags at least
    ``config.global_min_flagged`` of the trusted vertices (a region, not scattered stretch), and
    a vertex it flags moves only as far as a mirror image lies (``config.flagged_min_shift``).

    ``fixed``: the distance fields on A and on B ((m, n_a), (m, n_b), already
    :func:`reachable`) of anchors known to be right (the caller's landmarks), used besides the
    farthest-point ones and never dropped.
    """
    cand = np.flatnonzero(trusted)
    if cand.size < 4 or (cand.size == trusted.size and not global_check):
        return f
    anchors, da = farthest_witnesses(a, cand, config.n_anchors)
    db = distance_fields(b, f[anchors])
    da, db = reachable(da, config), reachable(db, config)
    flagged = None
    if global_check:
        anchors, da, db = drop_disagreeing_anchors(f, anchors, da, db, config)
    if fixed is not None:
        da, db = np.vstack([fixed[0], da]), np.vstack([fixed[1], db])
    if global_check:
        flagged = trusted & (agree(da, db[:, f], config).mean(axis=0) < config.global_min_agree)
        if flagged.sum() >= config.global_min_flagged * trusted.sum():
            trusted = trusted & ~flagged
        else:
            flagged = None
        if trusted.all():
            return f
    moved = np.flatnonzero(~trusted)
    place = AnchorPlacement(da, db, config.search_dims).place(moved)
    if flagged is not None:
        keep = ~flagged[moved] | (shift_lower_bound(db, f[moved], place) > config.flagged_min_shift)
        moved, place = moved[keep], place[keep]
        if moved.size == 0:
            return f
    g = f.copy()
    g[moved] = place
    return g


def shift_lower_bound(db: np.ndarray, old: np.ndarray, new: np.ndarray) -> np.ndarray:
    """A lower bound of the distance between each pair of vertices ``old[i]``, ``new[i]`` of B,
    from their distances ``db`` (anchors × n_b) to the anchors (triangle inequality)."""
    return np.abs(db[:, old] - db[:, new]).max(axis=0)


class AnchorPlacement:
    """Places vertices of A on B by their distances to anchors: ``da`` (anchors × n_a) holds
    the distances from the anchors on A, ``db`` (anchors × n_b) those from their images."""

    def __init__(self, da: np.ndarray, db: np.ndarray, search_dims: int = RepairConfig.search_dims):
        self.da = da
        db = db.T
        self.mu = db.mean(axis=0)
        centred = db - self.mu
        with single_threaded_blas():
            _, vecs = np.linalg.eigh(centred.T @ centred)
        self.basis = vecs[:, ::-1][:, :search_dims]
        self.points = np.ascontiguousarray(centred @ self.basis)
        # Queries lie far from B's points (A's distances are not B's), where a k-d tree
        # visits many cells per query, more the finer the mesh. An exact search among point
        # clusters (Rust) answers instead; queries whose two nearest points tie up to rounding
        # go to the k-d tree, so every answer equals the k-d tree's.
        self.clusters = _core.PointClusters(self.points)
        self._tree: cKDTree | None = None

    def place(self, moved: np.ndarray) -> np.ndarray:
        """For each vertex ``moved`` of A, the vertex of B whose distances to the anchors'
        images are nearest its own distances to the anchors."""
        x = np.ascontiguousarray((self.da[:, moved].T - self.mu) @ self.basis)
        q, near_tie = self.clusters.nearest(x)
        if near_tie.any():
            if self._tree is None:
                self._tree = cKDTree(self.points)
            q[near_tie] = self._tree.query(x[near_tie], workers=2)[1]
        return q


def firm_regions(a: Shape, firm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(label, sizes)``: the connected components of A's ``firm`` vertices (joined by edges
    between firm vertices), ``label`` -1 elsewhere, and each component's vertex count."""
    return masked_components(a.edges, a.n_vertices, firm)


def masked_components(edges: np.ndarray, n: int, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`firm_regions` on the graph of ``n`` vertices and undirected ``edges``."""
    keep = mask[edges[:, 0]] & mask[edges[:, 1]]
    graph = sp.csr_matrix(
        (np.ones(int(keep.sum())), (edges[keep, 0], edges[keep, 1])), shape=(n, n)
    )
    _, label = connected_components(graph, directed=False)
    label[~mask] = -1
    return label, np.bincount(label[mask])


def core_fields(
    a: Shape, b: Shape, f: np.ndarray, core: np.ndarray, config: RepairConfig = RepairConfig()
) -> tuple[np.ndarray, np.ndarray]:
    """``(da, db)``: distance fields on A of ``config.n_anchors`` farthest-point anchors among
    the ``core`` vertices, and on B of their images under ``f``, without the anchors that
    disagree with the others (:func:`drop_disagreeing_anchors`); ``db`` not yet
    :func:`reachable`."""
    anchors, da = farthest_witnesses(a, np.flatnonzero(core), config.n_anchors)
    db = distance_fields(b, f[anchors])
    _, da, db = drop_disagreeing_anchors(f, anchors, da, db, config)
    return da, db


def swapped_regions(
    a: Shape,
    b: Shape,
    f: np.ndarray,
    consistent: np.ndarray,
    config: RepairConfig = RepairConfig(),
    fixed: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """``f`` with every region that is mapped consistently but to the wrong place moved back.

    Two hands that touch in one pose and not in the other get swapped (TOSCA remeshed david
    and victoria: each hand carried onto the other, its 2-rings intact). The global check of
    :func:`anchor_step` misses them: its anchors are spread over every trusted vertex, hands
    included, and a hand is under ``config.global_min_flagged`` of the shape. Here the regions
    are the components of the vertices LMD trusts firmly (``config.region_consistent`` of their
    2-ring; ``consistent`` is that fraction per vertex), since a swapped region joins the rest
    along a seam of vertices with inconsistent neighbours. The largest region holds the
    anchors, and another region moves to its place by anchor distances
    (:class:`AnchorPlacement`) when that raises its share of agreeing anchor distances by
    ``config.region_min_gain`` and the place is ``config.region_min_shift`` away: every placement by
    anchors agrees better, since it is chosen to, but only a wrong region moves far. ``fixed``:
    see :func:`anchor_step`.
    """
    firm = consistent >= config.region_consistent
    if firm.sum() < 4:
        return f
    label, sizes = firm_regions(a, firm)
    core = int(np.argmax(sizes))
    others = [c for c in np.flatnonzero(sizes >= config.region_min_size) if c != core]
    if sizes[core] < 4 or not others:
        return f
    da, db = core_fields(a, b, f, label == core, config)
    # Regions of other mesh components than the anchors' have no distances to compare.
    others = [c for c in others if np.isfinite(da[:, label == c]).all()]
    if not others:
        return f
    db = reachable(db, config)
    if fixed is not None:
        da, db = np.vstack([fixed[0], da]), np.vstack([fixed[1], db])
    placement = AnchorPlacement(da, db, config.search_dims)
    owner = None
    g = f.copy()
    for c in others:
        v = np.flatnonzero(label == c)
        p = placement.place(v)
        now = agree(da[:, v], db[:, f[v]], config).mean()
        there = agree(da[:, v], db[:, p], config).mean()
        shift = np.median(shift_lower_bound(db, f[v], p))
        if there - now > config.region_min_gain and shift > config.region_min_shift:
            # The region also takes the seam vertices nearer to it than to any other region
            # (in hops): moved without them, the wrong half of its seam pulls it back in the
            # next k-hop step.
            if owner is None:
                owner = _nearest_region(a, firm, label)
            grown = np.flatnonzero(owner == c)
            g[grown] = placement.place(grown)
    return g if (g != f).any() else f
