"""Every setting of :func:`hope_rs.match`, as data: one frozen dataclass per stage in
:class:`MatchConfig`.

The defaults are the method's one parameter set for all data; ``docs/decisions.md`` keeps,
per setting, what else was tried. A config is printable, comparable and hashable, and
:meth:`MatchConfig.key` is what caches and result files are keyed by.

>>> from hope_rs import MatchConfig
>>> cfg = MatchConfig().with_options(top_k=32, spectral=False)
>>> cfg.refine.top_k, cfg.spectral.enabled
(32, False)
>>> MatchConfig() == MatchConfig()
True
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib
import json
import math
import numbers
from dataclasses import dataclass, field
from types import ModuleType

import numpy as np

from ..kernels.search import SearchConfig
from ..shape import ShapeConfig
from .config_checks import check_config

# Imported by name: mypy's target (3.10) has no tomllib, and tomli may or may not be there.
tomllib: ModuleType | None
try:
    tomllib = importlib.import_module("tomllib")
except ImportError:  # Python < 3.11: the tomli backport, when installed
    try:
        tomllib = importlib.import_module("tomli")
    except ImportError:
        tomllib = None

#: The descriptors an initial map can compare.
INIT_KINDS = ("shot", "wks", "hks")

__all__ = [
    "CONFIDENCE_FEATURES",
    "INIT_KINDS",
    "KEYWORDS",
    "ConfidenceConfig",
    "DenoiseConfig",
    "FinishConfig",
    "GrowthConfig",
    "InitialConfig",
    "LandmarkConfig",
    "MatchConfig",
    "MultiscaleConfig",
    "OrientConfig",
    "PartialConfig",
    "RefineConfig",
    "RepairConfig",
    "ResolutionConfig",
    "SpectralConfig",
    "declared",
    "read_config",
]


@dataclass(frozen=True)
class InitialConfig:
    """The initial map: each vertex's nearest descriptor (:mod:`hope_rs.pipeline.initial`).

    Attributes
    ----------
    descriptor : {"shot", "wks", "hks"}
        Descriptors compared (``match(init=...)``).
    search : SearchConfig
        The nearest-descriptor search (PCA dimensions, exact vs inverted-file search).
    """

    descriptor: str = field(default="shot", metadata={"choices": INIT_KINDS})
    search: SearchConfig = field(default_factory=SearchConfig)


@dataclass(frozen=True)
class LandmarkConfig:
    """What the caller's landmarks (``match(landmarks=...)``) do besides being mapped exactly
    (:mod:`hope_rs.pipeline.landmarks`); unused without landmarks.

    A vertex's distances to the landmarks (edge-graph geodesics, sqrt(area) units) are its
    landmark coordinates. A match is *off* when the RMS difference between the coordinates of
    a vertex and of its match exceeds, by more than ``max_gap``, the least any vertex of B
    achieves: a region mapped onto its mirror image trades its distances to the left and right
    landmarks, which pose and remeshing stretch far less.

    Attributes
    ----------
    max_gap : float
        The margin above (sqrt(area) units, RMS over the landmarks).
    init : bool
        The "landmarks" stage re-places every off match of the initial map ...
    candidates : int
        ... at the nearest descriptor among the vertices of B whose landmark coordinates are
        the nearest this many to the vertex's own.
    refine_trust : bool
        An off match is never a witness of the refinement (not applied in a part's own
        matches, whose distances to the landmarks run around the missing region:
        docs/decisions.md#landmarks).
    swap_anchors : bool
        The refinement's swapped-region step takes the landmarks as anchors (what moves a
        mirrored region back).
    repair_anchors : bool
        The global repair takes them as anchors too. Off: on non-isometric pairs the
        landmarks' distance fields bend with the shape and the repair re-placed right
        matches by them (docs/decisions.md#landmarks).
    zoomout_weight : float
        The spectral pass's ZoomOut matches each vertex by its spectral embedding extended by
        its landmark coordinates times this weight, each landmark's field first scaled to
        the same mean over A and over B (a non-isometric pair stretches the distances from
        one landmark more than from another); 0 leaves ZoomOut as without landmarks.
    near_weight : float
        ZoomOut's embedding also gets, per landmark, ``max(near_radius - d, 0)`` times this
        weight, ``d`` the scaled field above: steep coordinates within ``near_radius`` of a
        landmark that are zero farther away. Near a landmark its own distance stretches
        little between the shapes, while the distances to the far landmarks stretch with
        whole limbs and the spectral embedding pulls a limb end that is larger on A than on
        B up the limb of B; these coordinates keep the vertices around each landmark at
        their distance from it. 0: none. Used only when ``zoomout_weight > 0``.
    near_radius : float
        The radius above (sqrt(area) units, the scaled fields').
    max_coordinates : int
        At most this many landmarks give the landmark coordinates (of the "landmarks" stage,
        the refinement's trust and swapped-region anchors, ZoomOut's extra columns): farthest
        points among A's landmarks, the one farthest from A's centroid first. Every landmark
        stays mapped exactly. Each coordinate costs a distance field on both shapes and a
        dimension of every search, so hundreds of landmarks (a sparse correspondence) would
        slow a match many times over (docs/decisions.md#landmarks).
    """

    max_gap: float = 0.25
    init: bool = True
    candidates: int = 64
    refine_trust: bool = True
    swap_anchors: bool = True
    repair_anchors: bool = False
    # A weight of inf would make every coordinate inf or NaN: check_config refuses it.
    zoomout_weight: float = field(default=3.0, metadata={"finite": True})
    near_weight: float = field(default=90.0, metadata={"finite": True})
    near_radius: float = field(default=0.2, metadata={"finite": True})
    max_coordinates: int = field(default=128, metadata={"range": (1, 100_000)})


@dataclass(frozen=True)
class RepairConfig:
    """The global repair of each refinement pass (:mod:`hope_rs.pipeline.anchors`).

    Distances are edge-graph geodesics in sqrt(area) units (docs/decisions.md#global-repair).

    Attributes
    ----------
    n_anchors : int
        Farthest-point anchors among the witnesses.
    search_dims : int
        Principal axes of the anchor coordinates kept for the neighbour search.
    unreachable : float
        Stands in for the distance to a vertex of another component.
    agree_rel, agree_abs : float
        Two geodesic distances agree within ``agree_rel`` of their length plus ``agree_abs``.
    global_min_agree : float
        The global check keeps a vertex trusted when it agrees with this share of the anchors ...
    global_min_flagged : float
        ... and acts only when it flags at least this share of the trusted vertices.
    flagged_min_shift : float
        A flagged vertex moves only this far at least (a mirrored region moves far).
    region_consistent : float
        A swapped region is a component of vertices with this share of their 2-ring consistent ...
    region_min_size : int
        ... of at least this many vertices; it moves when its share of agreeing anchor
        distances rises by ``region_min_gain`` ...
    region_min_gain : float
    region_min_shift : float
        ... and its median vertex moves at least this far.
    """

    n_anchors: int = field(default=32, metadata={"range": (0, 10_000)})
    search_dims: int = field(default=12, metadata={"range": (1, 1024)})
    unreachable: float = 4.0
    agree_rel: float = 0.1
    agree_abs: float = 0.03
    global_min_agree: float = 0.7
    global_min_flagged: float = 0.1
    flagged_min_shift: float = 0.15
    region_consistent: float = 0.7
    region_min_size: int = 10
    region_min_gain: float = 0.2
    region_min_shift: float = 0.3


@dataclass(frozen=True)
class RefineConfig:
    """HOPE's refinement (:mod:`hope_rs.pipeline.refine`); passes are 0-based.

    Attributes
    ----------
    schedule : tuple of int or None
        Hop radii of one pass; ``None``: k_max → 1 (docs/decisions.md#schedule).
    max_passes : int
        Passes of the schedule at most (docs/decisions.md#stopping).
    pass_k_max : tuple of (int or None) or None
        Per pass, the largest hop radius of the schedule it runs (its last entry for every
        later pass; ``None`` in it: the whole schedule); ``None``: every pass runs the whole
        schedule (docs/decisions.md#schedule).
    min_consistent : float
        LMD's witness rule: the share of a vertex's 2-ring that must keep its distances
        (docs/decisions.md#lmd); the spectral pass's anchors use it too.
    top_k : int
        Candidates kept per row of every overlap cost (the polish's and the finish's too).
    min_witness_fraction : float
        Below this share of witnesses every vertex votes.
    polish_k : int or None
        Hop radius of the last, not one-to-one step (at most ``MatchConfig.k_max``: a larger
        one runs at ``k_max``); ``None``: no polish (docs/decisions.md#polish).
    global_step : bool
        Start each pass with the global repair (docs/decisions.md#global-repair).
    converged_fraction : float
        Stop after a pass that changed fewer than this share of the vertices.
    min_untrusted_drop : float
        With the global step, stop (from pass ``untrusted_drop_pass`` on) when a pass shrank
        the share of untrusted vertices by less than this fraction of itself.
    untrusted_drop_pass : int
    global_check_pass : int
        From this pass on the repair also checks long-range distances.
    region_check_pass : int
        From this pass on each pass first moves back swapped regions.
    stay_pass, stay_counts : int
        From pass ``stay_pass`` on a witness's current match is worth ``stay_counts`` more
        overlap counts (docs/decisions.md#stay).
    auction_floor_div : int
        First auction epsilon at least (value range) / this (docs/decisions.md#auction).
    nearest_unused_k : int
        Unused vertices ranked per group of duplicates beyond twice its size when the
        refinement completes a map to a one-to-one one.
    max_turned : float or None
        A vertex more than this share of whose triangles' area the map turns over
        (:mod:`hope_rs.pipeline.turned`) does not vote in the k-hop steps and the polish (the
        ``min_witness_fraction`` rule is judged before); ``None``: the orientation is not
        checked. The partial stage sets it for a part's matches
        (``PartialConfig.max_turned``).
    repair : RepairConfig
    """

    schedule: tuple[int, ...] | None = None
    max_passes: int = field(default=4, metadata={"range": (1, None)})
    pass_k_max: tuple[int | None, ...] | None = None
    min_consistent: float = field(default=0.5, metadata={"range": (0.0, 1.0)})
    # Column counts are 32-bit in the Rust core.
    top_k: int = field(default=48, metadata={"range": (1, 2**31 - 1)})
    min_witness_fraction: float = 0.1
    polish_k: int | None = field(default=3, metadata={"range": (1, 64)})
    global_step: bool = True
    converged_fraction: float = 0.01
    min_untrusted_drop: float = 0.1
    untrusted_drop_pass: int = 3
    global_check_pass: int = 1
    region_check_pass: int = 1
    stay_pass: int = 2
    stay_counts: int = field(default=1, metadata={"range": (0, 1000)})
    auction_floor_div: int = field(default=16, metadata={"range": (1, None)})
    nearest_unused_k: int = field(default=16, metadata={"range": (1, None)})
    max_turned: float | None = None
    repair: RepairConfig = field(default_factory=RepairConfig)

    def __post_init__(self):
        _check_share("RefineConfig.max_turned", self.max_turned)
        if self.pass_k_max is not None:
            caps = self.pass_k_max
            with contextlib.suppress(TypeError):  # not a sequence: the check below says so
                caps = tuple(caps)
                object.__setattr__(self, "pass_k_max", caps)
            if not (
                isinstance(caps, tuple)
                and caps
                and all(k is None or (_is_count(k) and k >= 1) for k in caps)
            ):
                raise ValueError(
                    "RefineConfig.pass_k_max must be None or a non-empty sequence of hop radii "
                    f">= 1 or None, got {self.pass_k_max!r}"
                )
        # A tuple, so that the config stays hashable whatever sequence was given.
        if self.schedule is not None and not isinstance(self.schedule, (tuple, str, bytes)):
            # A string stays one, for match's option check to refuse as a string.
            with contextlib.suppress(TypeError):  # not a sequence: match's option check says so
                object.__setattr__(self, "schedule", tuple(self.schedule))


@dataclass(frozen=True)
class SpectralConfig:
    """The spectral pass: ZoomOut from HOPE's map, then a per-region choice of the two
    (:mod:`hope_rs.pipeline.spectral`, docs/decisions.md#spectral).

    Attributes
    ----------
    enabled : bool
    k_start, k_end, k_step : int
        ZoomOut's basis sizes.
    max_samples : int
        ZoomOut iterates on at most this many vertices of each shape ...
    candidates : int
        ... each moved to the best of this many vertices of B around its sample's image.
    local_from, local_candidates : int
        From basis size ``local_from`` on, unsampled shapes search among the
        ``local_candidates`` vertices of B nearest the current image.
    max_vertices : int
        Skipped when a shape has more vertices.
    max_discrepancy_ratio : float
        HOPE's map is kept when the chosen map bends distances to anchors more than this
        factor times HOPE's ...
    max_zoomout_discrepancy_ratio : float
        ... or ZoomOut's own map more than this factor.
    early_from_pass : int
        ZoomOut starts during the refinement's last pass when that pass is at least this one.
    smoothing_steps : int
        Rounds of 1-ring averaging of the distortion difference before the choice.
    margin : float
        HOPE's map is kept where its smoothed distortion exceeds ZoomOut's by at most this
        (A's mean edge lengths).
    slanted : bool
        When one shape is measured at the other's scale (a part, see
        :mod:`hope_rs.pipeline.partial`), ZoomOut fits the smaller shape's first
        k·(its area / the other's) eigenfunctions against the larger's first k
        (:func:`hope_rs.pipeline.spectral.basis_slope`); shapes each in their own units are
        unaffected.
    """

    enabled: bool = True
    k_start: int = field(default=20, metadata={"range": (1, None)})
    k_end: int = field(default=120, metadata={"range": (1, None)})
    k_step: int = field(default=5, metadata={"range": (1, None)})
    max_samples: int = field(default=8000, metadata={"range": (1, None)})
    candidates: int = field(default=32, metadata={"range": (1, None)})
    local_from: int = 60
    local_candidates: int = field(default=64, metadata={"range": (1, None)})
    max_vertices: int = 60_000
    max_discrepancy_ratio: float = 1.1
    max_zoomout_discrepancy_ratio: float = 1.2
    early_from_pass: int = 3
    smoothing_steps: int = field(default=32, metadata={"range": (0, 10_000)})
    margin: float = 0.05
    slanted: bool = True

    def __post_init__(self):
        # Between fields; each field's own range is checked with the others (check_config).
        if not all(_is_count(x) and x >= 1 for x in (self.k_start, self.k_end, self.max_samples)):
            return
        if self.k_start > self.k_end:
            raise ValueError(
                f"SpectralConfig.k_start ({self.k_start}) must be at most k_end ({self.k_end})"
            )
        if self.max_samples < self.k_end:
            # ZoomOut's least-squares fits need at least one sample per basis function.
            raise ValueError(
                f"SpectralConfig.max_samples ({self.max_samples}) must be at least k_end "
                f"({self.k_end})"
            )


@dataclass(frozen=True)
class GrowthConfig:
    """The growth of the shared-face finish (:mod:`hope_rs.pipeline.growth`,
    docs/decisions.md#growth).

    Attributes
    ----------
    seed_share : float
        Handle patches smaller than this share of A's vertices do not seed it ...
    seed_irregular : int
        ... nor those with fewer handles where the triangulation is not a regular lattice
        (``hope_rs.pipeline.handles.irregular_vertices``): a lattice patch may be shifted.
    face_error : float
        Largest triangle shape difference for growing across a face (edge lengths).
    affine_stages : tuple of (accept, ratio)
        Acceptance tests of the affine growth, strict first.
    weight_width : float
        Width of the affine fits' Gaussian weights, relative to the mean squared distance.
    min_known : int
        A vertex is fitted once this many vertices of its 2-ring are mapped.
    rounds : int
        Rounds of growth at most.
    faces_first, affine_first, agreement_order : tuple
        Orders of the growth's steps ("faces" or an index of ``affine_stages``).
    agreement_rounds : int
        Rounds in which the growths from both sides keep what they agree on.
    """

    seed_share: float = 0.02
    seed_irregular: int = 1
    face_error: float = 0.5
    affine_stages: tuple[tuple[float, float], ...] = ((0.35, 2.0), (0.5, 1.5), (0.7, 1.2))
    weight_width: float = 0.7
    min_known: int = 6
    rounds: int = field(default=3, metadata={"range": (0, 1000)})
    faces_first: tuple = ("faces", 0, 1, 2)
    affine_first: tuple = (0, 1, 2, "faces")
    agreement_order: tuple = (0, 1, "faces", 2)
    agreement_rounds: int = field(default=3, metadata={"range": (0, 1000)})

    def __post_init__(self):
        stages = self.affine_stages
        ok = isinstance(stages, (tuple, list)) and all(
            isinstance(s, (tuple, list)) and len(s) == 2 and all(_is_number(x) for x in s)
            for s in stages
        )
        if not ok:
            raise ValueError(
                "GrowthConfig.affine_stages must be (accept, ratio) pairs of numbers, got "
                f"{stages!r}"
            )
        object.__setattr__(self, "affine_stages", tuple(tuple(s) for s in stages))
        steps = ("faces", *range(len(stages)))
        for name in ("faces_first", "affine_first", "agreement_order"):
            order = getattr(self, name)
            if (
                isinstance(order, (str, bytes))
                or not isinstance(order, (tuple, list))
                or not all(
                    (x == "faces" if isinstance(x, str) else _is_count(x) and 0 <= x < len(stages))
                    for x in order
                )
            ):
                raise ValueError(
                    f'GrowthConfig.{name} must be a sequence of steps, each "faces" or an index '
                    f"of affine_stages ({', '.join(map(repr, steps))}), got {order!r}"
                )
            object.__setattr__(self, name, tuple(order))


@dataclass(frozen=True)
class FinishConfig:
    """The shared-face finish (:mod:`hope_rs.pipeline.shared_faces`,
    docs/decisions.md#shared-faces).

    Attributes
    ----------
    enabled : bool
    max_vertices : int or None
        Larger shapes are not finished; ``None``: any size.
    min_handles : float
        Rounds run only while this share of A's vertices are handles.
    rounds : int
        Rounds at most; they stop once the seeded share grows by less than ``min_growth``.
    min_growth : float
    steps, step_k : int
        HOPE steps after each round's snapping, and their hop radius.
    arap_iterations : int
        ARAP's alternations of rotations and the global solve.
    anchor_weight : float
        Pull of each free vertex towards its current image, relative to an edge.
    growth : GrowthConfig
    """

    enabled: bool = True
    max_vertices: int | None = None
    min_handles: float = 0.2
    rounds: int = field(default=10, metadata={"range": (0, 1000)})
    min_growth: float = 0.01
    steps: int = field(default=3, metadata={"range": (0, 1000)})
    step_k: int = field(default=5, metadata={"range": (1, 64)})
    arap_iterations: int = field(default=5, metadata={"range": (0, 1000)})
    anchor_weight: float = 1e-3
    growth: GrowthConfig = field(default_factory=GrowthConfig)


@dataclass(frozen=True)
class MultiscaleConfig:
    """Coarse-to-fine matching (:mod:`hope_rs.pipeline.multiscale`,
    docs/decisions.md#multiscale); the coarsening itself is ``MatchConfig.shape.coarsen``.

    Attributes
    ----------
    enabled : bool or None
        ``None`` (``match``'s default): the path is chosen by size, coarse-to-fine when the
        larger shape has more than ``auto_vertices`` vertices; ``True`` or ``False`` force it.
    auto_vertices : int
        See ``enabled``.
    fine_passes : int
        Refinement passes on the fine meshes after the lift when a mesh has more than
        ``fine_passes_small_vertices`` ...
    fine_schedule : tuple of int or None
        ... with these hop radii (``None``: the refinement's own schedule,
        ``RefineConfig.schedule``) ...
    fine_seed_share : float
        ... and the shared-face finish's growth seeded from handle patches of this share of
        the vertices (``GrowthConfig.seed_share``): after a short pass the right patches
        are many and smaller, and a patch that disagrees with larger ones does not seed.
    fine_passes_small : int
        Passes of the refinement's own schedule on fine meshes of at most
        ``fine_passes_small_vertices`` vertices.
    fine_passes_small_vertices : int
    lift_ridge : float
        Ridge of the lift's local linear fits, relative to the mean squared edge.
    """

    enabled: bool | None = None
    auto_vertices: int = 60_000
    fine_passes: int = field(default=1, metadata={"range": (0, 100)})
    fine_schedule: tuple[int, ...] | None = (3, 2, 1)
    fine_seed_share: float = field(default=0.005, metadata={"range": (0.0, 1.0)})
    fine_passes_small: int = field(default=2, metadata={"range": (0, 100)})
    fine_passes_small_vertices: int = 60_000
    lift_ridge: float = 1e-3

    def __post_init__(self):
        if self.fine_schedule is not None:
            _set_radii(self, "fine_schedule", "MultiscaleConfig.fine_schedule must be None or")


@dataclass(frozen=True)
class ResolutionConfig:
    """Matching at a common resolution (:mod:`hope_rs.pipeline.resolution`,
    docs/decisions.md#resolution).

    Each shape is measured in its own sqrt(area), so its vertex count is its vertex density
    (a part, measured at its whole's scale, covers less than unit area): when one shape has
    more than ``max_ratio`` times the other's density, the denser one is coarsened to about
    the sparser one's density (for two whole shapes, its count) by manifold-keeping edge
    collapses, the whole stage list matches the pair there, and the map is lifted to the
    dense mesh.

    Attributes
    ----------
    enabled : bool
    max_ratio : float
        Density ratio (denser / sparser) above which the denser shape is coarsened; at
        least 1.
    count_tolerance : float
        The coarse copy's vertex count is within this share of its target.
    refine : bool
        After the lift, refine at full resolution: the sparser shape is subdivided (each
        face into four, as often as brings its density nearest the denser one's), the
        pair matched from the lifted map with one pass of ``refine_schedule`` and the
        shared-face finish, and the map carried back to the sparser shape's own vertices.
    refine_schedule : tuple of int
        Hop radii of that pass.
    refine_min_handles : float
        The pass runs only when this share of the vertices are handles of the lifted map
        (:func:`~hope_rs.pipeline.handles.face_handles`): shapes remeshed independently have
        almost none, and there the pass would cost time for nothing.
    refine_patch_share : float
        With ``refine_min_patched``: a handle patch (connected over the edges) counts when it
        holds at least this share of the vertices.
    refine_min_patched : float
        The pass runs only when this share of the vertices lie in handle patches that count:
        a shared triangulation's handles cluster in patches, while the few handles of shapes
        remeshed independently are coincidences scattered in small ones
        (docs/decisions.md#refine-patches).
    refine_seed_share : float
        The shared-face finish of that pass takes handle patches of at least this share of
        the vertices as seeds (``GrowthConfig.seed_share`` there): after one short pass the
        right patches are many and small.
    follow_density : bool
        When A is the denser shape, match again (from the descriptors, or a given start map
        carried there) at a copy of A whose
        vertices lie as B's do: for each vertex of B, the vertex of A nearest the centroid of
        those the first lifted map sends there, every other vertex collapsed into its nearest
        such site; the lift of that match is kept. A template denser at its hands and face
        than a uniform copy of a scan then meets like neighbourhoods there.
    dense_shot : bool
        The copy's SHOT descriptors are those of the dense mesh at the copy's vertices (each
        a vertex of the dense mesh), every dense vertex voting in their supports, rather than
        the copy's own: the copy's few, irregular faces bend its normals and reference
        frames. Not for a copy whose vertices move or that was made on the mesh smoothed (a
        noisy scan), nor for a noisy dense A (:func:`~hope_rs.pipeline.resolution.rough_scan`).
    smooth_rougher : float
        When B is the denser shape, its copy's vertices move to the mean of the dense
        vertices each owns when the copy is more than this many times as rough along its
        normals as A (:func:`~hope_rs.geometry.roughness.normal_roughness`): the noise of a
        noisy dense scan stays at the vertices a copy keeps, no longer small against its
        edges. A copy of a clean surface is about as rough as the other shape or smoother,
        and keeps its vertices on the surface. ``inf``: never. (A dense A is not smoothed:
        measured worse, docs/decisions.md#smooth-rougher.)
    collapse_excess : float
        When the collapses keep more than this many times the copy's target count (a noisy
        scan: a collapse that would turn a face over is refused, and its faces turn over at
        the noise's scale), they are made again on the dense mesh smoothed
        ``collapse_smoothing`` times (each vertex halfway to its 1-ring's centroid), the copy
        keeping its vertices' own positions. ``inf``: never.
    collapse_smoothing : int
        The smoothing steps of that second attempt; 1 to 100.
    judge_rougher : float
        When A is the denser shape and more than this many times as rough along its normals
        as B, each at its own resolution (a noisy scan), the share of A a map turns over
        (the orient stage's trigger and cost, ``MatchQuality.flipped_share``) is measured on
        A's copy, the map read at its vertices: a right map turns a noisy scan's own
        triangles over at random. A clean dense surface is smoother than a sparser one.
        ``inf``: never.
    """

    enabled: bool = True
    max_ratio: float = field(default=2.0, metadata={"finite": True, "range": (1.0, None)})
    count_tolerance: float = field(default=0.05, metadata={"range": (0.0, 1.0), "exclusive": True})
    refine: bool = True
    refine_schedule: tuple[int, ...] = (3, 2, 1)
    refine_min_handles: float = field(default=0.04, metadata={"range": (0.0, 1.0)})
    refine_patch_share: float = field(default=0.001, metadata={"range": (0.0, 1.0)})
    refine_min_patched: float = field(default=0.006, metadata={"range": (0.0, 1.0)})
    refine_seed_share: float = field(default=0.005, metadata={"range": (0.0, 1.0)})
    follow_density: bool = True
    dense_shot: bool = True
    smooth_rougher: float = field(default=1.5, metadata={"range": (1.0, None)})
    collapse_excess: float = field(default=1.25, metadata={"range": (1.0, None)})
    collapse_smoothing: int = field(default=5, metadata={"range": (1, 100)})
    judge_rougher: float = field(default=1.5, metadata={"range": (1.0, None)})

    def __post_init__(self):
        _set_radii(self, "refine_schedule", "ResolutionConfig.refine_schedule must be")


def _set_radii(config, name: str, must: str) -> None:
    """Store ``config.<name>`` as a tuple (hashable whatever sequence was given) and refuse it
    unless it is a non-empty sequence of hop radii >= 1 (check_config leaves tuples to their
    class); ``must`` starts the error message."""
    value = getattr(config, name)
    if not isinstance(value, tuple):
        with contextlib.suppress(TypeError):  # not a sequence: the check below says so
            value = tuple(value)
            object.__setattr__(config, name, value)
    if not (
        isinstance(value, tuple)
        and value
        and all(
            isinstance(k, numbers.Integral) and not isinstance(k, bool) and int(k) >= 1
            for k in value
        )
    ):
        raise ValueError(f"{must} a non-empty sequence of hop radii >= 1, got {value!r}")


def declared(option: str) -> dict:
    """The constraints declared on the config field behind ``match``'s keyword ``option``
    (see :data:`KEYWORDS`): ``range`` (lo, hi; None: unbounded), ``choices``, ``finite``."""
    stage, attr = KEYWORDS[option]
    cls = MatchConfig if stage is None else type(getattr(MatchConfig(), stage))
    return dict(next(f.metadata for f in dataclasses.fields(cls) if f.name == attr))


def _tuples(value):
    """Lists (as JSON and TOML give sequences) as tuples, nested ones included."""
    if isinstance(value, (list, tuple)):
        return tuple(_tuples(v) for v in value)
    return value


def _from_dict(cls, data, path: str):
    """An instance of the config dataclass ``cls`` from a (nested) dict of its fields."""
    if not isinstance(data, dict):
        raise TypeError(f"{path} must be a table of settings, got {type(data).__name__}")
    fields = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ValueError(
            f"{path} has no setting {unknown[0]!r}; its settings are {', '.join(fields)}"
        )
    default = cls()
    optional = {f.name for f in dataclasses.fields(cls) if "None" in str(f.type)}
    values = {}
    for name, value in data.items():
        ref = getattr(default, name)
        if dataclasses.is_dataclass(ref):
            values[name] = _from_dict(type(ref), value, f"{path}.{name}")
        else:
            values[name] = _tuples(_nones(value) if name in optional else value)
    return cls(**values)


def _nones(value):
    """A setting that may be ``None`` read from TOML, which has no null: the string "none"
    (any case) is ``None``, also as an entry of a list (``pass_k_max = [8, "none"]``)."""
    if isinstance(value, str) and value.lower() == "none":
        return None
    if isinstance(value, list):
        return [_nones(v) for v in value]
    return value


def read_config(path) -> MatchConfig:
    """The :class:`MatchConfig` of a TOML settings file: tables nested as :meth:`MatchConfig.to_dict`
    nests the stages (``k_max = 6`` at the top, ``[refine]`` ``max_passes = 2``, ...); what the
    file leaves out keeps its default. Needs Python 3.11+ (``tomllib``) or the ``tomli``
    package."""
    if tomllib is None:
        raise ValueError(
            f"reading the settings file {str(path)!r} needs Python 3.11 or later, or the tomli "
            "package (pip install tomli)"
        )
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
        # A byte-order mark some editors write is not TOML.
        data = tomllib.loads(raw.decode("utf-8-sig"))
    except FileNotFoundError:
        raise FileNotFoundError(f"no such settings file: {str(path)!r}") from None
    except IsADirectoryError:
        raise ValueError(f"settings file {str(path)!r} is a folder; give a .toml file") from None
    except UnicodeDecodeError:
        raise ValueError(f"settings file {str(path)!r} is not UTF-8 text (TOML)") from None
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"settings file {str(path)!r} is not valid TOML: {e}") from None
    try:
        return MatchConfig.from_dict(data)
    except (TypeError, ValueError) as e:
        raise type(e)(f"settings file {str(path)!r}: {e}") from None


def settings_json(obj) -> str:
    """``obj`` (settings: dicts, lists, numbers, strings) as JSON text that equal settings
    share: keys sorted, NumPy scalars as numbers, and a whole float written as the int it
    equals (``0.0`` as ``0``), since ``MatchConfig(min_piece=0) == MatchConfig(min_piece=0.0)``."""
    return json.dumps(_whole_floats_as_ints(obj), sort_keys=True, default=json_default)


def _whole_floats_as_ints(x):
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and math.isfinite(x) and x.is_integer():
        return int(x)
    if isinstance(x, dict):
        return {k: _whole_floats_as_ints(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_whole_floats_as_ints(v) for v in x]
    return x


def json_default(x):
    """What ``json`` writes for a value it cannot (``json.dumps(..., default=json_default)``):
    a NumPy scalar as its Python number (``np.int64(32)`` like ``32``), another sequence as a
    list."""
    return x.item() if isinstance(x, np.generic) else list(x)


def _is_number(x) -> bool:
    """Whether ``x`` is a finite real number (``bool`` is not one)."""
    return not isinstance(x, bool) and isinstance(x, numbers.Real) and math.isfinite(x)


def _is_count(x) -> bool:
    """Whether ``x`` is an integer (``bool`` is not one)."""
    return isinstance(x, numbers.Integral) and not isinstance(x, bool)


def _check_share(name: str, value) -> None:
    """A one-line error unless ``value`` is ``None`` or a number in (0, 1]."""
    if value is not None and not (_is_number(value) and 0.0 < value <= 1.0):
        raise ValueError(f"{name} must be None or a number in (0, 1], got {value!r}")


def _positive_numbers(name: str, value) -> tuple[float, ...]:
    """``value`` as a tuple of finite positive floats, or a one-line error naming the field."""
    try:
        if isinstance(value, (str, bytes)):
            raise TypeError
        out = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        raise TypeError(
            f"PartialConfig.{name} must be a sequence of positive numbers, got {value!r}"
        ) from None
    if not all(math.isfinite(x) and x > 0 for x in out):
        raise ValueError(f"PartialConfig.{name} must be positive numbers, got {value!r}")
    return out


@dataclass(frozen=True)
class PartialConfig:
    """Matching a part of a shape (:mod:`hope_rs.pipeline.partial`).

    Attributes
    ----------
    enabled : bool
        Detect a part and measure both shapes at the whole's scale (the shapes must be in the
        same units).
    min_boundary_excess : float
        A shape is a part of the other when its boundary is longer than the other's by at
        least this, each in units of its own sqrt(area) (a plane cut through a human torso is
        about 0.6, one geodesic hole of 3% of the area about 0.6, a closed shape 0).
    max_whole_boundary : float
        ... and the other's boundary is at most this long (two cut shapes are not a part
        and its whole).
    whole_to_part : {"reverse", "direct"}
        When B is the part: "reverse" matches B → A and inverts the map (each vertex of A
        takes the vertex of B whose image is nearest; a given initial map of A onto B starts
        that match inverted); "direct" matches A → B like any pair, with B at A's scale.
    counterpart_edges : float
        With "reverse", a vertex of A has a counterpart on B when the nearest image of a
        vertex of B lies within this many of A's mean edge lengths.
    counterpart_gaps : float
        With "reverse", the vertices of A without a counterpart by ``counterpart_edges`` that
        form a connected patch of fewer than this share of A's vertices have one too: where
        the part's map is locally many-to-one its images leave such gaps; the part's missing
        side and its holes are larger. 0: no gap filled.
    rescale_tolerance : float
        A part (A) is first matched at the larger sqrt(area) of the two; when the share of B
        its map covers puts A's whole at a scale off by more than this fraction, A is matched
        again at that scale (shapes of one class in different units, people of different
        sizes).
    min_covered : float
        The covered share is taken as at least this (a map gone wrong covers little).
    scale_trials : tuple of float
        A part (A) is also matched at these multiples of the guessed scale. Which region of
        the whole a part's refinement settles on changes with small changes of its scale, and
        regions can settle where the whole has no counterpart (the part has no other side to
        compete for them); of all the maps, their merge (``merge_rings``) refined once more
        included, the one with the highest mean confidence is kept. Empty: one match at the
        guessed scale (and at the covered share's scale, see ``rescale_tolerance``), the one
        whose descriptors lie nearer their images kept.
    merge_rings : int
        With ``scale_trials``, each vertex of the merge takes its image from the map whose
        confidence, averaged over this many rounds of 1-ring averaging, is highest there.
    wide_trials : tuple of float
        With ``scale_trials``, when no map so far (the merge included) reaches a mean
        confidence of ``wide_below``, the part is also matched at these multiples of the
        guessed scale: a few percent of scale can move the refinement into another basin, and
        a part that went wrong is worth a wider search. Empty: no wider search.
    wide_below : float
        See ``wide_trials`` (a mean confidence in [0, 1]).
    wide_margin : float
        A map of ``wide_trials`` is kept only when its mean confidence exceeds the best of the
        other maps by at least this: the confidence of maps of one part varies by about this
        much between scales whether or not they are right.
    placement_trials : int
        With ``scale_trials``, when the map kept so far is flagged
        (``MatchQuality.likely_failed``) or its mean confidence is below ``placement_below``,
        and neither landmarks nor an initial map are given, the part is also matched
        from this many starts, each confined to one region of the whole around one of as many
        centres spread over it (:mod:`hope_rs.pipeline.placement`): a part can settle, at any
        scale, on a region that looks like its counterpart (the front half of a quadruped on
        the hind half, a person upside down). 0: none.
    placement_share : float
        Each region holds this multiple of the part's share of the whole's area (a smaller
        region than the part's counterpart: the start is then one distinctive piece of it, and
        the refinement grows the map from there).
    placement_below : float
        See ``placement_trials`` (a mean confidence in [0, 1]; a part's map that is wrong over
        most of its area can keep distances well enough to read above the flag's bar).
    placement_margin : float
        A map of ``placement_trials`` is kept only when its mean confidence exceeds the kept
        map's by at least this.
    max_turned : float or None
        The part's matches run with ``RefineConfig.max_turned`` at this value: a vertex whose
        triangles the map mostly turns over does not vote. With nothing on the part to fill
        the whole's missing side, a branch of the part can settle on another branch of the
        whole wound the other way (a leg laid over the other leg's place and the torso),
        keeping its distances; ``None``: the refinement's own setting. A whole matched
        directly to its part (``whole_to_part="direct"``) keeps the refinement's own setting
        too.
    rough_smoothing : int
        The part's sqrt(area) for the guessed scale is measured on its copy smoothed this many
        times (each vertex halfway to its 1-ring's centroid) when that shrinks it by more
        than ``inflated``: vertex noise of about a dense scan's edge length inflates its area
        by a third or more, while smoothing shrinks a clean mesh of a few thousand vertices
        or more by a few percent. 0: the part as given.
    inflated : float
        See ``rough_smoothing`` (a share of sqrt(area)).
    """

    enabled: bool = True
    min_boundary_excess: float = 0.3
    max_whole_boundary: float = 0.3
    rescale_tolerance: float = 0.03
    min_covered: float = 0.2
    whole_to_part: str = "reverse"
    counterpart_edges: float = 1.0
    counterpart_gaps: float = field(default=0.002, metadata={"range": (0.0, 1.0)})
    scale_trials: tuple[float, ...] = (0.95, 1.05)
    merge_rings: int = field(default=32, metadata={"range": (0, 10_000)})
    wide_trials: tuple[float, ...] = (0.85, 0.9, 1.1)
    wide_below: float = 0.85
    wide_margin: float = 0.15
    placement_trials: int = field(default=8, metadata={"range": (0, 1000)})
    placement_share: float = field(default=0.5, metadata={"range": (0.0, None), "exclusive": True})
    placement_below: float = 0.6
    placement_margin: float = 0.05
    max_turned: float | None = 0.5
    rough_smoothing: int = field(default=5, metadata={"range": (0, 100)})
    inflated: float = field(default=0.15, metadata={"range": (0.0, 1.0)})

    def __post_init__(self):
        _check_share("PartialConfig.max_turned", self.max_turned)
        for name in ("scale_trials", "wide_trials"):
            object.__setattr__(self, name, _positive_numbers(name, getattr(self, name)))
        for name in ("wide_below", "wide_margin", "placement_below", "placement_margin"):
            x = getattr(self, name)
            if not (_is_number(x) and 0.0 <= x <= 1.0):
                raise ValueError(f"PartialConfig.{name} must be a number in [0, 1], got {x!r}")
        if self.whole_to_part not in ("reverse", "direct"):
            raise ValueError(
                f"PartialConfig.whole_to_part must be 'reverse' or 'direct', got {self.whole_to_part!r}"
            )


#: The features of :class:`ConfidenceConfig`, in the order of its ``weights``.
CONFIDENCE_FEATURES = (
    "consistent",  # LMD's consistent share of the 2-ring under the final map
    "consistent_smooth",  # the same, averaged over the rings of ``rings``
    "log_distortion_smooth",  # log(floor + LMD's mean distortion), averaged (mean edges)
    "anchor_agreement",  # share of anchors whose geodesic distance the map keeps
    "log_anchor_error_smooth",  # log(floor + mean |d_A - d_B| to the anchors), averaged
    "log_hope_shift_smooth",  # log(floor + distance on B between HOPE's and the final image)
    "log_zoomout_shift_smooth",  # log(floor + the same for ZoomOut's map; 0 without one)
    "log_stretch_smooth",  # log(floor + mean B/A edge-length ratio under the map), averaged
    "pair_consistent",  # the mean of "consistent" over A: how well the whole pair went
)


@dataclass(frozen=True)
class ConfidenceConfig:
    """The per-vertex confidence of the final map (:mod:`hope_rs.pipeline.confidence`).

    A logistic model of the features of :data:`CONFIDENCE_FEATURES`: ``confidence =
    1 / (1 + exp(-(intercept + weights · features)))``. The coefficients are fitted by
    ``scripts/confidence_fit.py`` on matches of training pairs (remeshed FAUST pairs outside
    the benchmark's ``pairs.txt``), "right" meaning a geodesic error of at most 0.05 sqrt(area).

    Attributes
    ----------
    enabled : bool
        Compute ``MatchResult.confidence`` and ``MatchResult.quality``.
    n_anchors : int
        Farthest-point anchors among the LMD-consistent vertices for the long-range features.
    rings : int
        Rounds of 1-ring averaging of the regional features, so that regions, not single
        vertices, lose confidence.
    floor : float
        Added before the logarithm of a distance feature (sqrt(area) units, or A's mean edge
        length for the distortion), so that a zero distance is finite.
    weights : tuple of float
        One coefficient per feature of :data:`CONFIDENCE_FEATURES`.
    intercept : float
    threshold : float
        A vertex counts as confident at this confidence (``MatchQuality.share_confident``).
    failed_mean : float
        ``MatchQuality.likely_failed`` when the mean confidence is below this ...
    failed_share : float
        ... or when fewer than this share of A's vertices are confident ...
    failed_flipped : float
        ... or when the map turns more than this share of A's area over
        (``MatchQuality.flipped_share``).
    turned_weight : float
        A vertex's confidence is multiplied by ``1 - turned_weight * t``, ``t`` the share of
        the area around it (averaged over ``rings``) that the map turns over; 0 turns it off.
    min_vertices : int
        A pair where A or B has fewer vertices than this has confidence 0 everywhere: the
        2-rings span the whole shape and the long-range features have no far anchors, so
        nothing the model reads can tell a right map from a wrong one (a lone triangle
        matched to itself rotated).
    noisy : float
        A shape more than ``denser`` times as dense as the other is judged on its copy
        smoothed ``rough_smoothing`` times when one umbrella smoothing takes more than this
        share of its normal roughness out (:meth:`~hope_rs.Shape.smoothing_drop`: vertex noise
        goes at once, the offsets of smooth curvature barely move). The images of a sparser
        shape's 2-rings lie many short edges apart on a dense scan, whose noisy edge paths
        zigzag: its distances run long and a right map reads as distorted
        (:func:`~hope_rs.pipeline.confidence.judged_shapes`).
    denser : float
        See ``noisy`` (a ratio of vertices per unit area).
    rough_smoothing : int
        See ``noisy``; 0 measures both shapes as they are.
    """

    enabled: bool = True
    n_anchors: int = 32
    rings: int = 16
    floor: float = 0.01
    weights: tuple[float, ...] = (
        0.5473,
        0.2841,
        -2.205,
        1.969,
        -0.6086,
        -0.3411,
        0.09902,
        0.8701,
        5.369,
    )
    intercept: float = -9.623
    threshold: float = 0.5
    failed_mean: float = 0.5
    failed_share: float = 0.5
    failed_flipped: float = 0.3
    turned_weight: float = 0.5
    min_vertices: int = 32
    noisy: float = 0.3
    denser: float = 2.0
    rough_smoothing: int = 5

    def __post_init__(self):
        # Checked here, not when the confidence stage runs after the whole match.
        for name, low, high in (
            ("n_anchors", 1, 10_000),
            ("rings", 0, 10_000),
            ("min_vertices", 0, None),
            ("rough_smoothing", 0, 100),
        ):
            x = getattr(self, name)
            if (
                isinstance(x, bool)
                or not isinstance(x, numbers.Integral)
                or int(x) < low
                or (high is not None and int(x) > high)
            ):
                allowed = f">= {low}" if high is None else f"in [{low}, {high}]"
                raise ValueError(f"ConfidenceConfig.{name} must be an integer {allowed}, got {x!r}")
        try:
            if isinstance(self.weights, (str, bytes)):
                raise TypeError
            weights = tuple(float(w) for w in self.weights)
        except (TypeError, ValueError):
            raise TypeError(
                f"ConfidenceConfig.weights must be a sequence of numbers, got {self.weights!r}"
            ) from None
        if len(weights) != len(CONFIDENCE_FEATURES):
            raise ValueError(
                f"ConfidenceConfig.weights must hold one finite number per feature "
                f"({', '.join(CONFIDENCE_FEATURES)}), got {len(weights)} values"
            )
        bad = [w for w in weights if not math.isfinite(w)]
        if bad:
            raise ValueError(
                f"ConfidenceConfig.weights must hold one finite number per feature, got {bad[0]}"
            )
        object.__setattr__(self, "weights", weights)
        shares = (
            "threshold",
            "failed_mean",
            "failed_share",
            "failed_flipped",
            "turned_weight",
            "noisy",
        )
        for name, fits, span in (
            ("floor", lambda x: x > 0.0, "a finite positive number"),
            ("intercept", lambda x: True, "a finite number"),
            ("denser", lambda x: x >= 1.0, "a finite number >= 1"),
            *((n, lambda x: 0.0 <= x <= 1.0, "a number in [0, 1]") for n in shares),
        ):
            x = getattr(self, name)
            if not (_is_number(x) and fits(x)):
                raise ValueError(f"ConfidenceConfig.{name} must be {span}, got {x!r}")


@dataclass(frozen=True)
class OrientConfig:
    """Repairing a map that turns A over on B (:mod:`hope_rs.pipeline.orientation_repair`).

    Attributes
    ----------
    enabled : bool
        Run the "orient" stage (without landmarks; on a part A matched to a whole, only its
        torn-off trigger, with those of ``torn_hypotheses`` that
        :data:`~hope_rs.pipeline.orientation_repair.PART_HYPOTHESES` allows).
    min_turned : float
        The stage tries other maps when the final map turns more than this share of A's area
        over (``MatchQuality.flipped_share``); a right map of remeshed shapes turns a few
        percent over where the triangulations disagree, more between different bodies.
    on_failed : bool
        The stage also tries other maps when the final map turns less over but the
        confidence's rule flags it (``MatchQuality.likely_failed``), and a hypothesis counts as
        good enough to stop at only when that rule does not flag it.
    hypotheses : tuple of str
        The alternative maps tried ("mirror", "mirror_turned", "reseed": derived from a
        map, the one turning the least over refined; "torn": see ``torn_hypotheses``;
        "reverse": from the match of B to A
        inverted; "wks": the pipeline from WKS; "reverse_wks": from the match of B to A from
        WKS, inverted, kept only when it passes the stop rule), the derived ones first (but
        see ``starts_first_mismatch``), then the others in the order given, until one turns
        at most ``min_turned`` over.
    on_topology : bool
        The stage also tries other maps when neither rule above calls for it but the two
        shapes differ in topology (their Euler characteristics: a topological shortcut, as
        where a hand touches a thigh in a scan, or a handle), which misleads the k-hop balls
        and the geodesic distances near it ...
    topology_hypotheses : tuple of str
        ... with these hypotheses (as ``hypotheses``) and the same stop rule.
    on_torn : bool
        The stage also tries other maps when neither the turned share, the confidence's rule
        nor the topology calls for it but the map tears a region off the rest
        (:mod:`hope_rs.pipeline.torn`: a region carried to the wrong place with its
        orientation and 2-rings kept, such as a head shifted along the neck); on a part A
        matched to a whole (the partial stage's map) this is the only trigger ...
    torn_hypotheses : tuple of str
        ... with these hypotheses ("torn": every vertex off the core of a mesh component
        with a piece torn off placed by its geodesic distances to anchors in that core, then
        refined; "reverse", for a region too large to place back from the rest: see
        ``hypotheses``; a part tries only those of
        :data:`~hope_rs.pipeline.orientation_repair.PART_HYPOTHESES`) and the same stop rule.
    tear_length : float
        An edge of A is torn when its ends land farther apart on B (in space) than this many
        sqrt(area) of B (never one with an end on A's boundary: a part's rim lands
        loosely) ...
    tear_edges : float
        ... and than this many mean edge lengths of A or of B, the longer (each in its own
        sqrt(area)): on a coarse mesh a right map's edges span more of the surface. A right
        map's widest edges span a few edges.
    min_torn : float
        The least share of A's area a piece cut off by torn edges must cover to count as torn
        off. The share torn off is also a term of the stage's cost, for every trigger
        (``min_torn = 1`` leaves it out).
    seam_rings : int
        1-rings added around the turned-over vertices for the regional hypotheses.
    distortion_weight : float
        Weight of the LMD-inconsistent share of A's vertices (of its copy at the common
        resolution, for a dense A's lifted map) against the turned-over share in the cost the
        stage minimises.
    min_gain : float
        The refined hypothesis replaces the map when it lowers that cost by at least this.
    again : bool
        After each other start, while no refined hypothesis passes the stop rule (at most
        ``min_turned`` turned over, ``min_gain`` cheaper, not flagged), derive the maps from
        the best one too (when it beats the map the stage started
        from, or turns more than ``again_turned`` of A over, and was not derived from yet) and
        refine the least turned-over.
    again_turned : float
        A start's map turning more than this share of A over is a mirror image as a whole:
        composed with B's symmetry it turns back, so its derived maps are tried even though
        it costs more than the stage's own.
    starts_first_mismatch : float
        When the map turns more than ``min_turned`` over or is flagged, and the shapes'
        Laplace–Beltrami spectra differ by more than this
        (:func:`~hope_rs.pipeline.deform.spectral_mismatch` of their first 30 eigenvalues,
        read off the bases this match's spectral pass made: not after a lift from a common
        resolution), the first other start is tried before the maps derived from the stage's
        own map, which it then tries only if no map tried so far passes the stop rule: shapes
        that far from isometric are matched better the other way more often than re-placed
        by their geodesic distances. ``inf``: derived maps first.
    symmetry_rounds : int
        B's symmetry (the match of B's mirror image to B, for "mirror" and "mirror_turned")
        is matched again at most this many times, each time with its turned-over regions
        placed by their geodesic distances to the rest, while it turns more than
        ``symmetry_turned`` of the area over and less than before: the identity keeps every
        distance, and from the midline it can take over a whole side.
    symmetry_turned : float
        The share of the mirror image's area B's symmetry may turn over without another round.
    """

    enabled: bool = True
    min_turned: float = 0.2
    on_failed: bool = True
    hypotheses: tuple[str, ...] = (
        "mirror",
        "mirror_turned",
        "reseed",
        "reverse",
        "wks",
        "reverse_wks",
    )
    on_topology: bool = True
    topology_hypotheses: tuple[str, ...] = ("reseed", "reverse")
    on_torn: bool = True
    torn_hypotheses: tuple[str, ...] = ("torn", "reverse")
    tear_length: float = field(default=0.08, metadata={"range": (0.0, None), "finite": True})
    tear_edges: float = field(default=3.0, metadata={"range": (0.0, None), "finite": True})
    min_torn: float = field(default=0.01, metadata={"range": (0.0, 1.0)})
    seam_rings: int = 2
    distortion_weight: float = field(default=1.0, metadata={"finite": True})
    min_gain: float = field(default=0.02, metadata={"finite": True})
    again: bool = True
    again_turned: float = field(default=0.5, metadata={"range": (0.0, 1.0)})
    starts_first_mismatch: float = field(default=0.15, metadata={"range": (0.0, None)})
    symmetry_rounds: int = field(default=4, metadata={"range": (0, 1000)})
    symmetry_turned: float = field(default=0.05, metadata={"range": (0.0, 1.0)})

    def __post_init__(self):
        known = ("mirror", "mirror_turned", "reseed", "torn", "wks", "reverse", "reverse_wks")
        for name in ("hypotheses", "topology_hypotheses", "torn_hypotheses"):
            value = getattr(self, name)
            bad = [h for h in value if h not in known]
            if isinstance(value, str) or bad:
                raise ValueError(
                    f"OrientConfig.{name} must be a tuple of {', '.join(known)}, got {value!r}"
                )
            object.__setattr__(self, name, tuple(value))
        if not (_is_number(self.min_turned) and 0.0 <= self.min_turned <= 1.0):
            raise ValueError(
                f"OrientConfig.min_turned must be a number in [0, 1], got {self.min_turned!r}"
            )
        r = self.seam_rings
        if isinstance(r, bool) or not isinstance(r, numbers.Integral) or not 0 <= r <= 10_000:
            raise ValueError(f"OrientConfig.seam_rings must be an integer in [0, 10000], got {r!r}")


@dataclass(frozen=True)
class DeformConfig:
    """The deformation-aware pass for non-isometric shapes (:mod:`hope_rs.pipeline.deform`,
    docs/decisions.md#deform).

    Attributes
    ----------
    enabled : bool
    min_mismatch : float
        The pass runs when the shapes' first ``n_eigenvalues`` non-zero Laplace–Beltrami
        eigenvalues at unit area differ by more than this mean |log ratio|
        (:func:`~hope_rs.pipeline.deform.spectral_mismatch`); isometric shapes differ by a
        few hundredths, different bodies by about 0.2; noise or welded shortcuts on an
        isometric copy reach about 0.1, and the pass does not help them.
    n_eigenvalues : int
    iterations : int
        Rounds of deforming A along the map and matching again.
    k_displacement : int
        A's eigenfunctions spanning the displacement (fewer: a smoother deformation).
    k_spectral : int
        Eigenfunctions of the spectral embedding in the nearest-vertex search ...
    spectral_weight : float
        ... and its weight against the coordinates (both at unit area).
    """

    enabled: bool = True
    min_mismatch: float = field(default=0.15, metadata={"finite": True, "range": (0.0, None)})
    n_eigenvalues: int = field(default=30, metadata={"range": (1, 1000)})
    iterations: int = field(default=3, metadata={"range": (1, 100)})
    k_displacement: int = field(default=10, metadata={"range": (1, 1000)})
    k_spectral: int = field(default=40, metadata={"range": (1, 1000)})
    spectral_weight: float = field(default=0.03, metadata={"finite": True, "range": (0.0, None)})


@dataclass(frozen=True)
class DenoiseConfig:
    """Matching a noisy shape on its smoothed copy (:mod:`hope_rs.pipeline.denoise`,
    docs/decisions.md#denoise).

    Attributes
    ----------
    enabled : bool
    min_roughness : float
        A shape is matched on its copy smoothed ``iterations`` times (same numbering, so the
        map is the same array) when its normal roughness
        (:func:`~hope_rs.geometry.roughness.normal_roughness`: the median distance of a
        vertex from its 1-ring's centroid along its normal, in mean edge lengths) is above
        this ...
    min_drop : float
        ... and one smoothing takes more than this share of that roughness out
        (:meth:`~hope_rs.Shape.smoothing_drop`: vertex noise, not curvature; a clean coarse
        mesh is rough by its curvature, which smoothing does not take out). Only between
        shapes of like density (neither more than ``ResolutionConfig.max_ratio`` times as
        dense as the other; a part measured at its whole's scale): a much denser whole goes
        through the resolution stage, with its own smoothing of a noisy scan's copy. The
        outer match decides; nested matches do not smooth again.
    iterations : int
        Umbrella smoothings of the copy (each vertex halfway to its 1-ring's centroid).
    """

    enabled: bool = True
    min_roughness: float = field(default=0.16, metadata={"finite": True, "range": (0.0, None)})
    min_drop: float = field(default=0.2, metadata={"finite": True, "range": (0.0, 1.0)})
    iterations: int = field(default=2, metadata={"range": (1, 100)})


#: ``match``'s keyword options → (stage field of :class:`MatchConfig`, field of that stage).
KEYWORDS: dict[str, tuple[str | None, str]] = {
    "k_max": (None, "k_max"),
    "schedule": ("refine", "schedule"),
    "max_passes": ("refine", "max_passes"),
    "min_consistent": ("refine", "min_consistent"),
    "top_k": ("refine", "top_k"),
    "polish_k": ("refine", "polish_k"),
    "global_step": ("refine", "global_step"),
    "multiscale": ("multiscale", "enabled"),
    "spectral": ("spectral", "enabled"),
    "shared_faces": ("finish", "enabled"),
    "confidence": ("confidence", "enabled"),
}


@dataclass(frozen=True)
class MatchConfig:
    """All settings of :func:`hope_rs.match`.

    Attributes
    ----------
    k_max : int
        Largest hop radius, in [2, 64].
    min_piece : float
        A mesh's pieces (connected components) that each hold less than this share of its
        area are left out of the match, never its largest, and only when its largest holds
        at least half the area (scan debris around a body, not a mesh of many pieces;
        :mod:`hope_rs.pipeline.unreferenced`); 0 keeps every piece.
    shape : ShapeConfig
        Per-shape precomputation (descriptors, eigenbases, coarse copies) of shapes built
        from meshes; a :class:`~hope_rs.Shape` passed in keeps its own.
    initial, refine, spectral, finish, multiscale, resolution, partial, confidence
        The stages' settings.
    landmarks : LandmarkConfig
        What the caller's landmarks do, when there are any.
    orient : OrientConfig
        Repairing a map that turns A over.
    deform : DeformConfig
        The deformation-aware pass for non-isometric shapes.
    denoise : DenoiseConfig
        Matching a noisy shape on its smoothed copy.

    Examples
    --------
    >>> from hope_rs import MatchConfig
    >>> from hope_rs.pipeline.config import RefineConfig
    >>> MatchConfig(refine=RefineConfig(max_passes=2)).refine.max_passes
    2
    >>> MatchConfig().with_options(multiscale=True).multiscale.enabled
    True
    """

    # LMD reads 2-rings; the hop balls of much larger radii cover most of a mesh.
    k_max: int = field(default=8, metadata={"range": (2, 64)})
    min_piece: float = field(default=0.005, metadata={"range": (0.0, 1.0)})
    shape: ShapeConfig = field(default_factory=ShapeConfig)
    initial: InitialConfig = field(default_factory=InitialConfig)
    refine: RefineConfig = field(default_factory=RefineConfig)
    spectral: SpectralConfig = field(default_factory=SpectralConfig)
    finish: FinishConfig = field(default_factory=FinishConfig)
    multiscale: MultiscaleConfig = field(default_factory=MultiscaleConfig)
    resolution: ResolutionConfig = field(default_factory=ResolutionConfig)
    confidence: ConfidenceConfig = field(default_factory=ConfidenceConfig)
    landmarks: LandmarkConfig = field(default_factory=LandmarkConfig)
    partial: PartialConfig = field(default_factory=PartialConfig)
    orient: OrientConfig = field(default_factory=OrientConfig)
    deform: DeformConfig = field(default_factory=DeformConfig)
    denoise: DenoiseConfig = field(default_factory=DenoiseConfig)

    def with_options(self, **options) -> MatchConfig:
        """A copy with ``match``'s keyword options (see :data:`KEYWORDS`) set, its settings
        checked at once as :func:`hope_rs.match` checks a config: a value of the wrong kind
        or out of its field's range is a one-line TypeError or ValueError naming the field.
        """
        cfg = self
        for name, value in options.items():
            if name not in KEYWORDS:
                raise TypeError(
                    f"unknown option {name!r}; the options are {', '.join(sorted(KEYWORDS))}"
                )
            stage, attr = KEYWORDS[name]
            if stage is None:
                cfg = dataclasses.replace(cfg, **{attr: value})
            else:
                part = dataclasses.replace(getattr(cfg, stage), **{attr: value})
                cfg = dataclasses.replace(cfg, **{stage: part})
        check_config(cfg)
        return cfg

    def options(self) -> dict:
        """``match``'s keyword options as this config sets them (inverse of
        :meth:`with_options`)."""
        out = {}
        for name, (stage, attr) in KEYWORDS.items():
            part = self if stage is None else getattr(self, stage)
            out[name] = getattr(part, attr)
        return out

    def to_dict(self) -> dict:
        """Every setting, nested by stage (JSON-serialisable)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> MatchConfig:
        """The config :meth:`to_dict` gave ``data`` (JSON or TOML lists are read as tuples);
        settings missing from ``data`` keep their defaults, an unknown name is a one-line
        error naming it. The values are checked where :func:`hope_rs.match` checks them."""
        return _from_dict(cls, data, "MatchConfig")

    def key(self) -> str:
        """A SHA-256 (hex) of every setting: equal configs, equal keys."""
        return hashlib.sha256(settings_json(self.to_dict()).encode()).hexdigest()
