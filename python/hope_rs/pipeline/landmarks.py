"""The caller's landmarks: vertex pairs (A, B) known to correspond, kept exactly in the map.

``match(a, b, landmarks=L)`` takes ``L``, an (m, 2) array of (vertex of A, vertex of B) rows.
Geodesic distances to the landmarks are intrinsic coordinates both shapes share, and unlike
descriptors they tell a left limb from its mirror image. They act in four places:

* the "landmarks" stage (:class:`LandmarkStage`) re-places every match of the initial map
  whose distances to the landmarks fit far worse than they could (a mirrored region), at the
  nearest descriptor among the vertices of B whose distances to the landmarks are nearest its
  own (:func:`landmark_initial_map`);
* the refinement (:func:`hope_rs.pipeline.refine.refine`) pins the landmarks after every step,
  counts them as witnesses, never trusts such a match (:class:`LandmarkCoordinates`), and its
  swapped-region step takes the landmarks as anchors (its global repair too with
  ``LandmarkConfig.repair_anchors``);
* the spectral pass's ZoomOut matches by landmark coordinates, and steep ones near each
  landmark, besides its spectral embedding (:func:`landmark_embedding`);
* after every later stage (the spectral pass, the finish), the stage re-pins them.

Without landmarks none of this runs and the map is the one ``match`` makes without them.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from ..shape import Shape
from .anchors import distance_fields, reachable
from .config import LandmarkConfig, RepairConfig
from .state import QUIET, MatchState, Stage

__all__ = [
    "LandmarkCoordinates",
    "LandmarkStage",
    "coordinate_landmarks",
    "check_landmarks",
    "coarse_landmarks",
    "input_landmarks",
    "landmark_embedding",
    "landmark_initial_map",
    "pin",
]

#: Rows of A's vertices compared at once with their candidates' descriptors (bounds the
#: temporary (rows, candidates, descriptor length) array).
_CHUNK = 512


def check_landmarks(landmarks, n_a: int | None, n_b: int | None) -> np.ndarray | None:
    """``landmarks`` as an (m, 2) int64 array of (vertex of A, vertex of B), 0-based, checked
    against shapes of ``n_a`` and ``n_b`` vertices (``None``: not known yet, only negative
    indices are refused); ``None`` when there are none (``None`` or an empty array). Rows given
    twice count once.

    Raises
    ------
    TypeError, ValueError
        One line saying what is wrong: not integers, not (m, 2), a vertex out of range, a vertex
        of A given two matches or a vertex of B matched twice.
    """
    if landmarks is None:
        return None
    try:
        arr = np.asarray(landmarks)
    except (TypeError, ValueError) as e:
        raise TypeError(f"landmarks must be an (m, 2) array of vertex indices: {e}") from None
    if arr.size == 0:
        return None
    if arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(
            f"landmarks must be integer vertex indices (0-based), got dtype {arr.dtype}; "
            "convert with np.asarray(landmarks, dtype=np.int64)"
        )
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(
            f"landmarks must have shape (m, 2), one (vertex of A, vertex of B) row per "
            f"landmark, got shape {arr.shape}"
        )
    # Checked in the given dtype, so that huge unsigned values are not wrapped first.
    for col, n, name in ((0, n_a, "A"), (1, n_b, "B")):
        out = arr[:, col] < 0
        if n is not None:
            out |= arr[:, col] >= n
        bad = np.flatnonzero(out)
        if bad.size:
            r = int(bad[0])
            has = f"which has {n} (0-based indices 0..{n - 1})" if n is not None else "0-based"
            raise ValueError(
                f"landmark row {r} ({arr[r, 0]}, {arr[r, 1]}): vertex {arr[r, col]} is not a "
                f"vertex of {name}, {has}"
            )
    arr = np.unique(arr.astype(np.int64), axis=0)
    for col, name, other in ((0, "A", "B"), (1, "B", "A")):
        v, count = np.unique(arr[:, col], return_counts=True)
        if (count > 1).any():
            x = int(v[np.argmax(count > 1)])
            rows = arr[arr[:, col] == x][:, 1 - col]
            raise ValueError(
                f"landmarks contradict each other: vertex {x} of {name} is paired with vertices "
                f"{int(rows[0])} and {int(rows[1])} of {other}; give each vertex at most once"
            )
    return arr


def coarse_landmarks(
    landmarks: np.ndarray, owner_a: np.ndarray, owner_b: np.ndarray
) -> np.ndarray | None:
    """The landmarks carried to coarse copies of both shapes (fine vertex ``i`` belongs to
    coarse vertex ``owner[i]``): a row whose coarse vertex of A or of B another row takes too
    is dropped (two landmarks in one cell), as are later copies of a row; ``None`` if none is
    left."""
    rows = np.stack([owner_a[landmarks[:, 0]], owner_b[landmarks[:, 1]]], axis=1)
    rows = np.unique(rows, axis=0)
    keep = np.ones(len(rows), dtype=bool)
    for col in (0, 1):
        v, count = np.unique(rows[:, col], return_counts=True)
        keep &= ~np.isin(rows[:, col], v[count > 1])
    return rows[keep] if keep.any() else None


def input_landmarks(state: MatchState, swap: bool = False) -> np.ndarray | None:
    """The caller's landmarks in the shapes' input numbering, for a nested match (of B to A
    with ``swap``)."""
    if state.landmarks is None:
        return None
    la, lb = state.a.order[state.landmarks[:, 0]], state.b.order[state.landmarks[:, 1]]
    return np.column_stack([lb, la] if swap else [la, lb])


def pin(f: np.ndarray, landmarks: np.ndarray | None) -> np.ndarray:
    """``f`` with every landmark's vertex of A mapped to its vertex of B (``f`` itself when it
    does already)."""
    if landmarks is None or (f[landmarks[:, 0]] == landmarks[:, 1]).all():
        return f
    g = f.copy()
    g[landmarks[:, 0]] = landmarks[:, 1]
    return g


def coordinate_landmarks(a: Shape, landmarks: np.ndarray, cap: int) -> np.ndarray:
    """The rows of ``landmarks`` (internal numbering) that give landmark coordinates
    (``LandmarkConfig.max_coordinates``): all of them up to ``cap``, else ``cap`` farthest
    points among their vertices on A (in space), the one farthest from A's centroid first;
    in the order of ``landmarks``."""
    if len(landmarks) <= cap:
        return landmarks
    p = a.points[landmarks[:, 0]]
    pick = [int(np.argmax(np.linalg.norm(p - a.points.mean(axis=0), axis=1)))]
    d = np.linalg.norm(p - p[pick[0]], axis=1)
    while len(pick) < cap and d.max() > 0.0:  # coincident vertices add nothing
        pick.append(int(np.argmax(d)))
        d = np.minimum(d, np.linalg.norm(p - p[pick[-1]], axis=1))
    return landmarks[np.sort(pick)]


class LandmarkCoordinates:
    """Landmark coordinates of both shapes: ``da`` (m, n_a) and ``db`` (m, n_b) distances
    (sqrt(area) units) from the landmarks on A and on B, vertices of other components at
    ``repair.unreachable``; and, per vertex of A, the least RMS difference ``best`` any vertex
    of B achieves (``nearest`` is that vertex)."""

    def __init__(
        self, a: Shape, b: Shape, landmarks: np.ndarray, repair: RepairConfig = RepairConfig()
    ):
        self.da = reachable(distance_fields(a, landmarks[:, 0]), repair)
        self.db = reachable(distance_fields(b, landmarks[:, 1]), repair)
        self.tree = cKDTree(self.db.T)
        best, self.nearest = self.tree.query(self.da.T)
        self.best = best / np.sqrt(len(landmarks))

    def gap(self, f: np.ndarray, rows=slice(None)) -> np.ndarray:
        """How much worse than ``best`` the matches ``f[rows]`` of the vertices ``rows`` fit
        (RMS over the landmarks)."""
        d = self.da[:, rows] - self.db[:, f[rows]]
        return np.sqrt((d * d).mean(axis=0)) - self.best[rows]

    def off(self, f: np.ndarray, max_gap: float) -> np.ndarray:
        """Whether each vertex's match fits more than ``max_gap`` worse than ``best``."""
        return self.gap(f) > max_gap


