"""Per-shape precomputation reused across every pair a shape takes part in."""

from __future__ import annotations

import copy
import numbers
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.sparse as sp

from . import _core
from .features.descriptors import (
    BasisConfig,
    DescriptorConfig,
    descriptors_as_numbered,
    shot_as_numbered,
    spectral_basis_of,
)
from .geometry.coarsen import Coarse, CoarsenConfig, coarse_mesh
from .geometry.mesh import Mesh, as_mesh, scale_exponent, unique_edges
from .geometry.numbering import canonical_mesh
from .geometry.roughness import normal_roughness, umbrella_smoothed
from .geometry.sites import shot_sites

__all__ = ["Shape", "ShapeConfig"]

#: :meth:`Shape.at_scale` takes scales within this factor of the shape's own sqrt(area) and
#: its inverse: a part is measured at its whole's scale, never a million times off.
MIN_SCALE_RATIO = 1e-6


@dataclass(frozen=True)
class ShapeConfig:
    """Settings of a :class:`Shape`'s precomputation.

    Attributes
    ----------
    descriptors : DescriptorConfig
        SHOT radius, SHOT sites on dense meshes, eigenpairs of WKS/HKS.
    basis : BasisConfig
        Eigenbases of dense meshes seeded from their coarse copies.
    coarsen : CoarsenConfig
        The coarse copy (multiscale matching, basis seeding).
    """

    descriptors: DescriptorConfig = field(default_factory=DescriptorConfig)
    basis: BasisConfig = field(default_factory=BasisConfig)
    coarsen: CoarsenConfig = field(default_factory=CoarsenConfig)


