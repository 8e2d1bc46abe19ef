"""hope_rs: dense 3D shape matching with HOPE (aligning k-hop neighbourhoods), Rust-accelerated.

``match(A, B).map[i]`` is the vertex of B matched to vertex i of A. (pyFM's ``p2p_21`` points the
other way: it lists, for each vertex of shape 2, a vertex of shape 1.)
"""

from ._threads import cap_rayon_threads
from ._version import __version__ as __version__
from .batch.cache import ShapeCache
from .batch.driver import PairResult, match_many, read_pairs
from .evaluation.evaluate import geodesic_errors, load_vts, score
from .geometry.map_io import read_landmarks, read_map, write_map
from .geometry.mesh import Mesh, load_mesh
from .kernels.assignment import auction_assignment
from .kernels.khop import khop_neighbourhoods, overlap_cost
from .matching import MatchConfig, MatchResult, match
from .pipeline.confidence import MatchQuality
from .shape import Shape, ShapeConfig

cap_rayon_threads()  # before any Rust call starts the thread pool (importing calls none)

__all__ = [
    "MatchConfig",
    "MatchQuality",
    "MatchResult",
    "Mesh",
    "PairResult",
    "Shape",
    "ShapeCache",
    "ShapeConfig",
    "auction_assignment",
    "geodesic_errors",
    "khop_neighbourhoods",
    "load_mesh",
    "load_vts",
    "match",
    "match_many",
    "overlap_cost",
    "read_landmarks",
    "read_map",
    "read_pairs",
    "score",
    "write_map",
]
