"""A deformation-aware pass for shapes that are not isometric (a gorilla and a human).

HOPE's hop counts and ZoomOut's spectral embeddings both read intrinsic geometry, which a
non-isometric pair does not share: the map comes back right region by region but slid within
each region, a diffuse stretch. This pass moves A towards B along the current map (a smooth
displacement: the map's displacements projected onto A's first few Laplace–Beltrami
eigenfunctions, Smooth Shells' idea of aligning low-frequency shells) and matches each
vertex of A to the vertex of B nearest in a product space: the deformed coordinates plus,
lightly weighted, the spectral embedding mapped by the functional map (which keeps a
vertex off a nearby part that its deformed position touches). Repeated a few times.

It reads the spectral pass's eigenbases, and runs only when that pass computed them and the
two shapes' spectra differ (:func:`spectral_mismatch`): isometric
shapes have the same Laplace–Beltrami eigenvalues at unit area, and on them the pass would
trade HOPE's sub-edge accuracy for a nearest-point map (docs/decisions.md#deform).
"""

from __future__ import annotations

import time

import numpy as np

from .._blas import single_threaded_blas
from ..features.descriptors import rayleigh_quotients
from ..shape import Shape
from .config import DeformConfig
from .spectral import functional_map, nearest_rows
from .state import QUIET, MatchState, Stage
from .turned import is_open


def _non_null(q: np.ndarray) -> np.ndarray:
    """Eigenvalues without the null ones, one per piece of the mesh (its constants): a second
    closed piece would otherwise set a zero against the other shape's first frequency."""
    return q[q > NULL_SHARE * max(float(q.max(initial=0.0)), 1e-300)]


#: Eigenvalues below this share of the largest computed are null.
NULL_SHARE = 1e-8


def spectral_mismatch(a: Shape, b: Shape, n: int = DeformConfig.n_eigenvalues) -> float:
    """Mean |log(λ_i(A) / λ_i(B))| over the first ``n`` non-zero Laplace–Beltrami eigenvalues
    of both shapes at unit area (Rayleigh quotients of their spectral bases): about 0 for
    isometric shapes, whatever their triangulations; a body against another body's
    proportions gives several times more."""
    la, lb = (_non_null(rayleigh_quotients(s.internal, s.spectral_basis(n + 1)[0])) for s in (a, b))
    m = min(la.size, lb.size)
    if m == 0:
        return 0.0
    la, lb = np.maximum(la[:m], 1e-12), np.maximum(lb[:m], 1e-12)
    return float(np.mean(np.abs(np.log(la / lb))))


def deform_refine(a: Shape, b: Shape, f: np.ndarray, config: DeformConfig = DeformConfig()):
    """The map ``f`` (A → B, internal numbering) after ``config.iterations`` rounds of: A's
    coordinates (unit area) moved by the low-pass part (A's first ``config.k_displacement``
    eigenfunctions, mass-weighted projection) of the displacement to their images, then every
    vertex of A sent to the vertex of B nearest in [deformed coordinates,
    ``config.spectral_weight`` × spectral embedding (``config.k_spectral`` functions, B's
    mapped by the functional map of the current map)]."""
    k = max(config.k_spectral, config.k_displacement)
    phi_a, mass_a = a.spectral_basis(k)
    phi_b, _ = b.spectral_basis(k)
    k = min(k, phi_a.shape[1], phi_b.shape[1])
    ks, kx = min(config.k_spectral, k), min(config.k_displacement, k)
    xa, xb = a.points / a.scale, b.points / b.scale
    t = np.asarray(f, dtype=np.int64)
    low = phi_a[:, :kx]
    w = config.spectral_weight
    with single_threaded_blas():
        for _ in range(config.iterations):
            y = xa + low @ (low.T @ (mass_a[:, None] * (xb[t] - xa)))
            c = functional_map(phi_a[:, :ks], mass_a, phi_b[t, :ks])
            ea = np.hstack([y, w * phi_a[:, :ks]])
            eb = np.hstack([xb, w * (phi_b[:, :ks] @ c.T)])
            t = nearest_rows(ea, eb)
    return t


class DeformStage(Stage):
    """The "deform" stage: :func:`deform_refine` of the map when the shapes' spectra differ by
    more than ``DeformConfig.min_mismatch`` (:func:`spectral_mismatch`)."""

    name = "deform"
    runs_on_final_map = False

    def attach(self, state: MatchState) -> None:
        #: The shapes' spectral mismatch and the seconds it took, measured by skip_reason.
        self.mismatch, self.gate_seconds = 0.0, 0.0

    def skip_reason(self, state: MatchState):
        cfg = state.config.deform
        if not cfg.enabled or state.f is None:
            return QUIET
        if state.landmarks is not None or state.partial is not None:
            return QUIET  # the landmarks' and the partial stage's maps are not re-matched here
        a, b = state.a, state.b
        k = max(cfg.k_spectral, cfg.k_displacement, cfg.n_eigenvalues + 1)
        if state.zoomout is None or not (a.has_spectral_basis(k) and b.has_spectral_basis(k)):
            # The spectral pass did not run in this match (disabled, too large, too small): no
            # basis to read, and solving one here would cost more than the pass. A basis an
            # earlier match left on the shapes does not count: the map would depend on it.
            return QUIET
        if any(is_open(s) for s in (a, b)):
            return QUIET  # an open surface's spectrum differs from a closed one's for that alone
        t = time.perf_counter()
        try:
            self.mismatch = spectral_mismatch(a, b, cfg.n_eigenvalues)
        except RuntimeError:  # an eigenbasis the spectral pass could not read either
            return "an eigenbasis could not be computed"
        self.gate_seconds = time.perf_counter() - t
        if self.mismatch <= cfg.min_mismatch:
            return QUIET  # isometric shapes: the common case, not worth a line in the log
        return None

    def run(self, state: MatchState) -> None:
        cfg = state.config.deform
        t = time.perf_counter()
        f = state.f
        assert f is not None  # skip_reason checked it
        state.log.start("deform", detail="deforming A towards B along the map")
        g = deform_refine(state.a, state.b, f, cfg)
        state.f = g
        state.timings["deform"] = self.gate_seconds + time.perf_counter() - t
        state.log.ran(
            "deform",
            state.timings["deform"],
            f"spectra differ by {self.mismatch:.3f}; changed {int(np.count_nonzero(g != f))} "
            f"of {g.size} vertices",
        )
