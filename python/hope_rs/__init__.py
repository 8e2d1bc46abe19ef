"""hope_rs: dense 3D shape matching with HOPE (aligning k-hop neighbourhoods), Rust-accelerated.

``match(A, B).map[i]`` is the vertex of B matched to vertex i of A. (pyFM's ``p2p_21`` points the
other way: it lists, for each vertex of shape 2, a vertex of shape 1.)
"""

from .assignment import auction_assignment
from .kernels import khop_neighbourhoods, overlap_cost

__all__ = [
    "auction_assignment",
    "khop_neighbourhoods",
    "overlap_cost",
]

__version__ = "0.1.0"
