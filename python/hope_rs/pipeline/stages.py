"""The stage list of :func:`hope_rs.match`, in the order it runs.

Adding or removing a stage touches its own module, this list and its field of
:class:`~hope_rs.pipeline.config.MatchConfig`.
"""

from __future__ import annotations

from .confidence import ConfidenceStage
from .deform import DeformStage
from .denoise import DenoiseStage
from .initial import DescriptorStage, InitialStage
from .landmarks import LandmarkStage
from .multiscale import MultiscaleStage
from .orientation_repair import OrientStage
from .partial import PartialStage
from .refine import RefineStage
from .resolution import ResolutionStage
from .shared_faces import FinishStage
from .spectral import SpectralStage
from .state import Stage

__all__ = ["default_stages"]


def default_stages() -> list[Stage]:
    """Fresh instances of the stages (a stage keeps the state of one match, such as the
    spectral pass's background threads)."""
    return [
        DenoiseStage(),  # "denoise": only when a shape is noisy
        PartialStage(),  # "partial": only when one shape is a part of the other
        ResolutionStage(),  # "resolution": only when one shape is much denser than the other
        MultiscaleStage(),  # "coarse", "lift": multiscale=True only
        DescriptorStage(),  # "descriptors"
        InitialStage(),  # "init"
        LandmarkStage(),  # "landmarks": with landmarks only
        RefineStage(),  # "refine", "polish"
        SpectralStage(),  # "spectral"
        FinishStage(),  # "faces"
        OrientStage(),  # "orient": when the map turns much of A over or looks failed
        # The confidence judges the map the deformation pass starts from: the pass moves each
        # image by a smooth displacement, not onto another region, and its nearest-point map is
        # less locally consistent than the map it refines (docs/decisions.md#deform).
        ConfidenceStage(),  # "confidence"
        DeformStage(),  # "deform": only when the shapes' spectra differ (not isometric)
    ]
