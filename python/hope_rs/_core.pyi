"""Type stubs of the private native module (see src/python/).

Every function raises ValueError on malformed input and MemoryError when a size it is given
(a vertex count, a column count, an output's size) needs more than the machine's physical
memory, instead of aborting; a KeyboardInterrupt that arrives during a kernel is raised as soon
as the kernel returns.
"""

import numpy as np
import numpy.typing as npt
from typing_extensions import TypeAlias, final

__all__ = [
    "MeshGraph",
    "PointClusters",
    "DuplicateEntries",
    "khop_neighbourhoods",
    "overlap_cost_csr",
    "best_overlap_graphs",
    "local_map_distortion_graphs",
    "auction_assignment_int",
    "overlap_assignment_graphs",
    "overlap_step_cost_graphs",
    "warm_assignment_int",
    "auction_assignment_float",
    "shot_descriptors",
    "greedy_pairs",
    "nearest_among",
    "closest_rotations",
    "edge_rotations",
    "grow_across_faces",
    "collapse_to_sites",
]

_Csr: TypeAlias = tuple[npt.NDArray[np.int64], npt.NDArray[np.int32], np.ndarray]

class DuplicateEntries(ValueError):
    """A sparse cost stores one entry twice."""

@final
class MeshGraph:
    def __new__(
        cls, vertices: npt.NDArray[np.float64], faces: npt.NDArray[np.int64], k_max: int
    ) -> MeshGraph: ...
    @property
    def n_vertices(self) -> int: ...
    @property
    def k_max(self) -> int: ...
    def khop(self, k: int) -> _Csr: ...
    def pair_distances(
        self, sources: npt.NDArray[np.int64], targets: npt.NDArray[np.int64]
    ) -> npt.NDArray[np.float64]: ...
    def distance_fields(self, sources: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]: ...
    def farthest_fields(
        self, candidates: npt.NDArray[np.int64], start: int, n: int, scale: float
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
        """Farthest-point samples of ``candidates`` from ``start`` (at most ``n``) and their
        distance fields, (len(samples), n_vertices); ``scale`` divides the distances compared."""
    def mean_edge_length(self) -> float: ...

@final
class PointClusters:
    """Exact nearest points of a fixed (n, d) float point set, d > 0, for many queries."""

    def __new__(cls, points: npt.NDArray[np.float64]) -> PointClusters: ...
    def nearest(
        self, queries: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
        """Per query row, its nearest point and whether another is about as near (only
        unflagged answers are certain to be the one any exact search gives)."""

def khop_neighbourhoods(faces: npt.NDArray[np.int64], k: int, n_vertices: int) -> _Csr:
    """k-hop pattern of the mesh graph; ``n_vertices`` at least the largest face index + 1 and
    at most 2**31 - 1."""

def overlap_cost_csr(
    a_indptr: npt.NDArray[np.int64],
    a_indices: npt.NDArray[np.int32],
    n_a: int,
    b_indptr: npt.NDArray[np.int64],
    b_indices: npt.NDArray[np.int32],
    n_b: int,
    f: npt.NDArray[np.int64],
    witnesses: npt.NDArray[np.bool_],
    top_k: int | None = None,
    keep: npt.NDArray[np.int64] | None = None,
) -> _Csr: ...
def best_overlap_graphs(
    a: MeshGraph,
    b: MeshGraph,
    k: int,
    f: npt.NDArray[np.int64],
    witnesses: npt.NDArray[np.bool_],
    top_k: int | None,
) -> npt.NDArray[np.int64]: ...
def overlap_assignment_graphs(
    a: MeshGraph,
    b: MeshGraph,
    k: int,
    f: npt.NDArray[np.int64],
    witnesses: npt.NDArray[np.bool_],
    top_k: int | None,
    keep: npt.NDArray[np.int64],
    hint: npt.NDArray[np.int64],
    floor_div: int,
    stay: int,
) -> tuple[npt.NDArray[np.int64], float, float]: ...
def overlap_step_cost_graphs(
    a: MeshGraph,
    b: MeshGraph,
    k: int,
    f: npt.NDArray[np.int64],
    witnesses: npt.NDArray[np.bool_],
    top_k: int | None,
    keep: npt.NDArray[np.int64],
    stay: int,
) -> _Csr: ...
def warm_assignment_int(
    indptr: npt.NDArray[np.int64],
    indices: npt.NDArray[np.int32],
    data: npt.NDArray[np.int64],
    n_rows: int,
    n_cols: int,
    prev: npt.NDArray[np.int64],
    prices: npt.NDArray[np.int64],
    max_repair: int,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], int, bool] | None: ...
def local_map_distortion_graphs(
    a: MeshGraph,
    b: MeshGraph,
    f: npt.NDArray[np.int64],
    scale_a: float,
    scale_b: float,
    prev: tuple[npt.NDArray[np.int64], npt.NDArray[np.float32], npt.NDArray[np.float32]]
    | None = None,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]: ...
def auction_assignment_int(
    indptr: npt.NDArray[np.int64],
    indices: npt.NDArray[np.int32],
    data: npt.NDArray[np.int64],
    n_rows: int,
    n_cols: int,
    maximize: bool,
    floor_div: int = ...,
    hint: npt.NDArray[np.int64] | None = None,
) -> npt.NDArray[np.int64]:
    """``floor_div``: the final epsilon's divisor (default 1024, src/auction's
    ``DEFAULT_FLOOR_DIV``)."""

def auction_assignment_float(
    indptr: npt.NDArray[np.int64],
    indices: npt.NDArray[np.int32],
    data: npt.NDArray[np.float64],
    n_rows: int,
    n_cols: int,
    maximize: bool,
) -> npt.NDArray[np.int64]: ...
def shot_descriptors(
    vertices: npt.NDArray[np.float64],
    faces: npt.NDArray[np.int64],
    radius: float,
    centres: npt.NDArray[np.int64] | None = None,
) -> npt.NDArray[np.float32]: ...
def greedy_pairs(
    rows: npt.NDArray[np.int64],
    cols: npt.NDArray[np.int64],
    capacity: npt.NDArray[np.int64],
    n_cols: int,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]: ...
def nearest_among(
    query: npt.NDArray[np.float32],
    base: npt.NDArray[np.float32],
    cand: npt.NDArray[np.int64],
) -> npt.NDArray[np.int64]: ...
def closest_rotations(m: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """For each 3 x 3 matrix ``M`` of an (n, 3, 3) array, the rotation ``R`` maximising
    ``tr(R M)`` (Horn's quaternion method); raises ValueError on other shapes or non-finite
    values."""

def edge_rotations(
    indptr: npt.NDArray[np.int64],
    edges: npt.NDArray[np.int64],
    ex: npt.NDArray[np.float64],
    ey: npt.NDArray[np.float64],
) -> npt.NDArray[np.float64]:
    """ARAP's local step, (n, 3, 3): for each vertex v, :func:`closest_rotations` of
    ``sum(ex[e] ey[e]ᵀ)`` over the directed edges ``edges[indptr[v]:indptr[v + 1]]`` (summed in
    that order from zero, as a 0/1 sparse matrix times the stacked outer products sums them);
    ``ex``, ``ey``: (n_edges, 3) edges at rest and deformed."""

def grow_across_faces(
    faces_a: npt.NDArray[np.int64],
    points_a: npt.NDArray[np.float64],
    faces_b: npt.NDArray[np.int64],
    points_b: npt.NDArray[np.float64],
    partial_map: npt.NDArray[np.int64],
    max_error: float,
) -> npt.NDArray[np.int64]:
    """``partial_map`` (A -> B, -1 where unknown, one-to-one where known) extended across the
    faces of A whose mapped edge bounds a face of B on the same side, best-shaped first, where
    the two triangles' shapes differ by less than ``max_error`` (the third vertex's coordinates
    relative to the edge, in edge lengths). Known entries stay. Raises ValueError on faces out
    of range, a map of the wrong length, entries outside -1..n_b-1, a map that is not
    one-to-one, or a negative or NaN ``max_error``."""

def collapse_to_sites(
    vertices: npt.NDArray[np.float64],
    faces: npt.NDArray[np.int64],
    sites: npt.NDArray[np.int64],
    dist: npt.NDArray[np.float64],
    pred: npt.NDArray[np.int64],
    source: npt.NDArray[np.int64],
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Every vertex merged into its site by half-edge collapses that keep a manifold, keep the
    boundary and turn no face over, along the multi-source shortest-path tree from ``sites``
    (``dist``: inf where unreached; ``pred``, ``source``: negative where none). Returns the
    kept vertices (input numbering), the kept vertex each input vertex went to (their
    numbering) and the (m, 3) faces left (their numbering). Raises ValueError on indices out
    of range, a face repeating a vertex, or arrays not of one entry per vertex."""
