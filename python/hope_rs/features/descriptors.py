"""Per-vertex descriptors for the initial map: SHOT (default), HKS and WKS."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse.linalg as sla

from .. import _core
from .._blas import single_threaded_blas, with_single_threaded_blas
from .._cancel import check
from ..geometry.coarsen import CoarsenConfig, coarse_mesh
from ..geometry.mesh import Mesh
from ..geometry.numbering import canonical_mesh, canonical_order, inverse_permutation
from ..geometry.sites import SiteConfig, shot_sites


@dataclass(frozen=True)
class DescriptorConfig:
    """Settings of the per-vertex descriptors (docs/decisions.md#descriptors).

    Attributes
    ----------
    shot_radius : float
        SHOT support radius as a multiple of sqrt(surface area).
    sites : SiteConfig
        When vertices of a dense mesh share SHOT descriptors (:mod:`hope_rs.geometry.sites`).
    n_eigen : int
        Laplacian eigenpairs behind WKS and HKS (at least 2: the first, constant, carries no
        shape information).
    """

    shot_radius: float = field(
        default=0.1, metadata={"range": (0.0, None), "exclusive": True, "finite": True}
    )
    sites: SiteConfig = field(default_factory=SiteConfig)
    n_eigen: int = field(default=100, metadata={"range": (2, 5000)})


@dataclass(frozen=True)
class BasisConfig:
    """How eigenbases of dense meshes are seeded from their coarse copies
    (:func:`laplacian_basis_from_coarse`, docs/decisions.md#spectral).

    Attributes
    ----------
    coarse_extra : int
        Coarse eigenpairs beyond the ``k`` asked for: the Rayleigh–Ritz step then has room
        to sort out the top of the spectrum.
    coarse_iterations : int
        Steps of shifted inverse iteration on the fine mesh.
    coarse_shift : float
        The iteration's shift, as a fraction of the largest coarse eigenvalue: small enough to
        damp the prolongation's high frequencies, large enough that the constant function
        does not swamp the other columns.
    """

    coarse_extra: int = field(default=20, metadata={"range": (0, 5000)})
    coarse_iterations: int = field(default=2, metadata={"range": (0, 1000)})
    coarse_shift: float = 0.05


def shot(mesh: Mesh, *, radius: float = DescriptorConfig.shot_radius) -> np.ndarray:
    """SHOT descriptors (Tombari et al. 2010), ``(n, 352)`` float32, rows L2-normalised.

    Parameters
    ----------
    mesh : Mesh
    radius : float, keyword-only
        Support radius relative to ``sqrt(mesh.area)``.

    Notes
    -----
    SHOT's local frame is right-handed, so a mirror image gets different descriptors: this is
    what lets the initial map tell left from right, which the intrinsic HKS/WKS cannot.

    On meshes much denser than the support radius needs, the vertices of each small grid cell
    share the descriptor of one of them (:mod:`hope_rs.geometry.sites`), which keeps the cost linear
    in the vertex count instead of quadratic.
    """
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive number, got {radius}")
    canon, _, rank = canonical_mesh(mesh)
    return shot_as_numbered(canon, radius)[rank]


def shot_as_numbered(
    mesh: Mesh,
    radius: float = DescriptorConfig.shot_radius,
    sites=False,
    site_config: SiteConfig = SiteConfig(),
) -> np.ndarray:
    """:func:`shot` in ``mesh``'s own numbering."""
    # Computed in the numbering given: its sums run in neighbour order, and where a local frame
    # is nearly degenerate the last bits decide an axis. The public functions pass the
    # position-fixed numbering (hope_rs.geometry.numbering), so relabelling a mesh relabels its
    # descriptors bit for bit. The same holds for every `_as_numbered` function below.
    # ``sites``: those of hope_rs.geometry.sites.shot_sites for this mesh and radius if the caller has
    # them (None: every vertex is described); False: find them here (``site_config``).
    if sites is False:
        sites = shot_sites(mesh, radius, site_config)
    if sites is None:
        r = float(radius) * mesh.scale
        return _core.shot_descriptors(mesh.vertices, mesh.faces, r).reshape(mesh.n_vertices, -1)
    # A dense mesh: one descriptor per grid cell, shared by its vertices (see hope_rs.geometry.sites).
    at, owner = sites
    return shot_at(mesh, at, radius)[owner]


def shot_at(mesh: Mesh, at: np.ndarray, radius: float = DescriptorConfig.shot_radius) -> np.ndarray:
    """SHOT of the vertices ``at`` of ``mesh`` only, ``(len(at), 352)``, every vertex of the
    mesh voting in their supports (rows equal those of :func:`shot` on the same numbering)."""
    r = float(radius) * mesh.scale
    out = _core.shot_descriptors(mesh.vertices, mesh.faces, r, np.asarray(at, dtype=np.int64))
    return out.reshape(len(at), -1)


def laplacian_eigenpairs(mesh: Mesh, k: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest eigenpairs of the robust Laplacian (Sharp & Crane 2020).

    Returns eigenvalues ``(k,)`` (ascending) and mass-orthonormal eigenvectors ``(n, k)`` of the
    mesh scaled to unit area, so values are comparable across shapes.
    """
    canon, _, rank = canonical_mesh(mesh)
    evals, evecs = _eigenpairs_as_numbered(canon, k)
    return evals, evecs[rank]


def _eigenpairs_as_numbered(mesh: Mesh, k: int) -> tuple[np.ndarray, np.ndarray]:
    evals, evecs, _ = laplacian_basis_as_numbered(mesh, k)
    return evals, evecs


def _unit_area_laplacian(mesh: Mesh):
    """The robust Laplacian (cotangent weights, lumped masses) of ``mesh`` scaled to unit area."""
    try:
        import robust_laplacian
    except ImportError:
        raise ImportError(
            "WKS/HKS descriptors need the robust-laplacian package: pip install robust-laplacian"
        ) from None
    return robust_laplacian.mesh_laplacian(mesh.vertices / mesh.scale, mesh.faces)


# ARPACK's small dense steps on a BLAS thread pool run several times slower than on one
# thread, and one thread keeps the bits whatever the caller's thread count.
@with_single_threaded_blas
def laplacian_basis_as_numbered(
    mesh: Mesh, k: int, *, stop: threading.Event | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`laplacian_eigenpairs` in ``mesh``'s own numbering, plus the lumped mass of each
    vertex ``(n,)`` (of the mesh scaled to unit area), the weights of the inner product in
    which the eigenvectors are orthonormal; solved on one BLAS thread. ``stop``: when set,
    the solve raises :class:`~hope_rs._cancel.Cancelled` at its next step."""
    k = int(min(k, mesh.n_vertices - 2))
    if k < 1:
        raise ValueError("the mesh is too small for a Laplacian spectrum")
    L, M = _unit_area_laplacian(mesh)
    # A fixed start vector: ARPACK's own is random.
    v0 = np.random.default_rng(0).random(mesh.n_vertices)
    # Shift-invert about a small negative value: L is singular (constants), L + eps*M is not.
    sigma = -1e-8
    op_inv = _shift_invert(L, M, sigma, stop)
    evals, evecs = sla.eigsh(L, k=k, M=M, sigma=sigma, which="LM", v0=v0, OPinv=op_inv)
    by_value = np.argsort(evals)
    return np.maximum(evals[by_value], 0.0), evecs[:, by_value], np.asarray(M.diagonal())


def rayleigh_quotients(mesh: Mesh, evecs: np.ndarray) -> np.ndarray:
    """``evecs[:, i]ᵀ L evecs[:, i]`` for each column, with ``L`` the robust Laplacian of
    ``mesh`` scaled to unit area: the eigenvalues of mass-orthonormal eigenvectors in
    ``mesh``'s numbering (and close to them for the coarse-seeded basis)."""
    L, _ = _unit_area_laplacian(mesh)
    return np.einsum("ij,ij->j", evecs, L @ evecs)


def _shift_invert(L, M, sigma: float, stop: threading.Event | None):
    """``x -> (L - sigma M)^-1 x`` as ARPACK's shift-invert operator: the LU factorisation
    ``eigsh`` builds itself for sparse symmetric input (same matrix, same bits), with a check of
    ``stop`` before every solve, which is what makes the eigensolve cancellable."""
    op = L - sigma * M
    # CSR of a real symmetric matrix transposes to CSC for free, as eigsh does.
    op = op.T if op.format == "csr" and not np.iscomplexobj(op.data) else op.tocsc()
    lu = sla.splu(op)

    def solve(x):
        check(stop)
        return lu.solve(np.asarray(x).astype(op.dtype))

    return sla.LinearOperator(op.shape, matvec=solve, dtype=op.dtype)


def laplacian_basis_from_coarse(
    mesh: Mesh,
    owner: np.ndarray,
    coarse: Mesh,
    k: int,
    *,
    config: BasisConfig = BasisConfig(),
    stop: threading.Event | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`laplacian_basis_as_numbered` approximated from a coarse copy of ``mesh``
    (``owner[i]``: the vertex of ``coarse`` that fine vertex ``i`` belongs to).

    The coarse eigenvectors, copied to the fine vertices, span nearly the right subspace but
    are piecewise constant; ``config.coarse_iterations`` steps of shifted inverse iteration on
    the fine Laplacian (one sparse factorisation, block solves) smooth them, and a
    Rayleigh–Ritz step turns the subspace into mass-orthonormal approximate eigenvectors:
    faster than ARPACK on the fine mesh, with the same accuracy of the match
    (docs/decisions.md#spectral). Raises ``RuntimeError`` when the subspace collapses.
    ``stop``: see :func:`laplacian_basis_as_numbered`.
    """
    k = int(min(k, mesh.n_vertices - 2))
    p = int(min(k + config.coarse_extra, coarse.n_vertices - 2))
    if p < k:
        raise RuntimeError(f"the coarse copy ({coarse.n_vertices} vertices) is too small for {k}")
    evals_c, evecs_c, _ = laplacian_basis_as_numbered(coarse, p, stop=stop)
    L, M = _unit_area_laplacian(mesh)
    shift = config.coarse_shift * max(float(evals_c[-1]), 1e-8)
    check(stop)
    lu = sla.splu((L + shift * M).tocsc())
    v = evecs_c[owner]
    for _ in range(config.coarse_iterations):
        check(stop)
        v = lu.solve(np.asfortranarray(M @ v))
        # Rayleigh–Ritz, robust to a nearly dependent block: orthonormalise through the
        # eigenvectors of the mass Gram matrix, dropping directions it cannot resolve.
        gram_m = v.T @ (M @ v)
        d, q = np.linalg.eigh(0.5 * (gram_m + gram_m.T))
        keep = d > 1e-10 * d[-1]
        t = q[:, keep] / np.sqrt(d[keep])
        gram_l = t.T @ (v.T @ (L @ v)) @ t
        w, y = np.linalg.eigh(0.5 * (gram_l + gram_l.T))
        v = v @ (t @ y)
    if v.shape[1] < k or not np.all(np.isfinite(v[:, :k])):
        raise RuntimeError("the coarse-seeded eigenbasis collapsed")
    return np.maximum(w[:k], 0.0), v[:, :k], np.asarray(M.diagonal())


def spectral_basis_of(
    mesh: Mesh,
    k: int,
    *,
    coarse=False,
    config: BasisConfig = BasisConfig(),
    coarsen: CoarsenConfig = CoarsenConfig(),
    stop: threading.Event | None = None,
) -> tuple:
    """The spectral pass's eigenpairs ``(evals, evecs, mass)`` of ``mesh``: from its coarse
    copy when the mesh is dense enough to have one (:func:`laplacian_basis_from_coarse`),
    otherwise, or should that fail, by ARPACK on the mesh itself
    (:func:`laplacian_basis_as_numbered`). ``coarse``: the
    :class:`~hope_rs.geometry.coarsen.Coarse` copy if known, ``None`` if known not to exist,
    ``False`` to build it here (with ``coarsen``).

    Solved on one BLAS thread, so that the bits do not depend on who asks: :func:`hope_rs.match`
    solves in a background thread while HOPE refines (see
    :class:`~hope_rs.pipeline.spectral.BasisPrefetch`), the batch cache ahead of the pairs.
    ``stop``: when set, the solve raises :class:`~hope_rs._cancel.Cancelled` at its next
    step."""
    with single_threaded_blas():
        return _spectral_basis_of(mesh, k, coarse, config, coarsen, stop)


def _spectral_basis_of(
    mesh: Mesh, k: int, coarse, config: BasisConfig, coarsen: CoarsenConfig, stop=None
) -> tuple:
    if coarse is False:
        coarse = coarse_mesh(mesh, coarsen)
    if coarse is not None:
        try:
            return laplacian_basis_from_coarse(
                mesh, coarse.owner, coarse.mesh, k, config=config, stop=stop
            )
        except (RuntimeError, np.linalg.LinAlgError):
            pass
    return laplacian_basis_as_numbered(mesh, k, stop=stop)


#: Laplacian eigenvalues below this are null (their eigenvectors are constant on each piece).
NULL_EIGENVALUE = 1e-10


def hks(evals: np.ndarray, evecs: np.ndarray, n_scales: int = 100) -> np.ndarray:
    """Heat kernel signature at log-spaced times (Sun et al. 2009), each scale normalised."""
    lam = evals[evals >= NULL_EIGENVALUE]  # one null eigenvalue per piece of the mesh
    if lam.size == 0:
        # A mesh too small to have a non-constant eigenfunction: every vertex alike.
        return np.full((evecs.shape[0], n_scales), 1.0 / np.sqrt(evecs.shape[0]))
    t = np.geomspace(4 * np.log(10) / lam[-1], 4 * np.log(10) / lam[0], n_scales)
    weights = np.exp(-np.outer(evals, t))  # (k, T)
    d = (evecs**2) @ weights
    return d / np.maximum(np.linalg.norm(d, axis=0, keepdims=True), 1e-300)


def wks(evals: np.ndarray, evecs: np.ndarray, n_energies: int = 100) -> np.ndarray:
    """Wave kernel signature (Aubry et al. 2011) with the usual log-energy Gaussian bands."""
    lam = np.maximum(evals, 1e-12)
    null = evals < NULL_EIGENVALUE  # one per piece of the mesh
    log_e = np.log(lam[~null])
    if log_e.size == 0:
        # A mesh too small to have a non-constant eigenfunction: every vertex alike.
        return np.full((evecs.shape[0], n_energies), 1.0 / np.sqrt(evecs.shape[0]))
    e_min, e_max = log_e[0], log_e[-1]
    sigma = 7 * (e_max - e_min) / n_energies
    if sigma > 0:
        e_min, e_max = e_min + 2 * sigma, e_max - 2 * sigma
    else:
        # One distinct eigenvalue (a regular tetrahedron): bands of unit width around it.
        sigma, e_min, e_max = 1.0, e_min - 1.0, e_max + 1.0
    energies = np.linspace(e_min, e_max, n_energies)
    coefs = np.exp(-((energies[None, :] - np.log(lam)[:, None]) ** 2) / (2 * sigma**2))
    coefs[null] = 0.0  # the constant eigenvectors (per piece) carry no shape information
    d = (evecs**2) @ coefs / np.maximum(coefs.sum(axis=0), 1e-300)
    return d / np.maximum(np.linalg.norm(d, axis=0, keepdims=True), 1e-300)


def descriptors(mesh: Mesh, kind: str = "shot", *, n_eigen: int = 100) -> np.ndarray:
    """Descriptors of ``kind`` in {"shot", "wks", "hks"} for every vertex of ``mesh``, computed
    in the position-fixed numbering (:mod:`hope_rs.geometry.numbering`) and returned in ``mesh``'s."""
    check_kind(kind)
    canon, _, rank = canonical_mesh(mesh)
    return descriptors_as_numbered(canon, kind, n_eigen=n_eigen)[rank]


def descriptors_as_numbered(
    mesh: Mesh, kind: str = "shot", *, n_eigen: int = DescriptorConfig.n_eigen
) -> np.ndarray:
    """:func:`descriptors` computed in ``mesh``'s own numbering, for a mesh already in the
    position-fixed one (a :class:`~hope_rs.Shape`'s internal mesh)."""
    check_kind(kind)
    if kind == "shot":
        return shot_as_numbered(mesh)
    evals, evecs = _eigenpairs_as_numbered(mesh, n_eigen)
    with single_threaded_blas():  # the product's bits whatever the thread count
        return (wks if kind == "wks" else hks)(evals, evecs)


def check_kind(kind: str) -> None:
    if kind not in ("shot", "wks", "hks"):
        raise ValueError(f"unknown descriptor {kind!r}; choose 'shot', 'wks' or 'hks'")


def spectral_descriptors(kind: str, evals: np.ndarray, evecs: np.ndarray, mesh: Mesh) -> np.ndarray:
    """WKS or HKS of ``mesh`` from its eigenpairs (eigenvectors in the mesh's numbering).

    Computed with the rows in the position-fixed numbering (:mod:`hope_rs.geometry.numbering`): the
    column norms sum over every row, and the matrix product's last bits can depend on a row's
    position, so this is what makes relabelling the mesh relabel the result bit for bit.
    """
    order = canonical_order(mesh.vertices)
    with single_threaded_blas():  # as descriptors_as_numbered, the same bits
        out = (wks if kind == "wks" else hks)(evals, evecs[order])
    return out[inverse_permutation(order)]
