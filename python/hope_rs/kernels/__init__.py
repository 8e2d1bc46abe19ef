"""Thin wrappers of the Rust core: k-hop neighbourhoods, overlap costs, assignments, map utilities."""

from .assignment import auction_assignment
from .khop import khop_neighbourhoods, overlap_cost

__all__ = ["auction_assignment", "khop_neighbourhoods", "overlap_cost"]
