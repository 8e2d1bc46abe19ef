"""The outcome of a match."""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field

import numpy as np

from .config import MatchConfig
from .iteration import Iteration
from .progress import STAGES, StageInfo

__all__ = ["MatchQuality", "MatchResult"]


@dataclass(frozen=True)
class MatchQuality:
    """A pair-level summary of :attr:`MatchResult.confidence`.

    Attributes
    ----------
    mean_confidence : float
        The mean confidence over A's vertices that faces use (a vertex in no face has
        confidence 0 and is left out: it says nothing of the surface's map).
    share_confident : float
        The share of those vertices with confidence at least ``ConfidenceConfig.threshold``.
    likely_failed : bool
        ``mean_confidence < ConfidenceConfig.failed_mean``, ``share_confident <
        ConfidenceConfig.failed_share`` or ``flipped_share > ConfidenceConfig.failed_flipped``:
        much of the map is probably wrong; look at the pair (``hope-rs show --color-by
        confidence``) before using it.
    flipped_share : float
        The share of A's area whose triangles the map turns over
        (:func:`~hope_rs.pipeline.confidence.flipped_share`), measured on the shapes the match
        ran on: a noisy shape's smoothed copy (``MatchConfig.denoise``); for a noisy dense A
        matched at a common resolution, its copy (``ResolutionConfig.judge_rougher``).
    """

    mean_confidence: float
    share_confident: float
    likely_failed: bool
    flipped_share: float = 0.0

    def describe(self) -> str:
        """The figures the flag reads, for a message: "mean confidence 0.41, 38% of A's
        vertices confident, 12% of its area turned over"."""
        return (
            f"mean confidence {self.mean_confidence:.2f}, {self.share_confident:.0%} of A's "
            f"vertices confident, {self.flipped_share:.0%} of its area turned over"
        )