class Shape:
    """A mesh with its k-hop neighbourhoods (up to ``k_max``) and cached descriptors.

    Build one per mesh and pass it to :func:`hope_rs.match` as often as you like: the
    neighbourhoods and descriptors are computed once.

    Internally the shape numbers its vertices by position (see :mod:`hope_rs.geometry.numbering`), so
    that no result depends on how the input happens to be numbered. ``mesh`` and
    :meth:`descriptors` keep the input's numbering; ``graph`` and ``points``, which the
    refinement works on, use the internal one: internal vertex ``i`` is input vertex
    ``order[i]``, and input vertex ``v`` is internal vertex ``rank[v]``.

    The internal mesh's faces are oriented consistently and outward
    (:mod:`hope_rs.geometry.orientation`), so a mesh whose faces wind the other way is matched like the
    mesh itself, not like its mirror image; and its coordinates are the input's times
    ``4**scale_exponent`` (:func:`hope_rs.geometry.mesh.scale_exponent`: 0 for meshes of ordinary size),
    so that coordinates near the limits of double precision match like ordinary ones.

    Parameters
    ----------
    mesh : Mesh, (vertices, faces), a mesh file's path or a mesh object
        Anything :func:`~hope_rs.geometry.mesh.as_mesh` reads (trimesh, open3d).
    k_max : int, keyword-only
        Largest hop radius the refinement may use.
    orient : bool, keyword-only
        Orient the internal mesh's faces (:mod:`hope_rs.geometry.orientation`); ``False``
        keeps them as given (for meshes derived from an oriented one, such as the multiscale
        coarse copy).
    config : ShapeConfig, keyword-only
        Settings of the descriptors, eigenbases and coarse copy.
    """

    def __init__(
        self, mesh, *, k_max: int = 8, orient: bool = True, config: ShapeConfig = ShapeConfig()
    ):
        if not isinstance(orient, (bool, np.bool_)):  # bool("false") would be True
            raise TypeError(f"orient must be a bool (True or False), got {orient!r}")
        mesh = as_mesh(mesh)
        if (
            isinstance(k_max, bool)
            or not isinstance(k_max, (int, np.integer))
            or not 2 <= k_max <= 64
        ):
            raise ValueError(f"k_max must be an integer in [2, 64], got {k_max!r}")
        if not isinstance(config, ShapeConfig):
            raise TypeError(
                f"config must be a hope_rs.shape.ShapeConfig, got {type(config).__name__}; the "
                "settings of a match go to match(config=MatchConfig(...))"
            )
        self.mesh = mesh
        self.k_max = int(k_max)
        self.orient = bool(orient)
        self.config = config
        self.internal, self.order, self.rank = canonical_mesh(mesh, orient=orient)
        # The internal mesh's coordinates are the input's times 4**scale_exponent (exact).
        self.scale_exponent = scale_exponent(mesh.vertices)
        # From the internal mesh, so that its float sums run in an order that does not depend
        # on the input's numbering either.
        self.scale = self.internal.scale
        self.graph = _core.MeshGraph(self.internal.vertices, self.internal.faces, self.k_max)
        # In the internal numbering: the initial map reads them there, and a second copy in
        # the input's numbering would double their memory.
        self._descriptors: dict[str, np.ndarray] = {}
        # False: not yet known.
        self._sites: tuple[np.ndarray, np.ndarray] | None | Literal[False] = False
        self._coarse: tuple[Coarse, Shape] | None | Literal[False] = False
        self._coarse_view: tuple[Coarse, Shape] | None = None  # a view's, at its scale
        self._basis: tuple[np.ndarray, np.ndarray] | None = None
        self._edges: np.ndarray | None = None
        self._euler: int | None = None
        self._ring: sp.csr_matrix | None = None
        self._without: tuple[object, Shape] | None = None  # see without()
        # smoothing_drop and smoothed()'s copies at the own scale, by iteration count: shared
        # by this shape's at_scale views (the geometry does not depend on the scale).
        self._smoothing: dict = {}
        self._smoothed_from: tuple[Shape, int] | None = None  # a smoothed() copy's origin

    def __reduce__(self):
        if self._smoothed_from is not None:
            # A smoothed copy keeps its origin's numbering: rebuilt from the origin.
            origin, iterations = self._smoothed_from
            return (_smoothed_copy, (origin, iterations, self.scale))
        # The Rust graph cannot be pickled: a copy is built again from the mesh and settings,
        # and keeps its scale (a view's, :meth:`at_scale`), the descriptors and the eigenbasis
        # already computed (the costly parts).
        args = (self.mesh, self.k_max, self.orient, self.config)
        state = {"scale": self.scale, "_descriptors": self._descriptors, "_basis": self._basis}
        return (_rebuilt, args, state)

    def __copy__(self) -> Shape:
        # A shallow copy shares everything, the graph included (what at_scale's views need).
        out = object.__new__(Shape)
        out.__dict__.update(self.__dict__)
        return out

    @property
    def points(self) -> np.ndarray:
        """Vertex positions in the internal numbering."""
        return self.internal.vertices

    @property
    def edges(self) -> np.ndarray:
        """The undirected edges ``(low, high)`` of the internal mesh, computed once."""
        if self._edges is None:
            self._edges = unique_edges(self.internal.faces)
        return self._edges

    @property
    def euler_characteristic(self) -> int:
        """V - E + F of the mesh's faces (vertices no face uses and repeated faces not
        counted): 2 for a closed surface of genus 0, 2 less for each handle, 1 less for each
        boundary loop and for each vertex where two sheets are welded, 2 more for each
        further component."""
        if self._euler is None:
            faces = np.sort(self.internal.faces, axis=1)
            rows = faces[np.lexsort(faces.T[::-1])]  # a 1-D sort per column, not unique(axis=0)
            n_faces = int(rows.shape[0] > 0) + int(np.any(np.diff(rows, axis=0), axis=1).sum())
            self._euler = int(np.unique(faces).size - self.edges.shape[0] + n_faces)
        return self._euler

    def ring_average(self) -> sp.csr_matrix:
        """The operator averaging a vertex function over each closed 1-ring of the internal
        mesh (rows sum to 1), built once."""
        if self._ring is None:
            n, e = self.n_vertices, self.edges
            rows = np.concatenate([e[:, 0], e[:, 1], np.arange(n)])
            cols = np.concatenate([e[:, 1], e[:, 0], np.arange(n)])
            m = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
            self._ring = sp.diags(1.0 / np.asarray(m.sum(axis=1)).ravel()) @ m
        return self._ring

    @property
    def n_vertices(self) -> int:
        return self.mesh.n_vertices

    def descriptors(self, kind: str = "shot") -> np.ndarray:
        """Descriptors of ``kind`` ("shot", "wks", "hks") in the input's numbering, computed
        once and cached (each call returns a new array)."""
        return self.internal_descriptors(kind)[self.rank]

    def internal_descriptors(self, kind: str = "shot") -> np.ndarray:
        """:meth:`descriptors` in the internal numbering (the cached array itself)."""
        if kind not in self._descriptors:
            # The internal mesh is in the position-fixed numbering already: this equals
            # descriptors(self.mesh, kind)[self.order] bit for bit, without renumbering again.
            cfg = self.config.descriptors
            self._descriptors[kind] = (
                shot_as_numbered(self.internal, self.shot_radius(), self.descriptor_sites("shot"))
                if kind == "shot"
                else descriptors_as_numbered(self.internal, kind, n_eigen=cfg.n_eigen)
            )
        return self._descriptors[kind]

    def descriptor_sites(self, kind: str = "shot") -> tuple[np.ndarray, np.ndarray] | None:
        """(``sites``, ``owner``) in the internal numbering when the descriptors of ``kind``
        are shared by the vertices of grid cells (SHOT on dense meshes, see
        :mod:`hope_rs.geometry.sites`): internal vertex ``i`` has the descriptor of ``sites[owner[i]]``.
        ``None`` when every vertex has its own."""
        if kind != "shot":
            return None
        if self._sites is False:
            cfg = self.config.descriptors
            self._sites = shot_sites(self.internal, self.shot_radius(), cfg.sites)
        return self._sites

    @property
    def at_own_scale(self) -> bool:
        """Whether this shape is measured in its own sqrt(area) (not a view at another scale,
        :meth:`at_scale`)."""
        return self.scale == self.internal.scale

    @property
    def density(self) -> float:
        """Vertices per unit area, in the units the shape is measured in (its own sqrt(area),
        or a whole's for a part viewed at that scale, which then has less than unit area)."""
        return self.n_vertices / self.unit_area

    @property
    def unit_area(self) -> float:
        """The shape's area in the units it is measured in: 1 at its own scale, less for a
        part viewed at its whole's scale."""
        return (self.internal.scale / self.scale) ** 2

    def shot_radius(self) -> float:
        """SHOT's support radius relative to the internal mesh's sqrt(area): the configured one,
        stretched when this shape is measured at another scale (:meth:`at_scale`)."""
        # At its own scale the factor is exactly 1.0, so the radius is the configured one.
        return self.config.descriptors.shot_radius * (self.scale / self.internal.scale)

    def at_scale(self, scale: float) -> Shape:
        """This shape measured in units of ``scale`` instead of its own sqrt(area): a view
        sharing the mesh, its numbering and neighbourhoods, with its own descriptor cache (the
        SHOT radius is ``shot_radius * scale``). A part of a shape is matched at the whole's
        scale (:mod:`hope_rs.pipeline.partial`): its own sqrt(area) is smaller, which would
        shrink every distance it compares. Copies of the mesh a view makes (its multiscale
        copy, :meth:`derived`) are measured at the view's scale too."""
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"a shape's scale must be a positive number, got {scale}")
        own = self.internal.scale
        if not MIN_SCALE_RATIO <= scale / own <= 1 / MIN_SCALE_RATIO:
            raise ValueError(
                f"a shape's scale {scale:g} is not within a factor {1 / MIN_SCALE_RATIO:g} of "
                f"its own sqrt(area) {own:g} (distances in its units would underflow or "
                "overflow); is it in the mesh's units?"
            )
        view = copy.copy(self)
        view.scale = float(scale)
        view._descriptors = {}
        view._sites = False
        view._coarse_view = None
        view._without = None
        return view

    def derived(self, mesh: Mesh, *, orient: bool = False) -> Shape:
        """A Shape of ``mesh``, a copy of this shape's mesh in its coordinates (coarser,
        subdivided, reflected; its faces oriented as they come unless ``orient``), with this
        shape's settings and measured in its units: at this shape's scale when that is not its
        own sqrt(area) (:meth:`at_scale`), so that a part's copy is matched at the whole's
        scale as the part is."""
        out = Shape(mesh, k_max=self.k_max, orient=orient, config=self.config)
        return out if self.at_own_scale else out.at_scale(self.scale)

    def without(self, mesh: Mesh, key) -> Shape:
        """The Shape of ``mesh``, this shape's mesh with vertices left out (in no face, or in
        small loose pieces), built as this one was (:meth:`derived`, its face orientation as
        given); kept, with its descriptors and eigenbasis, for the next call with the same
        ``key`` (what decided the vertices left out), so a shape matched many times is
        described once."""
        if self._without is None or self._without[0] != key:
            self._without = (key, self.derived(mesh, orient=self.orient))
        return self._without[1]

    @property
    def roughness(self) -> float:
        """The mesh's normal roughness (:func:`~hope_rs.geometry.roughness.normal_roughness`:
        the median distance of a vertex from its 1-ring's centroid along its normal, in mean
        edge lengths), computed once."""
        if "roughness" not in self._smoothing:
            self._smoothing["roughness"] = normal_roughness(self.internal)
        return self._smoothing["roughness"]

    @property
    def smoothing(self) -> int:
        """How many umbrella smoothings made this shape from the mesh it was built from
        (:meth:`smoothed`, repeated); 0 for a shape of its own mesh."""
        if self._smoothed_from is None:
            return 0
        origin, iterations = self._smoothed_from
        return origin.smoothing + iterations

    @property
    def smoothing_drop(self) -> float:
        """The share of the mesh's normal roughness
        (:func:`~hope_rs.geometry.roughness.normal_roughness`) that one umbrella smoothing
        takes out, computed once: vertex noise goes at once, the offsets of smooth curvature
        barely move (a clean mesh loses a few percent, one with Gaussian vertex noise of a
        fifth of its mean edge length more than a third). 0 for a flat mesh."""
        if "drop" not in self._smoothing:
            before = self.roughness
            after = normal_roughness(umbrella_smoothed(self.internal, 1))
            self._smoothing["drop"] = max(0.0, 1.0 - after / before) if before > 0 else 0.0
        return self._smoothing["drop"]

    def smoothed(self, iterations: int) -> Shape:
        """This shape with its vertices moved ``iterations`` times halfway to their 1-ring's
        centroid (:func:`~hope_rs.geometry.roughness.umbrella_smoothed`): the same numbering,
        faces and k-hop neighbourhoods, its distances those of the smoothed surface (a noisy
        scan's zigzag edge paths run longer than the surface they sample). Measured in the
        smoothed surface's own sqrt(area) when this shape is at its own, else at this view's
        scale (a part at its whole's). The smoothed geometry is made once per ``iterations``
        for this shape and its :meth:`at_scale` views."""
        own = self._smoothing.get(iterations)
        if own is None:
            internal = umbrella_smoothed(self.internal, iterations)
            own = copy.copy(self)
            own.internal = internal
            # Input vertex v is internal vertex rank[v], times 4**scale_exponent (exact).
            own.mesh = Mesh(
                np.ldexp(internal.vertices[self.rank], -2 * self.scale_exponent),
                self.mesh.faces,
            )
            own.scale = internal.scale
            own.graph = _core.MeshGraph(internal.vertices, internal.faces, self.k_max)
            own._descriptors = {}
            own._sites = False
            own._coarse = False
            own._coarse_view = None
            own._basis = None
            own._without = None
            own._smoothing = {}
            own._smoothed_from = (self, iterations)
            self._smoothing[iterations] = own
        return own if self.at_own_scale else own.at_scale(self.scale)

    def has_descriptors(self, kind: str) -> bool:
        """Whether descriptors of ``kind`` are computed or set already."""
        return kind in self._descriptors

    def coarse_level(self) -> tuple[Coarse, Shape] | None:
        """(:class:`~hope_rs.geometry.coarsen.Coarse`, its :class:`Shape`) of this shape's internal
        mesh for multiscale matching (measured at this shape's scale, as :meth:`derived`),
        built once; ``None`` when the mesh is not dense enough
        to coarsen (see :func:`hope_rs.geometry.coarsen.coarse_mesh`)."""
        if self._coarse is False:
            c = coarse_mesh(self.internal, self.config.coarsen)
            # The coarse copy keeps the faces of this oriented mesh as they come: vertex
            # clustering leaves non-manifold spots that a second orientation would flip.
            self._coarse = (
                None
                if c is None
                else (c, Shape(c.mesh, k_max=self.k_max, orient=False, config=self.config))
            )
        # The copy is built once at its own scale and shared with the views of this shape (it
        # also seeds their eigenbasis); a view gets it measured at the view's scale, once.
        if self._coarse is None or self.at_own_scale:
            return self._coarse
        if self._coarse_view is None:
            c, s = self._coarse
            self._coarse_view = (c, s.at_scale(self.scale))
        return self._coarse_view

    def spectral_basis(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The first ``k`` Laplace–Beltrami eigenvectors ``(n, k)`` of the mesh scaled to unit
        area and its lumped vertex masses ``(n,)``, in the internal numbering; computed once
        (again only when a larger ``k`` is asked for). Fewer columns when the mesh has fewer
        than ``k + 2`` vertices."""
        if isinstance(k, bool) or not isinstance(k, numbers.Integral) or k < 1:
            raise ValueError(f"k must be a positive integer (eigenvectors), got {k!r}")
        if not self.has_spectral_basis(k):
            self._basis = self.solve_spectral_basis(k)
        assert self._basis is not None
        evecs, mass = self._basis
        return evecs[:, :k], mass

    def has_spectral_basis(self, k: int) -> bool:
        """Whether :meth:`spectral_basis` has ``k`` columns (or all there can be) at hand."""
        have = 0 if self._basis is None else self._basis[0].shape[1]
        return have >= min(k, self.n_vertices - 2)

    def solve_spectral_basis(self, k: int, *, stop=None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`spectral_basis`'s ``(evecs, mass)`` solved afresh, without storing them.
        ``stop``: a :class:`threading.Event`; once set, the solve raises
        :class:`~hope_rs._cancel.Cancelled` at its next step."""
        # The multiscale coarse copy, when built already, seeds the basis.
        coarse = self._coarse[0] if isinstance(self._coarse, tuple) else self._coarse
        cfg = self.config
        _, evecs, mass = spectral_basis_of(
            self.internal, k, coarse=coarse, config=cfg.basis, coarsen=cfg.coarsen, stop=stop
        )
        return evecs, mass

    def set_spectral_basis(self, evecs: np.ndarray, mass: np.ndarray) -> None:
        """Store the eigenbasis of :meth:`spectral_basis` computed elsewhere (e.g. read from a
        cache), in the internal numbering."""
        evecs, mass = np.asarray(evecs, dtype=np.float64), np.asarray(mass, dtype=np.float64)
        if evecs.ndim != 2 or evecs.shape[0] != self.n_vertices or mass.shape != (self.n_vertices,):
            raise ValueError(
                f"a basis must be ({self.n_vertices}, k) eigenvectors and ({self.n_vertices},) "
                f"masses, got {evecs.shape} and {mass.shape}"
            )
        self._basis = (evecs, mass)

    def set_descriptors(self, kind: str, d: np.ndarray) -> None:
        """Store descriptors of ``kind`` computed elsewhere (e.g. read from a cache), given in
        the input's numbering."""
        d = np.asarray(d)
        if d.ndim != 2 or d.shape[0] != self.n_vertices:
            raise ValueError(f"{kind} descriptors must be ({self.n_vertices}, D), got {d.shape}")
        self._descriptors[kind] = d[self.order]

    def map_in(self, other: Shape, f: np.ndarray) -> np.ndarray:
        """A map from this shape to ``other`` in input numbering, in internal numbering."""
        return other.rank[self._checked_map(other, f)[self.order]]

    def map_out(self, other: Shape, g: np.ndarray) -> np.ndarray:
        """A map from this shape to ``other`` in internal numbering, in input numbering."""
        return other.order[self._checked_map(other, g)][self.rank]

    def _checked_map(self, other: Shape, f) -> np.ndarray:
        """``f`` as an array, refused unless it has one vertex of ``other`` per vertex (a
        negative index would wrap around)."""
        f = np.asarray(f)
        if f.shape != (self.n_vertices,) or not np.issubdtype(f.dtype, np.integer):
            raise ValueError(
                f"a map from this shape needs {self.n_vertices} integer indices, got "
                f"{f.dtype} of shape {f.shape}"
            )
        if f.size and not (f.min() >= 0 and f.max() < other.n_vertices):
            raise ValueError(
                f"a map's indices must lie in [0, {other.n_vertices}), got {f.min()} to {f.max()}"
            )
        return f

    def __repr__(self) -> str:
        return f"Shape(n_vertices={self.n_vertices}, k_max={self.k_max})"


def _smoothed_copy(origin: Shape, iterations: int, scale: float) -> Shape:
    """A :meth:`Shape.smoothed` copy built again (for unpickling and copies)."""
    out = origin.smoothed(iterations)
    return out if out.scale == scale else out.at_scale(scale)


def _rebuilt(mesh, k_max: int, orient: bool, config: ShapeConfig) -> Shape:
    """A :class:`Shape` built again, for unpickling and copies (:meth:`Shape.__reduce__`)."""
    return Shape(mesh, k_max=k_max, orient=orient, config=config)
