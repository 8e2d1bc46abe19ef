"""Many pairs at once: ``match_many``, its on-disk shape cache and its process backends."""

from .cache import ShapeCache
from .driver import PairResult, match_many, read_pairs

__all__ = ["PairResult", "ShapeCache", "match_many", "read_pairs"]
