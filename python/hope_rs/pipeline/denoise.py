"""The "denoise" stage: a noisy shape is matched on its smoothed copy.

Vertex noise that is large against a mesh's edges (a scan's, or Gaussian noise of half a
percent of sqrt(area) on a 5k mesh) corrupts what every later stage reads: SHOT's normals and
histograms, the zigzag edge paths the geodesic distances follow, and the triangles a right map
turns over. When a shape's normal roughness is above ``DenoiseConfig.min_roughness`` mean edge
lengths and one umbrella smoothing takes more than ``min_drop`` of it out (noise, not
curvature: a clean mesh loses a few percent), the stage replaces it by its copy smoothed
``iterations`` times (:meth:`~hope_rs.Shape.smoothed`: the same numbering, faces and k-hop
neighbourhoods), so the map found is a map of the shape itself.

Only between shapes of like density (a part measured at its whole's scale): a much denser
whole goes through the resolution stage, which smooths the copy of a noisy dense scan its own
way (docs/decisions.md#smooth-rougher). The decision is the outer match's: the runner turns
the stage off in every nested match (the partial stage's trials, the orient stage's
hypotheses and mirror image, the coarse copies), which match these shapes or copies of them.
"""

from __future__ import annotations

import time

from ..shape import Shape
from .config import MatchConfig
from .partial import detect_part
from .resolution import denser_side
from .state import QUIET, MatchState, Stage

__all__ = ["DenoiseStage", "denoised", "like_density", "noisy", "noisy_sides"]


def noisy(s: Shape, min_roughness: float, min_drop: float) -> bool:
    """Whether ``s`` is rougher along its normals than ``min_roughness`` mean edge lengths
    and one smoothing takes more than ``min_drop`` of that out (the cheap test first)."""
    return s.smoothing == 0 and s.roughness > min_roughness and s.smoothing_drop > min_drop


def like_density(a: Shape, b: Shape, config: MatchConfig) -> bool:
    """Whether neither shape is more than ``ResolutionConfig.max_ratio`` times as dense as
    the other: as vertices per unit area at their own scales, or, for a part and its whole
    (:func:`~hope_rs.pipeline.partial.detect_part`, the same units), with the part measured
    at the whole's scale (a part has fewer vertices for its smaller area)."""
    ratio = config.resolution.max_ratio
    if denser_side(a, b, ratio) is None:
        return True
    info = detect_part(a, b, config.partial) if config.partial.enabled else None
    if info is None:
        return False
    part, whole = (a, b) if info.part == "a" else (b, a)
    return denser_side(part.at_scale(info.scale), whole, ratio) is None


def noisy_sides(a: Shape, b: Shape, config: MatchConfig) -> list[str]:
    """Which of the two shapes ("A", "B") the stage replaces by a smoothed copy."""
    cfg = config.denoise
    if not cfg.enabled or not like_density(a, b, config):
        return []
    return [side for side, s in (("A", a), ("B", b)) if noisy(s, cfg.min_roughness, cfg.min_drop)]


def _smoothed(a: Shape, b: Shape, sides: list[str], n: int) -> tuple[Shape, Shape]:
    """``a`` and ``b``, each of ``sides`` replaced by its copy smoothed ``n`` times."""
    return (a.smoothed(n) if "A" in sides else a), (b.smoothed(n) if "B" in sides else b)


def denoised(a: Shape, b: Shape, config: MatchConfig) -> tuple[Shape, Shape]:
    """The shapes a match of ``a`` to ``b`` runs on after the stage (for a tool that judges
    a map as the pipeline does)."""
    return _smoothed(a, b, noisy_sides(a, b, config), config.denoise.iterations)


class DenoiseStage(Stage):
    """The "denoise" stage (see the module notes): runs only when a shape is noisy."""

    name = "denoise"
    runs_on_final_map = False

    def __init__(self):
        self.sides: list[str] = []

    def skip_reason(self, state: MatchState):
        self.sides = noisy_sides(state.a, state.b, state.config)
        return None if self.sides else QUIET

    def run(self, state: MatchState) -> None:
        t = state.log.start("denoise")
        n = state.config.denoise.iterations
        said = [
            f"{side} smoothed {n} times (roughness {s.roughness:.2f} mean edges, "
            f"{s.smoothing_drop:.0%} of it out in one smoothing)"
            for side, s in (("A", state.a), ("B", state.b))
            if side in self.sides
        ]
        state.a, state.b = _smoothed(state.a, state.b, self.sides, n)
        state.timings["denoise"] = time.perf_counter() - t
        state.log.ran("denoise", state.timings["denoise"], "; ".join(said))