@dataclass(eq=False)  # == is identity: comparing its arrays element-wise has no one answer
class MatchResult:
    """The outcome of :func:`match`.

    Attributes
    ----------
    map : (n_a,) int64
        ``map[i]`` is the vertex of B matched to vertex ``i`` of A. For pyFM, see
        :meth:`to_pyfm`.
    init_map : (n_a,) int64
        The map refinement started from: the initial map, or the caller's ``init`` map. When
        A is a part matched in trials, the kept trial's start (the merge of the trials' maps
        when the merge is kept); when B is, the part's match's start inverted (the caller's
        map when one was given).
    history : list of Iteration
        Per refinement step: k, witness fraction, vertices changed, seconds.
    timings : dict
        Seconds per stage ("shapes", "descriptors", "init" or, with ``multiscale``,
        "coarse"; "refine", "spectral", "faces" (the finishing rounds of
        :mod:`hope_rs.pipeline.shared_faces`, when they ran), "confidence", "total"), and
        within "refine" and "faces" the seconds their HOPE steps spent building overlap costs
        ("refine.cost", "faces.cost") and solving the assignments ("refine.assign",
        "faces.assign"). The spectral pass's eigenbases are solved in a background thread
        during "refine", as is its ZoomOut when the refinement reaches its last pass
        (:class:`~hope_rs.pipeline.spectral.SpectralBackground`); the wait for what is left
        of them after the refinement counts in "spectral".
    coarse : MatchResult or None
        With ``multiscale``, the match of the coarse copies.
    hope_map : (n_a,) int64
        HOPE's own map: the refinement's output, before the spectral pass chose between it and
        its ZoomOut refinement region by region and before the shared-face finish. Equal to
        ``map`` when neither of those changed it (see :attr:`stages`). When B is a part, the
        part's match's HOPE map inverted like ``map``.
    stages : list of StageInfo
        Every stage in the order it ran, with whether it ran, why (or why not) and its seconds:
        "shapes", "descriptors", "init" ("coarse" and "lift" with ``multiscale``), "refine",
        "polish", "spectral", "faces", "confidence" (see :data:`hope_rs.pipeline.progress.STAGES`). ``str()`` of an
        entry reads "spectral: skipped (HOPE's map settled: ...)".
    config : MatchConfig
        The settings the match ran with; ``config.initial.descriptor`` is the ``init`` kind
        given (with an ``init`` map, ``init_map`` is the start).
    confidence : (n_a,) float64 or None
        Per vertex of A, how far to trust its match, in [0, 1]: a calibrated estimate of the
        probability that ``map[i]`` lies within 0.05 sqrt(area) of the right vertex
        (docs/confidence.md). Low over a region the map placed wrongly. ``None`` with
        ``confidence=False``. Between non-isometric shapes it judges the map before the
        deformation pass (the "deform" stage), which moves each image only a little.
    quality : MatchQuality or None
        The pair-level summary of ``confidence`` (``quality.likely_failed``: look at the
        pair before using its map); when B is a part of A matched in reverse (the default,
        ``PartialConfig.whole_to_part``), over the vertices of A that have a counterpart on B.
    """

    map: np.ndarray
    init_map: np.ndarray
    history: list[Iteration] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    #: With ``multiscale``, the match of the coarse copies (each coarse vertex ``j`` is the
    #: vertex ``coarse_level()[0].sites[j]`` of the shape's internal mesh); else ``None``.
    coarse: MatchResult | None = None
    hope_map: np.ndarray | None = None
    stages: list[StageInfo] = field(default_factory=list)
    #: The settings the match ran with.
    config: MatchConfig | None = None
    confidence: np.ndarray | None = None
    quality: MatchQuality | None = None

    def map_or_unmatched(self, threshold: float = 0.5) -> np.ndarray:
        """The map with -1 where the confidence is below ``threshold``.

        Parameters
        ----------
        threshold : float
            In [0, 1]; 0 keeps every match, 1 only those at confidence 1.

        Returns
        -------
        (n_a,) int64
            ``map[i]``, or -1 where ``confidence[i] < threshold`` (a new array).

        Raises
        ------
        ValueError
            When the match ran with ``confidence=False`` or ``threshold`` is not in [0, 1].
        """
        if self.confidence is None:
            raise ValueError(
                "this match has no confidence (it ran with confidence=False); "
                "match again with confidence=True"
            )
        if (
            isinstance(threshold, bool)
            or not isinstance(threshold, numbers.Real)
            or not (0.0 <= float(threshold) <= 1.0)
        ):
            raise ValueError(f"threshold must be a number in [0, 1], got {threshold!r}")
        out = np.array(self.map, dtype=np.int64)
        out[self.confidence < threshold] = -1
        return out

    def stage(self, name: str) -> StageInfo:
        """The :class:`~hope_rs.pipeline.progress.StageInfo` of the stage ``name`` (e.g. "spectral").

        A stage of :data:`~hope_rs.pipeline.progress.STAGES` that this match's path does not
        include ("coarse" on the full path, "partial" between two whole shapes) reads as not
        run, with that reason.

        Raises
        ------
        KeyError
            When ``name`` is not a stage of :data:`~hope_rs.pipeline.progress.STAGES`.
        """
        for s in self.stages:
            if s.name == name:
                return s
        if name in STAGES:
            return StageInfo(name, ran=False, reason="not on this match's path")
        raise KeyError(f"no stage {name!r}; the stages are {', '.join(STAGES)}")

    def to_pyfm(self) -> np.ndarray:
        """The map as pyFM's ``p2p_21`` for ``mesh1 = B`` and ``mesh2 = A``.

        pyFM (``pip install pyfmaps``) writes a point-to-point map as ``p2p_21``: for each
        vertex of ``mesh2``, a vertex of ``mesh1``; it goes with the functional map ``FM_12``,
        which carries functions on ``mesh1`` to ``mesh2`` (``pyFM.spectral.mesh_p2p_to_FM(p2p_21,
        mesh1, mesh2)``). ``match(A, B).map`` gives a vertex of B for each vertex of A, so it is
        ``p2p_21`` with ``mesh1`` built from B and ``mesh2`` from A.

        With ``mesh1`` = A and ``mesh2`` = B instead, match the other way:
        ``hope_rs.match(b, a).to_pyfm()`` (a map is not one-to-one, so reversing it would lose
        vertices of B that nothing maps to).

        Returns
        -------
        (n_a,) int64
            A copy of :attr:`map`.

        Examples
        --------
        >>> import hope_rs, trimesh
        >>> from pyFM.mesh import TriMesh
        >>> from pyFM.spectral import mesh_p2p_to_FM
        >>> a = trimesh.creation.icosphere(subdivisions=2)
        >>> b = a.copy()
        >>> b.vertices *= [1.0, 1.2, 0.9]
        >>> res = hope_rs.match(a, b)
        >>> mesh1 = TriMesh(b.vertices, b.faces).process(k=30)  # B, with 30 eigenfunctions
        >>> mesh2 = TriMesh(a.vertices, a.faces).process(k=30)  # A
        >>> fm_12 = mesh_p2p_to_FM(res.to_pyfm(), mesh1, mesh2, dims=30)  # functions on B -> A
        >>> fm_12.shape
        (30, 30)
        """
        return np.array(self.map, dtype=np.int64)
