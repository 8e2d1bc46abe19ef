"""Many pairs at once: ``match_many`` (:mod:`.driver`), the pairs files of ``hope-rs batch``
(:mod:`.pairs_file`), map file names and the output folder's manifest (:mod:`.naming`,
:mod:`.manifest`), the on-disk shape cache (:mod:`.cache`), the tasks and where they run
(:mod:`.tasks`, :mod:`.backends`, :mod:`.ray_backend`), the scheduler and the progress line
(:mod:`.scheduler`, :mod:`.progress`)."""

from .cache import ShapeCache
from .driver import PairResult, match_many, read_pairs

__all__ = ["PairResult", "ShapeCache", "match_many", "read_pairs"]
