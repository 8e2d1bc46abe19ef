"""Per-vertex descriptors for the initial map: SHOT (default), HKS and WKS."""

from __future__ import annotations

import numpy as np

from .mesh import Mesh
from .numbering import canonical_mesh, canonical_order, inverse_permutation

#: SHOT support radius as a multiple of sqrt(surface area).
SHOT_RADIUS = 0.1


def shot(mesh: Mesh, *, radius: float = SHOT_RADIUS) -> np.ndarray:
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
    share the descriptor of one of them (:mod:`hope_rs.sites`), which keeps the cost linear
    in the vertex count instead of quadratic.
    """
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive number, got {radius}")
    canon, _, rank = canonical_mesh(mesh)
    return _shot_as_numbered(canon, radius)[rank]


def _shot_as_numbered(mesh: Mesh, radius: float = SHOT_RADIUS, sites=False) -> np.ndarray:
    # Computed in the numbering given: its sums run in neighbour order, and where a local frame
    # is nearly degenerate the last bits decide an axis (0.14% of the TOSCA cat's vertices
    # changed, by up to 0.23, under a random renumbering). The public functions pass the
    # position-fixed numbering (hope_rs.numbering), so relabelling a mesh relabels its
    # descriptors bit for bit. The same holds for every `_as_numbered` function below.
    # ``sites``: those of hope_rs.sites.shot_sites for this mesh and radius if the caller has
    # them (None: every vertex is described); False: find them here.
    from . import _core
    from .sites import shot_sites

    if sites is False:
        sites = shot_sites(mesh, radius)
    if sites is None:
        r = float(radius) * mesh.scale
        return _core.shot_descriptors(mesh.vertices, mesh.faces, r).reshape(mesh.n_vertices, -1)
    # A dense mesh: one descriptor per grid cell, shared by its vertices (see hope_rs.sites).
    at, owner = sites
    return shot_at(mesh, at, radius)[owner]


def shot_at(mesh: Mesh, at: np.ndarray, radius: float = SHOT_RADIUS) -> np.ndarray:
    """SHOT of the vertices ``at`` of ``mesh`` only, ``(len(at), 352)``, every vertex of the
    mesh voting in their supports (rows equal those of :func:`shot` on the same numbering)."""
    from . import _core

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


def laplacian_basis_as_numbered(mesh: Mesh, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`laplacian_eigenpairs` in ``mesh``'s own numbering, plus the lumped mass of each
    vertex ``(n,)`` (of the mesh scaled to unit area), the weights of the inner product in
    which the eigenvectors are orthonormal."""
    import scipy.sparse.linalg as sla

    try:
        import robust_laplacian
    except ImportError:
        raise ImportError(
            "WKS/HKS descriptors need the robust-laplacian package: pip install robust-laplacian"
        ) from None

    k = int(min(k, mesh.n_vertices - 2))
    if k < 1:
        raise ValueError("the mesh is too small for a Laplacian spectrum")
    L, M = robust_laplacian.mesh_laplacian(mesh.vertices / mesh.scale, mesh.faces)
    # A fixed start vector: ARPACK's own is random.
    v0 = np.random.default_rng(0).random(mesh.n_vertices)
    # Shift-invert about a small negative value: L is singular (constants), L + eps*M is not.
    evals, evecs = sla.eigsh(L, k=k, M=M, sigma=-1e-8, which="LM", v0=v0)
    by_value = np.argsort(evals)
    return np.maximum(evals[by_value], 0.0), evecs[:, by_value], np.asarray(M.diagonal())


def hks(evals: np.ndarray, evecs: np.ndarray, n_scales: int = 100) -> np.ndarray:
    """Heat kernel signature at log-spaced times (Sun et al. 2009), each scale normalised."""
    lam = evals[1:] if evals[0] < 1e-10 else evals
    t = np.geomspace(4 * np.log(10) / lam[-1], 4 * np.log(10) / lam[0], n_scales)
    weights = np.exp(-np.outer(evals, t))  # (k, T)
    d = (evecs**2) @ weights
    return d / np.maximum(np.linalg.norm(d, axis=0, keepdims=True), 1e-300)


def wks(evals: np.ndarray, evecs: np.ndarray, n_energies: int = 100) -> np.ndarray:
    """Wave kernel signature (Aubry et al. 2011) with the usual log-energy Gaussian bands."""
    lam = np.maximum(evals, 1e-12)
    log_e = np.log(lam[1:] if evals[0] < 1e-10 else lam)
    e_min, e_max = log_e[0], log_e[-1]
    sigma = 7 * (e_max - e_min) / n_energies
    e_min, e_max = e_min + 2 * sigma, e_max - 2 * sigma
    energies = np.linspace(e_min, e_max, n_energies)
    coefs = np.exp(-((energies[None, :] - np.log(lam)[:, None]) ** 2) / (2 * sigma**2))
    if evals[0] < 1e-10:
        coefs[0] = 0.0  # the constant eigenvector carries no shape information
    d = (evecs**2) @ coefs / np.maximum(coefs.sum(axis=0), 1e-300)
    return d / np.maximum(np.linalg.norm(d, axis=0, keepdims=True), 1e-300)


def descriptors(mesh: Mesh, kind: str = "shot", *, n_eigen: int = 100) -> np.ndarray:
    """Descriptors of ``kind`` in {"shot", "wks", "hks"} for every vertex of ``mesh``, computed
    in the position-fixed numbering (:mod:`hope_rs.numbering`) and returned in ``mesh``'s."""
    check_kind(kind)
    canon, _, rank = canonical_mesh(mesh)
    return descriptors_as_numbered(canon, kind, n_eigen=n_eigen)[rank]


def descriptors_as_numbered(mesh: Mesh, kind: str = "shot", *, n_eigen: int = 100) -> np.ndarray:
    """:func:`descriptors` computed in ``mesh``'s own numbering, for a mesh already in the
    position-fixed one (a :class:`~hope_rs.Shape`'s internal mesh)."""
    check_kind(kind)
    if kind == "shot":
        return _shot_as_numbered(mesh)
    evals, evecs = _eigenpairs_as_numbered(mesh, n_eigen)
    return (wks if kind == "wks" else hks)(evals, evecs)


def check_kind(kind: str) -> None:
    if kind not in ("shot", "wks", "hks"):
        raise ValueError(f"unknown descriptor {kind!r}; choose 'shot', 'wks' or 'hks'")


def spectral_descriptors(kind: str, evals: np.ndarray, evecs: np.ndarray, mesh: Mesh) -> np.ndarray:
    """WKS or HKS of ``mesh`` from its eigenpairs (eigenvectors in the mesh's numbering).

    Computed with the rows in the position-fixed numbering (:mod:`hope_rs.numbering`): the
    column norms sum over every row, and the matrix product's last bits can depend on a row's
    position, so this is what makes relabelling the mesh relabel the result bit for bit.
    """
    order = canonical_order(mesh.vertices)
    return (wks if kind == "wks" else hks)(evals, evecs[order])[inverse_permutation(order)]
