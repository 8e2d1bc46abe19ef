"""On-disk cache of per-shape precomputation, keyed by content, so batches pay it once per shape.

What is cached, per mesh:

- the parsed mesh (OFF parsing is pure Python; loading the arrays back is nearly free),
- descriptors: SHOT, and for WKS/HKS the Laplacian eigenpairs and the signatures computed from
  them,
- the spectral pass's eigenbasis (120 eigenpairs of the robust Laplacian in the shape's internal
  numbering), for shapes the pass runs on.

The k-hop neighbourhoods live in the Rust ``MeshGraph`` and are rebuilt: storing them would cost
more disk than the rebuild costs time.

Entries are keyed by the SHA-256 of the mesh file's bytes (or of the vertex and face arrays), the
descriptor parameters, the package version and a fingerprint of the compiled extension, so editing
a mesh, changing a parameter or rebuilding the Rust core never returns stale data. Every file is
written to a temporary name and renamed into place: readers see a whole entry or none, and
concurrent writers of the same entry are harmless (they write identical bytes).

Each entry also stores its own key (digest, kind, parameters, code) and a SHA-256 of its arrays,
checked on every read: an entry damaged by something outside these writes (a full disk, a copy
cut short, files swapped by hand) is recomputed and rewritten, with a warning naming the file.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import os
import warnings
from functools import lru_cache
from pathlib import Path

import numpy as np

from .. import _core
from .._version import __version__
from ..features.descriptors import (
    DescriptorConfig,
    laplacian_eigenpairs,
    shot_as_numbered,
    spectral_basis_of,
    spectral_descriptors,
)
from ..geometry.map_io import atomic_write
from ..geometry.mesh import Mesh, load_mesh, parse_mesh, read_mesh_file
from ..geometry.numbering import canonical_mesh
from ..pipeline.config import settings_json
from ..shape import Shape, ShapeConfig

#: Bump when the layout or the meaning of an entry changes (2: entries carry key and checksum).
FORMAT = 2
#: Names of the integrity fields stored next to an entry's arrays.
_KEY, _SUM = "__key__", "__sha256__"


def default_cache_dir() -> Path:
    """``$HOPE_RS_CACHE``, else ``$XDG_CACHE_HOME/hope_rs``, else ``~/.cache/hope_rs``."""
    # "~" expanded as a shell would (a quoted "~/c" made a folder named "~").
    if os.environ.get("HOPE_RS_CACHE"):
        return Path(os.path.expanduser(os.environ["HOPE_RS_CACHE"]))
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join("~", ".cache")
    return Path(os.path.expanduser(base)) / "hope_rs"


def file_digest(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def mesh_digest(mesh: Mesh) -> str:
    """SHA-256 of a mesh's vertex and face arrays (for meshes that did not come from a file)."""
    h = hashlib.sha256(b"arrays")
    for arr in (mesh.vertices, mesh.faces):
        h.update(str((arr.dtype.str, arr.shape)).encode())
        h.update(np.ascontiguousarray(arr).tobytes())
    return h.hexdigest()


@lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """Package version plus a hash of the compiled extension: a rebuild invalidates entries."""
    try:
        core = file_digest(_core.__file__)[:16]
    except (OSError, AttributeError, TypeError):
        core = "unknown"
    return f"{__version__}-{core}"


#: The internal mesh cached arrays are computed on (:func:`hope_rs.geometry.numbering.canonical_mesh`:
#: its vertex order, its faces). A new name when it changes, so older entries are computed again.
NUMBERING = "morton, faces once"


def descriptor_params(kind: str, config: DescriptorConfig = DescriptorConfig()) -> dict:
    """The key parameters of a descriptor entry: every descriptor setting, and the
    numbering they are computed in (the position-fixed one of hope_rs.geometry.numbering)."""
    if kind not in ("shot", "wks", "hks", "eigen"):
        raise ValueError(f"unknown descriptor {kind!r}; choose 'shot', 'wks' or 'hks'")
    return {"descriptors": dataclasses.asdict(config), "numbering": NUMBERING}