def landmark_embedding(
    a: Shape,
    b: Shape,
    landmarks: np.ndarray,
    weight: float,
    repair: RepairConfig = RepairConfig(),
    *,
    near_weight: float = 0.0,
    near_radius: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Landmark coordinates that ZoomOut appends to its spectral embeddings.

    Landmark ``k``'s distance field on each shape is scaled to the mean of its two means over
    the shapes' reachable vertices (sqrt(area) units; a non-isometric pair stretches the
    distances from one landmark more than from another): ``m`` columns, ``weight`` times
    the scaled fields ``d``. With ``near_weight > 0``, ``m`` more: ``near_weight * max(
    near_radius - d, 0)``, steep near each landmark and zero beyond ``near_radius``. Around a
    landmark its own distance is the one that stretches least between the shapes (the
    distances to the far landmarks stretch with whole limbs), so these columns hold the
    vertices near a landmark at their distance from it, where ZoomOut's spectral embedding
    would slide a limb end that is larger on A than on B up the limb of B.

    Parameters
    ----------
    a, b : Shape
        The two shapes.
    landmarks : (m, 2) int ndarray
        (vertex of A, vertex of B) rows, internal numbering.
    weight : float
        Factor of the scaled fields (``LandmarkConfig.zoomout_weight``).
    repair : RepairConfig
        Its ``unreachable`` is the coordinate of a vertex in another component.
    near_weight, near_radius : float
        Slope and radius (sqrt(area) units) of the near-landmark columns
        (``LandmarkConfig.near_weight``, ``LandmarkConfig.near_radius``); 0: none.

    Returns
    -------
    (n_a, j) and (n_b, j) float64 ndarrays
        The coordinates of A's and of B's vertices: ``j = m``, or ``2 m`` with the
        near-landmark columns.

    Examples
    --------
    >>> import numpy as np, hope_rs
    >>> from hope_rs.evaluation.demo import demo_pair
    >>> a, b = (hope_rs.Shape(m) for m in demo_pair())
    >>> lm = np.array([[0, 0], [100, 100]])
    >>> ea, eb = landmark_embedding(a, b, lm, 3.0)
    >>> ea.shape, eb.shape
    ((6890, 2), (6890, 2))
    >>> landmark_embedding(a, b, lm, 3.0, near_weight=90.0, near_radius=0.2)[0].shape
    (6890, 4)
    """
    da, db = distance_fields(a, landmarks[:, 0]), distance_fields(b, landmarks[:, 1])
    ma = np.array([row[np.isfinite(row)].mean() for row in da])
    mb = np.array([row[np.isfinite(row)].mean() for row in db])
    target = 0.5 * (ma + mb)
    out = []
    for d, m in ((da, ma), (db, mb)):
        # A landmark alone in its component has mean 0: its field is left unscaled.
        scale = np.divide(target, m, out=np.ones_like(m), where=m > 0)
        scaled = d * scale[:, None]
        cols = [weight * reachable(scaled, repair)]
        if near_weight > 0 and near_radius > 0:
            # Before reachable(): a vertex of another component (inf) gets 0.
            cols.append(near_weight * np.maximum(near_radius - scaled, 0.0))
        out.append(np.ascontiguousarray(np.vstack(cols).T))
    return out[0], out[1]


def landmark_initial_map(
    a: Shape,
    b: Shape,
    f0: np.ndarray,
    landmarks: np.ndarray,
    desc: tuple[np.ndarray, np.ndarray] | None,
    config: LandmarkConfig = LandmarkConfig(),
    coords: LandmarkCoordinates | None = None,
) -> np.ndarray:
    """``f0`` with the landmarks pinned and every off match (see :class:`LandmarkConfig`)
    re-placed: among the ``config.candidates`` vertices of B whose landmark coordinates are
    nearest the vertex's own, the one of nearest descriptor (``desc``: A's and B's, internal
    numbering), or without descriptors the nearest by coordinates. ``coords``: the shapes'
    :class:`LandmarkCoordinates`, if computed already."""
    coords = LandmarkCoordinates(a, b, landmarks) if coords is None else coords
    moved = np.flatnonzero(coords.off(f0, config.max_gap))
    f = f0.copy()
    if desc is None:
        f[moved] = coords.nearest[moved]
    elif moved.size:
        k = min(config.candidates, b.n_vertices)
        cand = coords.tree.query(coords.da[:, moved].T, k=k)[1].reshape(moved.size, k)
        ea, eb = desc
        for s in range(0, moved.size, _CHUNK):
            rows, c = moved[s : s + _CHUNK], cand[s : s + _CHUNK]
            diff = eb[c] - ea[rows][:, None, :]
            best = np.argmin(np.einsum("ijk,ijk->ij", diff, diff), axis=1)
            f[rows] = c[np.arange(rows.size), best]
    return pin(f, landmarks)


class LandmarkStage(Stage):
    """The "landmarks" stage: ``state.f0`` made to agree with the landmarks
    (:func:`landmark_initial_map`); after every later stage, the landmarks re-pinned in
    ``state.f``. Silent without landmarks."""

    name = "landmarks"
    runs_on_final_map = True

    def attach(self, state: MatchState) -> None:
        if state.landmarks is not None:
            state.hooks.on("stage_end", _repin)

    def skip_reason(self, state: MatchState):
        return QUIET if state.landmarks is None else None

    def run(self, state: MatchState) -> None:
        a, b, lm = state.a, state.b, state.landmarks
        assert lm is not None  # skip_reason skips the stage without landmarks
        assert state.f0 is not None  # the initial map, made before
        cfg = state.config
        cap = cfg.landmarks.max_coordinates
        detail = f"{len(lm)} landmarks" + (
            f" ({cap} of them as coordinates)" if len(lm) > cap else ""
        )
        t = state.log.start("landmarks", detail=detail)
        kind = state.init if isinstance(state.init, str) else None
        desc = None
        if kind is not None and state.coarse is None:
            # The descriptors the initial map was made from; not on the multiscale path, whose
            # start is the lifted coarse map (descriptors an earlier match left on the shapes
            # do not count there: the map would depend on them).
            desc = a.internal_descriptors(kind), b.internal_descriptors(kind)
        f0 = pin(state.f0, lm)
        if cfg.landmarks.init:
            some = coordinate_landmarks(a, lm, cap)
            coords = LandmarkCoordinates(a, b, some, cfg.refine.repair)
            f0 = landmark_initial_map(a, b, state.f0, lm, desc, cfg.landmarks, coords)
        moved = int(np.count_nonzero(f0 != state.f0))
        state.f0 = f0
        state.timings["landmarks"] = time.perf_counter() - t
        state.log.ran("landmarks", state.timings["landmarks"], f"{detail}, re-placed {moved}")


def _repin(state: MatchState, name: str) -> None:
    """The "stage_end" subscriber: the landmarks mapped exactly after every stage."""
    if state.f is not None:
        state.f = pin(state.f, state.landmarks)
