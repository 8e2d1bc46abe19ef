"""Matching whole collections: ``match_many`` and ``imatch_many``.

This module checks a batch's inputs and settings before any work and builds its plan: the
shapes' names and specs, the map file of each pair (:mod:`~hope_rs.batch.naming`), the
manifest of the output folder (:mod:`~hope_rs.batch.manifest`), the cache; the
:mod:`~hope_rs.batch.scheduler` runs it on a backend (:mod:`~hope_rs.batch.backends`).
Worker processes end with the batch, even when it is killed.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from collections.abc import Generator
from pathlib import Path

import numpy as np

from ..geometry.map_io import check_writable_folder, read_landmarks
from ..geometry.mesh import as_mesh
from ..matching import check_match_options, unknown_options
from ..pipeline.config import INIT_KINDS, KEYWORDS, MatchConfig
from ..pipeline.landmarks import check_landmarks
from ..shape import Shape
from .backends import check_backend, cpu_count, default_jobs, die_with_parent, make_backend
from .cache import ShapeCache, code_fingerprint
from .manifest import Manifest, settings_key
from .naming import MAP_FORMATS, map_name, map_names
from .pairs_file import all_pairs, read_pairs
from .progress import BatchProgress, one_line_warning
from .scheduler import PairResult, Plan, existing_map, run

__all__ = [
    "MAP_FORMATS",
    "BatchProgress",
    "PairResult",
    "all_pairs",
    "cpu_count",
    "default_jobs",
    "die_with_parent",
    "existing_map",
    "imatch_many",
    "map_name",
    "match_many",
    "one_line_warning",
    "read_pairs",
]

#: Disk one cache entry of a shape may take, per vertex (its descriptors, eigenbasis, mesh).
CACHE_BYTES_PER_VERTEX = 6 * 1024
#: Bytes of a mesh file per vertex at least (an OFF or binary PLY line and its faces' share):
#: the file size divided by this bounds the vertex count from above.
FILE_BYTES_PER_VERTEX = 32


# -- inputs --------------------------------------------------------------------------------------


def _names_of(shapes: list) -> tuple[list[str], list[str]]:
    """Names (file stems; positions for objects) and identities (absolute paths, positions)."""
    names, idents = [], []
    for i, s in enumerate(shapes):
        if isinstance(s, (str, os.PathLike)):
            names.append(Path(s).stem)
            idents.append(os.path.abspath(s))
        else:
            names.append(str(i))
            idents.append(f"#{i}")
    # A stem shared by different files (one file spelled two ways is one file): those
    # files are qualified by their folder, the other names stay as they are.
    files: dict[str, set[str]] = {}
    for s, n, ident in zip(shapes, names, idents):
        if isinstance(s, (str, os.PathLike)):
            files.setdefault(n, set()).add(ident)
    names = [
        f"{Path(ident).parent.name}_{n}" if len(files.get(n, ())) > 1 else n
        for n, ident in zip(names, idents)
    ]
    return names, idents


def _spec(s, config) -> dict:
    """What a prepare task needs to know about a shape (picklable), with the ShapeConfig its
    descriptors are computed and cached with: a Shape's own, else ``config``."""
    if isinstance(s, (str, os.PathLike)):
        return {"kind": "path", "path": os.fspath(s), "config": config}
    if isinstance(s, Shape):
        if not s.at_own_scale:
            raise ValueError(
                "a Shape measured at another scale (Shape.at_scale) cannot be batched: give the "
                "Shape itself (match measures a part at its whole's scale)"
            )
        # Its mesh and settings only: the batch describes it and caches that under the mesh's
        # content, so descriptors set by hand (set_descriptors) never reach the shared cache.
        return {"kind": "mesh", "vertices": s.mesh.vertices, "faces": s.mesh.faces,
                "config": s.config}  # fmt: skip
    try:
        m = as_mesh(s)
    except TypeError:
        raise TypeError(
            "shapes must be mesh file paths, hope_rs.Mesh or hope_rs.Shape objects, (vertices, "
            f"faces) pairs or objects with .vertices and .faces, got {type(s).__name__}"
        ) from None
    except ValueError as err:
        # A mesh that cannot be one (NaN coordinates, faces out of range) fails its own pairs,
        # like a corrupt file, not the batch.
        return {"kind": "invalid", "error": str(err), "config": config}
    return {"kind": "mesh", "vertices": m.vertices, "faces": m.faces, "config": config}


