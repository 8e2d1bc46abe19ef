"""Named matching methods for the benchmark: each turns a pair of meshes into a map and seconds.

Every method's ``seconds`` is its wall time from the two meshes to the map, including its
share of preprocessing: the descriptors and initial map are computed once per pair and their
time is added to each method that starts from them, so the methods can share work without
flattering any of them.

``init``, ``init-wks``, ``init-hks``
    The descriptor-based initial map alone (SHOT, WKS, HKS + one-to-one assignment).
``hope``
    :func:`hope_rs.match` with default parameters (SHOT start), the same for every data set;
    on a part and its whole it computes its own start (the part described at the whole's
    scale), so its time includes that start's.
``zoomout``, ``zoomout-wks``
    ZoomOut (Melzi et al. 2019) from pyFM (``pip install pyfmaps``), started from the same
    initial map as HOPE: the map is converted to a 20 x 20 functional map and zoomed out in
    steps of 5 to 100 eigenfunctions (pyFM's usual settings, area-normalised meshes).
Ablations
    ``hope-nospectral`` (HOPE's own map, no spectral pass), ``hope-nolmd`` (every vertex a
    witness), ``hope-fixedk`` (k = 8 in every step instead of 8 → 1), ``hope-k4`` /
    ``hope-k12`` (k_max; default 8), ``hope-rand25/50/75`` (HOPE from the SHOT map with
    25/50/75% of its entries replaced by random vertices of B).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..features.descriptors import descriptors
from ..geometry.mesh import Mesh
from ..matching import match
from ..pipeline.confidence import MatchQuality
from ..pipeline.config import MatchConfig
from ..pipeline.denoise import noisy_sides
from ..pipeline.initial import initial_map
from ..pipeline.partial import detect_part
from ..pipeline.resolution import denser_side
from ..shape import Shape

#: ZoomOut settings: functional map size at the start, steps and increment per step.
ZOOMOUT_K_INIT, ZOOMOUT_STEPS, ZOOMOUT_STEP = 20, 16, 5


@dataclass
class MethodResult:
    map: np.ndarray  #: (n_a,) vertex of B for each vertex of A
    seconds: float  #: wall time from meshes to map
    start: str | None = None  #: key of the initial map it refined (see PairContext.start_map)
    confidence: np.ndarray | None = None  #: (n_a,) MatchResult.confidence, for HOPE's methods
    quality: MatchQuality | None = None  #: MatchResult.quality, for HOPE's methods


class PairContext:
    """One pair's meshes plus the work methods share (descriptors and initial maps, each
    cached with the seconds it took; HOPE's shapes are made anew for each method)."""

    def __init__(self, a: Mesh, b: Mesh, *, seed: int = 0):
        self.a, self.b, self.seed = a, b, seed
        self._init: dict[str, tuple[np.ndarray, float]] = {}
        self._starts: dict[str, np.ndarray] = {}

    def initial(self, kind: str = "shot") -> tuple[np.ndarray, float]:
        """Initial map from ``kind`` descriptors and the seconds to compute it from the meshes."""
        if kind not in self._init:
            t = time.perf_counter()
            f0 = initial_map(descriptors(self.a, kind), descriptors(self.b, kind))
            self._init[kind] = (f0, time.perf_counter() - t)
            self._starts[kind] = f0
        return self._init[kind]

    def shapes(self, k_max: int):
        """HOPE's per-shape precomputation for ``k_max``: (Shape A, Shape B, seconds). New
        shapes on every call: a method run after another must not find the eigenbases,
        descriptors or smoothed copies the first one left on them, or its time would read
        short."""
        t = time.perf_counter()
        sa, sb = Shape(self.a, k_max=k_max), Shape(self.b, k_max=k_max)
        return sa, sb, time.perf_counter() - t

    def degraded(self, fraction: float, kind: str = "shot") -> tuple[str, np.ndarray, float]:
        """The ``kind`` initial map with ``fraction`` of its entries (a fixed random choice)
        replaced by random vertices of B: (key, map, seconds of the underlying initial map)."""
        f0, seconds = self.initial(kind)
        key = f"{kind}-rand{round(100 * fraction)}"
        if key not in self._starts:
            rng = np.random.default_rng(self.seed)
            f = f0.copy()
            pick = rng.random(f.size) < fraction
            f[pick] = rng.integers(0, self.b.n_vertices, int(pick.sum()))
            self._starts[key] = f
        return key, self._starts[key], seconds

    def start_map(self, key: str) -> np.ndarray:
        """An initial map a method started from, by the key in :attr:`MethodResult.start`."""
        return self._starts[key]


def _init(kind: str) -> Callable[[PairContext], MethodResult]:
    def run(ctx: PairContext) -> MethodResult:
        f0, seconds = ctx.initial(kind)
        return MethodResult(f0.copy(), seconds)

    return run


