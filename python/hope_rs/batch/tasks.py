"""The tasks of a batch, run in worker processes or Ray tasks: prepare a shape, match a pair.

They never raise: a failure is returned as ``{"error": ...}`` and reported per shape or pair.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections import OrderedDict

from ..geometry.mesh import Mesh
from ..matching import match
from ..pipeline.spectral import applies_to_size
from ..shape import Shape
from .cache import ShapeCache, cached_shape, mesh_digest

__all__ = ["error_text", "limit_threads", "pair_task", "prepare_task"]

#: Shapes a worker keeps built between pairs, counted in vertices.
SHAPE_BUDGET = 300_000


def limit_threads(n: int | None) -> None:
    """Cap the Rust kernels' thread pool (read once, at the first parallel call) of this process,
    unless the user set ``RAYON_NUM_THREADS``."""
    if n and "RAYON_NUM_THREADS" not in os.environ:
        os.environ["RAYON_NUM_THREADS"] = str(n)


def error_text(e: BaseException) -> str:
    """A failure as one line: its type and message."""
    return f"{type(e).__name__}: {e}"


def prepare_task(
    spec: dict, cache_root: str, kinds: tuple, want_data: bool = False, basis: int = 0
) -> dict:
    """Parse a shape and compute its descriptors into the cache with the shape's own
    :class:`~hope_rs.ShapeConfig` (``spec["config"]``, part of every entry's key), and with
    ``basis`` > 0 the spectral pass's eigenbasis of that many eigenpairs (on a shared disk
    only, for shapes the pass can run on); returns its digest and size (and its arrays when
    ``want_data``, for backends whose workers do not share a disk)."""
    try:
        cache = ShapeCache(cache_root)
        config = spec["config"]
        if spec["kind"] == "invalid":
            raise ValueError(spec["error"])
        if spec["kind"] == "path":
            if not os.path.isfile(spec["path"]):
                raise FileNotFoundError(f"no such mesh file: {spec['path']!r}")
            mesh, digest = cache.mesh(spec["path"])
        else:
            mesh = Mesh(spec["vertices"], spec["faces"])
            digest = mesh_digest(mesh)
            if cache.get(digest, "mesh", {}) is None:
                cache.put(digest, "mesh", {}, {"vertices": mesh.vertices, "faces": mesh.faces})
        descr = {kind: cache.descriptors(mesh, kind, digest, config.descriptors) for kind in kinds}
        if basis and not want_data and applies_to_size(mesh.n_vertices):
            cache.spectral_basis(mesh, digest, basis, config=config)
        out = {"digest": digest, "n_vertices": mesh.n_vertices}
        data = {
            "digest": digest, "vertices": mesh.vertices, "faces": mesh.faces,
            "descriptors": descr, "config": config,
        }  # fmt: skip
        if want_data:
            out["data"] = data
        elif cache.unwritten:
            # The cache could not hold the shape: its pairs get the arrays with the task.
            out["token"] = data
        elif spec["kind"] == "path":
            # A pair task reads the file again if the entry is gone (a cache cleared meanwhile).
            out["token"] = {"digest": digest, "config": config, "path": spec["path"]}
        return out
    except Exception as e:  # noqa: BLE001 - reported per shape, the batch goes on
        return {"error": error_text(e)}


_SHAPES: OrderedDict = OrderedDict()


def _shape(token: dict, cache_root: str | None, kinds: tuple, k_max: int, basis: int = 0) -> Shape:
    """The Shape of a token: ``{"digest", "config"}`` (read from the cache) or shipped arrays
    (``"vertices"``, ``"faces"``, ``"descriptors"`` too), kept for later pairs and keyed by
    digest, k_max and the shape's own config; with ``basis`` > 0, the cached eigenbasis of that
    size too, when there is one."""
    config = token["config"]
    key = (token["digest"], k_max, config)
    if key in _SHAPES:
        _SHAPES.move_to_end(key)
        return _SHAPES[key]
    if "vertices" in token:  # arrays shipped with the task
        shape = Shape(Mesh(token["vertices"], token["faces"]), k_max=k_max, config=config)
        for kind, d in token["descriptors"].items():
            shape.set_descriptors(kind, d)
    else:
        cache = ShapeCache(cache_root)
        digest = token["digest"]
        got = cache.get(digest, "mesh", {})
        if got is not None:
            mesh = Mesh(got["vertices"], got["faces"])
        elif "path" in token:  # the entry is gone: the file again, if it is the same
            mesh, now = cache.mesh(token["path"])
            if now != digest:
                raise RuntimeError(f"mesh file {token['path']!r} changed during the batch")
        else:
            raise RuntimeError(
                f"shape {digest[:12]} vanished from the cache {cache_root} (cleared during the "
                "batch?); run the batch again"
            )
        shape = cached_shape(
            mesh, cache=cache, kinds=kinds, k_max=k_max, digest=digest, config=config
        )
        eig = (
            cache.spectral_basis(shape.mesh, digest, basis, compute=False, config=config)
            if basis
            else None
        )
        if eig is not None:
            shape.set_spectral_basis(*eig)
    _SHAPES[key] = shape
    while sum(s.n_vertices for s in _SHAPES.values()) > SHAPE_BUDGET and len(_SHAPES) > 2:
        _SHAPES.popitem(last=False)
    return shape


def pair_task(job: dict, a: dict, b: dict, landmarks=None) -> dict:
    """Match one pair with ``job["config"]`` (a :class:`~hope_rs.MatchConfig`); ``a``/``b`` are
    shape tokens (see :func:`_shape`); ``landmarks``: the pair's, or ``None``."""
    limit_threads(job.get("threads"))
    try:
        t0 = time.perf_counter()
        config = job["config"]
        kinds = (config.initial.descriptor,)
        basis = job.get("basis", 0)
        sa = _shape(a, job["cache_root"], kinds, config.k_max, basis)
        sb = _shape(b, job["cache_root"], kinds, config.k_max, basis)
        load = time.perf_counter() - t0
        res = match(sa, sb, config=config, landmarks=landmarks)
        quality = None if res.quality is None else dataclasses.asdict(res.quality)
        return {"map": res.map, "timings": {"load": load, **res.timings}, "quality": quality}
    except Exception as e:  # noqa: BLE001 - reported per pair, the batch goes on
        return {"error": error_text(e)}