def _same_settings(pairs: list[tuple[int, int]], names: list[str], specs: list[dict]) -> None:
    """Refuse, before any work, a pair whose two shapes would be described with different
    :class:`~hope_rs.ShapeConfig` (a Shape's own and ``config.shape``, or two Shapes'):
    descriptors made with different settings cannot be compared (:func:`hope_rs.match`
    refuses two such Shapes too)."""
    for i, j in pairs:
        if specs[i]["config"] != specs[j]["config"]:
            raise ValueError(
                f"pair ({names[i]!r}, {names[j]!r}): the two shapes are described with different "
                "ShapeConfigs (a Shape keeps the one it was built with, other shapes take "
                "config.shape); build the Shapes with config.shape, or pass a config whose "
                "shape is theirs"
            )


def _vertex_bound(spec: dict) -> int:
    """The shape's vertex count, or for a file an upper bound from its size (0 if unknown)."""
    if spec["kind"] == "mesh":
        return len(spec["vertices"])
    if spec["kind"] == "invalid":
        return 0
    try:
        return os.path.getsize(spec["path"]) // FILE_BYTES_PER_VERTEX + 1
    except OSError:
        return 0  # a missing file fails its own pairs later


def _resolve_pairs(pairs, names: list[str], keys: list | None = None) -> list[tuple[int, int]]:
    """Pairs as positions. Pairs give positions or names, except for a dict of shapes with a
    key that is not a string (``keys``): its pairs give keys, and an int is a key, never a
    position."""
    if pairs is None:
        return all_pairs(len(names))
    index = {n: i for i, n in enumerate(names)}
    if keys is not None and all(isinstance(k, str) for k in keys):
        keys = None  # names are the keys themselves
    by_key = {} if keys is None else {k: i for i, k in enumerate(keys)}
    twice = {n for n in names if names.count(n) > 1}
    out = []
    for p in pairs:
        if isinstance(p, (str, bytes)) or not hasattr(p, "__len__") or len(p) != 2:
            raise ValueError(
                f"each pair must be a tuple or list of two entries (e.g. (0, 1) or ('a', 'b')), "
                f"got {p!r}"
            )
        ij = []
        for x in p:
            if keys is not None:
                try:
                    if isinstance(x, (bool, np.bool_)):
                        raise KeyError(x)  # True == 1, yet not the key 1
                    ij.append(by_key[x])
                except (KeyError, TypeError):
                    raise ValueError(
                        f"pair {p!r}: {x!r} is not a key of the shapes dict (its pairs name "
                        f"its keys, not positions: {list(by_key)[:5]}"
                        f"{'...' if len(by_key) > 5 else ''})"
                    ) from None
            elif keys is None and isinstance(x, (int, np.integer)) and not isinstance(x, bool):
                if not 0 <= x < len(names):
                    raise ValueError(f"pair {p!r}: index {x} is outside [0, {len(names)})")
                ij.append(int(x))
            elif isinstance(x, str) and x in twice:
                raise ValueError(
                    f"pair {p!r}: more than one shape is named {x!r}; give indices instead"
                )
            elif isinstance(x, str) and x in index:
                ij.append(index[x])
            else:
                raise ValueError(
                    f"pair {p!r}: {x!r} is neither a shape index nor one of the names "
                    f"{names[:5]}{'...' if len(names) > 5 else ''}"
                )
        out.append((ij[0], ij[1]))
    return out


_LANDMARKS_FORM = (
    "landmarks must be a list with one entry per pair: None, an (m, 2) array or the path of a "
    "landmark file"
)


def _check_not_inputs(paths: list, ij: list, names: list[str], inputs: list) -> None:
    """Refuse, before any work, a map file that is one of the batch's input files (a mesh or
    a landmark file, symbolic links followed): writing the map would replace it. (A hard link
    is another name: the map's atomic write replaces the name, not the input.)"""

    def real(p) -> str:
        return os.path.normcase(os.path.realpath(p))

    seen = {real(x): os.fspath(x) for x in inputs}
    for path, (i, j) in zip(paths, ij):
        x = seen.get(real(path))
        if x is not None:
            raise ValueError(
                f"the map of {names[i]} -> {names[j]} would be written over {x!r}, one of the "
                "inputs; choose another output folder"
            )