def basis_params(k: int, config: ShapeConfig = ShapeConfig()) -> dict:
    """The key parameters of an eigenbasis entry: its size, the settings of its solve (dense
    meshes are seeded from their coarse copies) and the numbering."""
    return {
        "k": int(k),
        "basis": dataclasses.asdict(config.basis),
        "coarsen": dataclasses.asdict(config.coarsen),
        "numbering": NUMBERING,
    }


def _checksum(arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 of arrays: names, dtypes, shapes and bytes, in name order."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        arr = np.ascontiguousarray(arrays[name])
        h.update(repr((name, arr.dtype.str, arr.shape)).encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def _atomic_save(path: Path, arrays: dict[str, np.ndarray]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    # numpy's stub types **kwds as if they could fill savez's allow_pickle.
    atomic_write(path, lambda fh: np.savez(fh, **arrays))  # type: ignore[arg-type]


class ShapeCache:
    """Per-shape data on disk under ``root`` (one folder per content digest).

    Parameters
    ----------
    root : path, optional
        Cache folder; default :func:`default_cache_dir`. Created on first write.

    Attributes
    ----------
    hits, misses : int
        Lookups served from disk / computed, in this process.
    unwritten : int
        Entries that could not be written, in this process.
    """

    def __init__(self, root: str | os.PathLike | None = None):
        if root is not None and os.fspath(root) == "":  # Path("") is the current folder
            raise ValueError(
                "the cache folder names no folder (an empty path); give a folder, or None for "
                "the default"
            )
        self.root = Path(root) if root is not None else default_cache_dir()
        self.hits = 0
        self.misses = 0
        self.unwritten = 0

    def __repr__(self) -> str:
        return f"ShapeCache({str(self.root)!r})"

    def _key(self, digest: str, what: str, params: dict) -> tuple[Path, str]:
        """The entry's file and the key stored inside it."""
        common = {"what": what, "params": params, "code": code_fingerprint(), "format": FORMAT}
        tag = hashlib.sha256(settings_json(common).encode()).hexdigest()[:16]
        key = settings_json({"digest": digest, **common})
        return self.root / f"v{FORMAT}" / digest[:2] / digest / f"{what}-{tag}.npz", key

    def get(self, digest: str, what: str, params: dict) -> dict[str, np.ndarray] | None:
        """The arrays of an entry, or None when it is absent or damaged (a damaged file is
        removed, with a warning naming it, so that the caller recomputes and rewrites it)."""
        path, key = self._key(digest, what, params)
        try:
            with np.load(path, allow_pickle=False) as z:
                out = {k: z[k] for k in z.files}
        except (FileNotFoundError, NotADirectoryError):  # absent (a file where a folder goes)
            return None
        except MemoryError:
            raise  # says nothing about the entry: keep it
        except Exception as e:  # noqa: BLE001 - BadZipFile, zlib.error, ValueError (refused
            # pickle, bad header), EOFError, OSError, KeyError...: all mean a damaged file
            self._damaged(path, f"unreadable: {type(e).__name__}")
            return None
        stored_key, stored_sum = out.pop(_KEY, None), out.pop(_SUM, None)
        if stored_key is None or stored_key.shape != () or str(stored_key) != key:
            self._damaged(path, "it holds another entry")
            return None
        if stored_sum is None or stored_sum.shape != () or str(stored_sum) != _checksum(out):
            self._damaged(path, "checksum mismatch")
            return None
        self.hits += 1
        return out

    def _damaged(self, path: Path, reason: str) -> None:
        warnings.warn(
            f"hope_rs cache entry {str(path)!r} is damaged ({reason}); recomputing it",
            RuntimeWarning,
            stacklevel=3,
        )
        with contextlib.suppress(OSError):  # already replaced or removed by a concurrent writer
            path.unlink()

    def put(self, digest: str, what: str, params: dict, arrays: dict[str, np.ndarray]) -> None:
        """Store an entry; one that cannot be written (a full disk, a read-only or damaged
        folder) is left out with a warning: the caller has its arrays, and later lookups
        compute them again."""
        self.misses += 1
        path, key = self._key(digest, what, params)
        arrays = {k: np.asarray(v) for k, v in arrays.items()}
        try:
            _atomic_save(path, {**arrays, _KEY: np.array(key), _SUM: np.array(_checksum(arrays))})
        except OSError as e:
            self.unwritten += 1
            warnings.warn(
                f"hope_rs cache entry {str(path)!r} cannot be written ({e.strerror or e}); "
                "going on without it",
                RuntimeWarning,
                stacklevel=2,
            )

    # -- the three kinds of entries -------------------------------------------------------------

    def mesh(self, path: str | os.PathLike) -> tuple[Mesh, str]:
        """The mesh of a file, parsed once, and the digest of the file's bytes: both from one
        read, so that a file replaced meanwhile cannot store one version's mesh under the
        other's digest."""
        data = read_mesh_file(path)
        digest = hashlib.sha256(data).hexdigest()
        got = self.get(digest, "mesh", {})
        if got is not None:
            return Mesh(got["vertices"], got["faces"]), digest
        m = parse_mesh(path, data)
        self.put(digest, "mesh", {}, {"vertices": m.vertices, "faces": m.faces})
        return m, digest

    def descriptors(
        self,
        mesh: Mesh,
        kind: str,
        digest: str | None = None,
        config: DescriptorConfig = DescriptorConfig(),
    ) -> np.ndarray:
        """Descriptors of ``kind`` for ``mesh`` with the settings ``config`` (part of the
        entry's key); WKS and HKS share cached eigenpairs."""
        digest = digest or mesh_digest(mesh)
        params = descriptor_params(kind, config)
        got = self.get(digest, kind, params)
        if got is not None:
            return got["d"]
        if kind == "shot":
            canon, _, rank = canonical_mesh(mesh)
            d = shot_as_numbered(canon, config.shot_radius, False, config.sites)[rank]
        else:
            eig_params = descriptor_params("eigen", config)
            eig = self.get(digest, "eigen", eig_params)
            if eig is None:
                evals, evecs = laplacian_eigenpairs(mesh, config.n_eigen)
                self.put(digest, "eigen", eig_params, {"vals": evals, "vecs": evecs})
            else:
                evals, evecs = eig["vals"], eig["vecs"]
            d = spectral_descriptors(kind, evals, evecs, mesh)
        self.put(digest, kind, params, {"d": d})
        return d

    def spectral_basis(
        self,
        mesh: Mesh,
        digest: str,
        k: int,
        *,
        compute: bool = True,
        config: ShapeConfig = ShapeConfig(),
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The spectral pass's eigenbasis of ``mesh``, ``k`` eigenpairs (eigenvectors and vertex
        masses, in the internal numbering of :class:`~hope_rs.Shape`): read, or with ``compute`` computed and
        stored. ``None`` when absent and not computed, or when the eigensolver fails (the pass
        then tries again, and warns, in the worker that needs it)."""
        params = basis_params(k, config)
        got = self.get(digest, "basis", params)
        if got is not None:
            return got["vecs"], got["mass"]
        if not compute:
            return None
        try:
            _, vecs, mass = spectral_basis_of(
                canonical_mesh(mesh)[0], params["k"], config=config.basis, coarsen=config.coarsen
            )
        except (RuntimeError, ValueError):  # ARPACK did not converge, a singular factorisation
            return None
        self.put(digest, "basis", params, {"vecs": vecs, "mass": mass})
        return vecs, mass


def cached_shape(
    source,
    *,
    cache: ShapeCache | None,
    kinds: tuple[str, ...] = ("shot",),
    k_max: int = 8,
    digest: str | None = None,
    config: ShapeConfig = ShapeConfig(),
) -> Shape:
    """A :class:`Shape` of ``source`` (a mesh file path or a Mesh) built with ``config``, with
    ``kinds`` descriptors filled from ``cache`` (computed with that config and stored, under a
    key holding it, on a miss). ``cache=None`` computes everything."""
    if isinstance(source, Mesh):
        mesh = source
        if cache is not None:
            digest = digest or mesh_digest(mesh)
    elif cache is None:
        mesh = load_mesh(source)
    else:
        mesh, digest = cache.mesh(source)
    shape = Shape(mesh, k_max=k_max, config=config)
    for kind in kinds:
        if cache is not None:
            shape.set_descriptors(kind, cache.descriptors(mesh, kind, digest, config.descriptors))
        else:
            shape.descriptors(kind)
    return shape