def _hope(*, kind: str = "shot", k_max: int = 8, degrade: float = 0.0, **kw):
    def run(ctx: PairContext) -> MethodResult:
        key: str | None
        if degrade:
            key, f0, t_init = ctx.degraded(degrade, kind)
        else:
            (f0, t_init), key = ctx.initial(kind), kind
        sa, sb, t_shapes = ctx.shapes(k_max)
        t = time.perf_counter()
        config = kw.get("config") or MatchConfig()
        resolution = config.resolution
        mixed = resolution.enabled and denser_side(sa, sb, resolution.max_ratio) is not None
        own = mixed or detect_part(sa, sb) is not None or bool(noisy_sides(sa, sb, config))
        if not degrade and own:
            # A part is described at the whole's scale (hope_rs.pipeline.partial), a much
            # denser shape at the other's resolution (hope_rs.pipeline.resolution) and a
            # noisy one on its smoothed copy (hope_rs.pipeline.denoise): the shared start,
            # described at each shape's own, is not HOPE's start there.
            res = match(sa, sb, init=kind, k_max=k_max, **kw)
            t_init, key = 0.0, None
        else:
            res = match(sa, sb, init=f0, k_max=k_max, **kw)
        seconds = t_init + t_shapes + time.perf_counter() - t
        return MethodResult(res.map, seconds, key, res.confidence, res.quality)

    return run


def _zoomout(kind: str) -> Callable[[PairContext], MethodResult]:
    def run(ctx: PairContext) -> MethodResult:
        try:
            from pyFM.mesh import TriMesh
            from pyFM.refine.zoomout import mesh_zoomout_refine_p2p
        except ImportError:
            raise ValueError(
                "the zoomout methods need pyFM: pip install pyfmaps (or hope-rs[eval])"
            ) from None
        f0, t_init = ctx.initial(kind)
        t = time.perf_counter()
        k = ZOOMOUT_K_INIT + ZOOMOUT_STEPS * ZOOMOUT_STEP
        mesh_a = TriMesh(np.array(ctx.a.vertices), np.array(ctx.a.faces), area_normalize=True)
        mesh_b = TriMesh(np.array(ctx.b.vertices), np.array(ctx.b.faces), area_normalize=True)
        mesh_a.process(k=k, intrinsic=False, verbose=False)
        mesh_b.process(k=k, intrinsic=False, verbose=False)
        # pyFM's p2p_21 lists a vertex of mesh1 for each vertex of mesh2; our maps (A → B) are
        # that with mesh1 = B and mesh2 = A.
        _, p2p = mesh_zoomout_refine_p2p(
            f0, mesh_b, mesh_a, ZOOMOUT_K_INIT, nit=ZOOMOUT_STEPS, step=ZOOMOUT_STEP,
            return_p2p=True,
        )  # fmt: skip
        return MethodResult(np.asarray(p2p, dtype=np.int64), t_init + time.perf_counter() - t, kind)

    return run


#: name → (one-line description, runner)
METHODS: dict[str, tuple[str, Callable[[PairContext], MethodResult]]] = {
    "init": ("SHOT initial map (descriptors + assignment)", _init("shot")),
    "init-wks": ("WKS initial map", _init("wks")),
    "init-hks": ("HKS initial map", _init("hks")),
    "hope": ("HOPE, default parameters, SHOT start", _hope()),
    "zoomout": ("ZoomOut (pyFM) 20→100, from the SHOT initial map", _zoomout("shot")),
    "zoomout-wks": ("ZoomOut (pyFM) 20→100, from the WKS initial map", _zoomout("wks")),
    "hope-nospectral": ("HOPE's own map, without the spectral pass", _hope(spectral=False)),
    "hope-nolmd": ("HOPE without LMD: every vertex a witness", _hope(min_consistent=0.0)),
    "hope-fixedk": ("HOPE with a single fixed k = 8", _hope(schedule=[8])),
    "hope-k4": ("HOPE with k_max = 4", _hope(k_max=4)),
    "hope-k12": ("HOPE with k_max = 12", _hope(k_max=12)),
    "hope-fullres": (
        "HOPE at each shape's own resolution (the resolution stage off)",
        _hope(
            config=MatchConfig(
                resolution=dataclasses.replace(MatchConfig().resolution, enabled=False)
            )
        ),
    ),
    "hope-noorient": (
        "HOPE without the orient stage (no orientation repair)",
        _hope(config=MatchConfig(orient=dataclasses.replace(MatchConfig().orient, enabled=False))),
    ),
    "hope-rand25": ("HOPE from SHOT with 25% of it randomised", _hope(degrade=0.25)),
    "hope-rand50": ("HOPE from SHOT with 50% of it randomised", _hope(degrade=0.50)),
    "hope-rand75": ("HOPE from SHOT with 75% of it randomised", _hope(degrade=0.75)),
}
DEFAULT_METHODS = ("init", "hope", "zoomout")
#: Methods that need pyFM (``pip install pyfmaps``).
PYFM_METHODS = tuple(n for n in METHODS if n.startswith("zoomout"))
ABLATIONS = tuple(n for n in METHODS if n.startswith("hope-"))


def check_methods(names) -> list[str]:
    """Validate a list of method names (or one comma-separated string)."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    if not names:
        raise ValueError("no methods given; choose from " + ", ".join(METHODS))
    bad = [n for n in names if n not in METHODS]
    if bad:
        raise ValueError(f"unknown method(s) {', '.join(bad)}; choose from {', '.join(METHODS)}")
    return list(dict.fromkeys(names))


def run_method(name: str, ctx: PairContext) -> MethodResult:
    """Run the method ``name`` on the pair in ``ctx``."""
    return METHODS[check_methods([name])[0]][1](ctx)