def _pair_landmarks(landmarks, pairs, n_pairs: int) -> tuple[list, list]:
    """One landmark array (form checked; indices are checked per pair once its shapes are
    read) or ``None`` per pair, and the landmark file each was read from (or ``None``)."""
    if landmarks is None:
        return [None] * n_pairs, [None] * n_pairs
    if pairs is None:
        raise ValueError("landmarks belong to pairs: give the pairs they are for as well")
    if isinstance(landmarks, (str, os.PathLike)):
        raise TypeError(_LANDMARKS_FORM)
    try:
        marks = list(landmarks)
    except TypeError:
        raise TypeError(_LANDMARKS_FORM) from None
    if len(marks) != n_pairs:
        raise ValueError(
            f"landmarks has {len(marks)} entries for {n_pairs} pairs; give one per pair"
        )
    files: list = [None] * n_pairs
    for n, lm in enumerate(marks):
        try:
            if isinstance(lm, (str, os.PathLike)):
                files[n] = os.fspath(lm)
                lm = read_landmarks(lm)
            marks[n] = check_landmarks(lm, None, None)
        except (OSError, TypeError, ValueError) as e:
            raise type(e)(f"landmarks[{n}] (for pairs[{n}]): {e}") from None
    return marks, files


#: :func:`match_many`'s own keyword options (besides those of :func:`hope_rs.match`).
BATCH_OPTIONS = (
    "out_dir", "jobs", "backend", "cache", "config", "init", "progress", "ray_options",
    "map_format", "landmarks",
)  # fmt: skip


def batch_config(config: MatchConfig | None, init, options: dict) -> MatchConfig:
    """The MatchConfig of every pair: ``config`` with ``init`` (descriptors) and ``match``'s
    keyword ``options`` set through :meth:`MatchConfig.with_options`, as :func:`hope_rs.match`
    does; every value checked by the same function as ``match``'s."""
    if init is not None and (not isinstance(init, str) or init not in INIT_KINDS):
        # A map's repr runs over many lines: say what it is instead.
        what = repr(init) if isinstance(init, str) else type(init).__name__
        raise ValueError(
            f"init must be 'shot', 'wks' or 'hks' in a batch, got {what} (a pair's own initial "
            "map: match that pair with hope_rs.match)"
        )
    for name in ("callback", "progress"):
        if name in options:
            raise TypeError(f"{name} is not an option of a batch's pairs")
    unknown = unknown_options(options)
    if unknown:
        raise TypeError(
            f"not an option of hope_rs.match_many: {unknown[0]!r}; its own options are "
            f"{', '.join(BATCH_OPTIONS)}, and hope_rs.match's {', '.join(KEYWORDS)}"
        )
    # check_match_options records init in cfg.initial.descriptor, as match does.
    return check_match_options(config=config, init=init, **options)


def _open_cache(cache, need: int) -> tuple[ShapeCache, tempfile.TemporaryDirectory | None]:
    """The batch's cache, probed (writable, ``need`` bytes free); an unusable cache folder
    gives way to a temporary one, with a warning."""
    if cache is False:
        tmp = tempfile.TemporaryDirectory(prefix="hope_rs-batch-")
        check_writable_folder(tmp.name, need_bytes=need, what="temporary cache")
        return ShapeCache(tmp.name), tmp
    if cache is True or cache is None:
        cache = ShapeCache()
    elif not isinstance(cache, ShapeCache):
        cache = ShapeCache(cache)
    try:
        check_writable_folder(cache.root, create=True, need_bytes=need, what="cache")
        return cache, None
    except ValueError as e:
        warnings.warn(
            f"{e}; using a temporary cache for this batch instead", RuntimeWarning, stacklevel=3
        )
    tmp = tempfile.TemporaryDirectory(prefix="hope_rs-batch-")
    try:
        check_writable_folder(tmp.name, need_bytes=need, what="temporary cache")
    except BaseException:
        tmp.cleanup()
        raise
    return ShapeCache(tmp.name), tmp


