"""hope_rs: dense 3D shape matching with HOPE (aligning k-hop neighbourhoods), Rust-accelerated.

``match(A, B).map[i]`` is the vertex of B matched to vertex i of A. (pyFM's ``p2p_21`` points the
other way: it lists, for each vertex of shape 2, a vertex of shape 1.)
"""

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _dist_version

from .assignment import auction_assignment
from .batch import PairResult, match_many, read_pairs
from .cache import ShapeCache
from .evaluate import geodesic_errors, load_vts, score
from .kernels import khop_neighbourhoods, overlap_cost
from .map_io import read_map, write_map
from .matching import MatchResult, match
from .mesh import Mesh, load_mesh
from .shape import Shape

__all__ = [
    "MatchResult",
    "Mesh",
    "PairResult",
    "Shape",
    "ShapeCache",
    "auction_assignment",
    "geodesic_errors",
    "khop_neighbourhoods",
    "load_mesh",
    "load_vts",
    "match",
    "match_many",
    "overlap_cost",
    "read_map",
    "read_pairs",
    "score",
    "write_map",
]

try:
    __version__ = _dist_version("hope-rs")
except PackageNotFoundError:  # a source tree on sys.path without installed metadata
    __version__ = "0+unknown"