# -- the batch -----------------------------------------------------------------------------------


def imatch_many(
    shapes,
    pairs=None,
    *,
    out_dir: str | os.PathLike | None = None,
    jobs: int | None = None,
    backend: str = "local",
    cache: ShapeCache | str | os.PathLike | bool | None = True,
    config: MatchConfig | None = None,
    init: str | None = None,
    progress=None,
    ray_options: dict | None = None,
    map_format: str = "txt",
    landmarks=None,
    **match_options,
) -> Generator[PairResult, None, None]:
    """Like :func:`match_many`, but yields each :class:`PairResult` as soon as it is done
    (finished pairs first, in no particular order). The inputs and the output folder are
    checked when it is called; the cache, the workers and the matches start with the first
    result asked for. Closing the generator early (or an exception, Ctrl-C) ends the workers
    at once; the maps already written stay."""
    if isinstance(shapes, dict):
        keys = list(shapes)
        names, shapes = [str(k) for k in keys], list(shapes.values())
        idents = [f"key {k!r}" for k in keys]
    else:
        shapes, keys = list(shapes), None
        names, idents = _names_of(shapes)
    if not shapes:
        raise ValueError("no shapes given")
    if map_format not in MAP_FORMATS:
        raise ValueError(f"map_format must be one of {sorted(MAP_FORMATS)}, got {map_format!r}")
    if not (progress is None or isinstance(progress, (bool, np.bool_)) or callable(progress)):
        raise TypeError(
            "progress must be None, True, False or callable (it is called with each "
            f"PairResult), got {type(progress).__name__}"
        )
    cfg = batch_config(config, init, match_options)
    check_backend(backend, jobs)
    ij = _resolve_pairs(pairs, names, keys)
    marks, mark_files = _pair_landmarks(landmarks, pairs, len(ij))
    specs = [_spec(s, cfg.shape) for s in shapes]
    _same_settings(ij, names, specs)
    largest = max((_vertex_bound(s) for s in specs), default=0)
    paths: list[Path | None] = [None] * len(ij)
    manifest = None
    if out_dir is not None:
        files = map_names(
            [(names[i], names[j]) for i, j in ij], [(idents[i], idents[j]) for i, j in ij],
            map_format,
        )  # fmt: skip
        # one map (at most 21 bytes a line) and the manifest
        out = check_writable_folder(out_dir, create=True, need_bytes=21 * largest + 2**16)
        paths = [out / f for f in files]
        inputs = [s for s in shapes if isinstance(s, (str, os.PathLike))]
        _check_not_inputs(paths, ij, names, inputs + [f for f in mark_files if f is not None])
        manifest = Manifest(out)
    basis = cfg.spectral.k_end if cfg.spectral.enabled else 0
    key = cfg.key()
    settings = [settings_key(key, specs[i]["config"], specs[j]["config"]) for i, j in ij]

    def results() -> Generator[PairResult, None, None]:
        shape_cache, tmp = _open_cache(cache, CACHE_BYTES_PER_VERTEX * largest)
        report = progress if callable(progress) else BatchProgress(len(ij), enabled=bool(progress))
        try:
            ex = make_backend(backend, jobs, ray_options)
        except BaseException:  # e.g. Ray missing or unreachable: no temporary cache left behind
            if tmp is not None:
                tmp.cleanup()
            raise
        plan = Plan(
            names=names, specs=specs, pairs=ij, paths=paths, landmarks=marks,
            landmark_files=mark_files, settings=settings,
            job={"cache_root": str(shape_cache.root), "config": cfg,
                 "threads": getattr(ex, "threads", None), "basis": basis},
            kinds=(cfg.initial.descriptor,), basis=basis, code=code_fingerprint(),
            manifest=manifest,
        )  # fmt: skip
        finished = False
        try:
            yield from run(plan, ex, report)
            finished = True
        finally:
            ex.close(abort=not finished)
            if tmp is not None:
                tmp.cleanup()

    return results()


def match_many(
    shapes,
    pairs=None,
    *,
    out_dir: str | os.PathLike | None = None,
    jobs: int | None = None,
    backend: str = "local",
    cache: ShapeCache | str | os.PathLike | bool | None = True,
    config: MatchConfig | None = None,
    init: str | None = None,
    progress=None,
    ray_options: dict | None = None,
    map_format: str = "txt",
    landmarks=None,
    **match_options,
) -> list[PairResult]:
    """Match many pairs of shapes, each shape precomputed once; one result per pair, in order.

    Parameters
    ----------
    shapes : list or dict
        Mesh file paths, :class:`~hope_rs.Mesh` or :class:`~hope_rs.Shape` objects (a dict maps
        names to them). Path shapes are named by their file stem, others by their position.
    pairs : list of (a, b), optional
        Positions in ``shapes`` or names; for a dict with a key that is not a string, its
        keys (an int is then a key, not a position). Default every pair (i, j) with i < j.
    out_dir : path, keyword-only, optional
        Write each map to ``out_dir/<a>__<b>.txt`` (one B index per line) as soon as it is done,
        atomically, and record it in ``out_dir/hope-rs-manifest.jsonl`` (both meshes' content
        digests, the landmarks', the settings and the code version). Names are made safe
        (other characters than letters, digits, ``_ . + -`` become ``_``) and get a short
        digest suffix when that changed them or two pairs would share a file
        (:mod:`hope_rs.batch.naming`); no file is written outside ``out_dir``. A rerun skips
        a pair only when its map file is whole and its manifest entry matches; others are
        redone, with a warning saying why (a map of other meshes or landmarks, or not whole,
        removed first). The folder is created, and checked to be writable with room for a
        map, before any work; a map file that is one of the inputs (a mesh or landmark file)
        is refused then too.
    map_format : {"txt", "npy"}
        Format of the map files (:func:`hope_rs.write_map`).
    jobs : int, optional
        Local worker processes (default :func:`default_jobs`: one per two cores, each with
        cores / jobs Rust threads); 1 runs in this process. When a worker dies (e.g. killed
        for lack of memory) the pool is restarted, the pairs that were running are run again
        one at a time, and one whose worker dies again, alone, fails; the others run on.
    backend : {"local", "ray"}
        ``"ray"`` runs the tasks on the Ray cluster ``ray.init()`` connects to (``pip install
        'hope-rs[ray]'``); ``ray_options`` are passed to :class:`hope_rs.batch.ray_backend.RayBackend`.
    cache : ShapeCache, path, True or False
        Per-shape cache (default :func:`hope_rs.batch.cache.default_cache_dir`), keyed by each
        shape's content and :class:`~hope_rs.ShapeConfig`; False keeps it in a temporary
        folder for this batch only, as does a cache folder that cannot be written or lacks
        room (with a warning).
    config : MatchConfig, optional
        Every setting of every pair, as for :func:`hope_rs.match`; ``init`` and the keyword
        options are set over it through :meth:`MatchConfig.with_options`.
    landmarks : list, optional
        One entry per pair of ``pairs`` (which must then be given): ``None``, an (m, 2)
        array of (vertex of a, vertex of b) that the pair's map keeps, as for
        :func:`hope_rs.match`, or the path of a landmark file (read with
        :func:`hope_rs.read_landmarks`, a relative path against the current folder; a pair's
        error then names it). A file that cannot be read, or landmarks not of (m, 2) form,
        fail the call before any work; indices out of range fail that pair only, before it
        is matched.
    init, **match_options
        As for :func:`hope_rs.match` (``init`` must name descriptors).
    progress : bool or callable
        Show a progress bar on stderr, or call ``progress(result)`` per finished pair.

    Returns
    -------
    list of PairResult
        Failed pairs have ``error`` set and ``map`` None; they never stop the batch.
    """
    results = list(
        imatch_many(
            shapes,
            pairs,
            out_dir=out_dir,
            jobs=jobs,
            backend=backend,
            cache=cache,
            config=config,
            init=init,
            progress=progress,
            ray_options=ray_options,
            map_format=map_format,
            landmarks=landmarks,
            **match_options,
        )
    )
    return sorted(results, key=lambda r: r.index)
