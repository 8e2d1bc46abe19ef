"""Matching whole collections: ``match_many`` and the pair files of ``hope-rs batch``.

A batch runs in two kinds of tasks. *Prepare* tasks, one per shape, parse the mesh and compute
its descriptors into the on-disk :class:`~hope_rs.batch.cache.ShapeCache` (a temporary one when caching
is off), so every shape is precomputed once however many pairs it is in. *Pair* tasks load both
shapes from there, rebuild the k-hop neighbourhoods (cheap) and run
:func:`hope_rs.match`. A pair starts as soon as its two shapes are ready. The parent process
writes each map atomically as soon as its pair is done (also with one job: tasks then run one
at a time, when their result is waited for); a rerun skips pairs whose map file exists and is
whole (right length, indices in range), and redoes the others; a shape that cannot be loaded
fails only its own pairs. Worker processes end with the batch, even when it is killed.
"""

from __future__ import annotations

import ctypes
import os
import shlex
import signal
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Generator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, overload

import numpy as np

from ..geometry.map_io import (
    check_writable_folder,
    read_landmarks,
    read_map,
    text_map_is_complete,
    write_map,
)
from ..geometry.mesh import as_mesh
from ..matching import check_match_options
from ..pipeline.config import KEYWORDS, MatchConfig
from ..pipeline.landmarks import check_landmarks
from ..shape import Shape, ShapeConfig
from .cache import ShapeCache
from .ray_backend import RayBackend
from .tasks import error_text, limit_threads, pair_task, prepare_task


@dataclass
class PairResult:
    """The outcome of one pair of a batch.

    Attributes
    ----------
    index : int
        Position of the pair in the ``pairs`` given.
    a, b : str
        Names of the two shapes.
    map : (n_a,) int64 or None
        ``map[i]`` is the vertex of b matched to vertex i of a; None when the pair failed.
    error : str or None
        Why the pair failed (e.g. the mesh could not be read).
    skipped : bool
        A whole map file already existed, so the pair was not recomputed (``map`` is read from
        it).
    path : Path or None
        The map file, when an output folder was given.
    timings : dict
        ``MatchResult.timings`` of the pair, plus "load" (seconds to get both shapes ready).
    """

    index: int
    a: str
    b: str
    map: np.ndarray | None = None
    error: str | None = None
    skipped: bool = False
    path: Path | None = None
    timings: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.error is None


# -- pair files ----------------------------------------------------------------------------------


def _pair_fields(line: str) -> list[str]:
    """The fields of one pairs-file line: tab-separated when the line has a tab (paths may then
    hold spaces), else shell-like words (quote paths with spaces); ``#`` starts a comment."""
    if "\t" in line:
        cut = (i for i, c in enumerate(line) if c == "#" and (i == 0 or line[i - 1].isspace()))
        body = line[: next(cut, len(line))]
        if "\t" in body.strip():
            return [f.strip() for f in body.split("\t") if f.strip()]
    return shlex.split(line, comments=True)


@overload
def read_pairs(
    path: str | os.PathLike, *, ext: str = "", with_landmarks: Literal[False] = False
) -> list[tuple[Path, Path]]: ...
@overload
def read_pairs(
    path: str | os.PathLike, *, ext: str = "", with_landmarks: Literal[True]
) -> tuple[list[tuple[Path, Path]], list[np.ndarray | None]]: ...
def read_pairs(path: str | os.PathLike, *, ext: str = "", with_landmarks: bool = False):
    """Read a pairs file: one pair per line, two mesh paths.

    The two paths are separated by white space (quote a path holding spaces, as in a shell:
    ``"my meshes/a.off" b.off``) or by a tab (then each field is taken as it is, spaces
    included). Relative paths are resolved against the file's folder; ``ext`` (e.g. ``".off"``)
    is appended to names that do not already end with it, so the ``pairs.txt`` of the shared
    benchmark sets (``tr_reg_002 tr_reg_007``) work as they are. Blank lines and ``#`` comments
    are ignored. A malformed line raises ValueError naming the file and line.

    With ``with_landmarks``, a line may name a third file: the pair's landmarks (read with
    :func:`hope_rs.read_landmarks`, relative paths against the pairs file's folder, no ``ext``
    added), and the result is ``(pairs, landmarks)`` with one (m, 2) array or ``None`` per pair.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (folder / "scan.lm").write_text("0 5\\n17 3\\n")
    >>> _ = (folder / "pairs.txt").write_text("template scan scan.lm\\ntemplate other\\n")
    >>> pairs, landmarks = read_pairs(folder / "pairs.txt", ext=".off", with_landmarks=True)
    >>> [(a.name, b.name) for a, b in pairs], landmarks[0].tolist(), landmarks[1]
    ([('template.off', 'scan.off'), ('template.off', 'other.off')], [[0, 5], [17, 3]], None)
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such pairs file: {str(path)!r}")
    if ext and not ext.startswith("."):
        ext = "." + ext
    folder = path.resolve().parent
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise ValueError(f"{path} is not a text file of mesh paths") from None
    out, marks = [], []
    for no, line in enumerate(text.splitlines(), 1):
        try:
            tokens = _pair_fields(line)
        except ValueError as e:  # shlex: an unclosed quote
            raise ValueError(f"{path}:{no}: {e}: {line.strip()!r}") from None
        if not tokens:
            continue
        if len(tokens) != 2 and not (with_landmarks and len(tokens) == 3):
            want = "two mesh paths (and a landmark file)" if with_landmarks else "two mesh paths"
            raise ValueError(
                f"{path}:{no}: expected {want} separated by white space or a tab, got "
                f"{len(tokens)} field(s) (quote paths holding spaces): {line.strip()!r}"
            )
        if len(tokens) == 3:
            lm = Path(tokens[2])
            try:
                marks.append(
                    check_landmarks(
                        read_landmarks(lm if lm.is_absolute() else folder / lm), None, None
                    )
                )
            except (OSError, TypeError, ValueError) as e:
                raise ValueError(
                    f"{path}:{no}: a third field names the pair's landmark file: {e}"
                ) from None
        else:
            marks.append(None)
        pair = []
        for t in tokens[:2]:
            if ext and not t.endswith(ext):
                t += ext
            p = Path(t)
            pair.append(p if p.is_absolute() else folder / p)
        out.append((pair[0], pair[1]))
    if not out:
        raise ValueError(f"{path} lists no pairs (expected lines of two mesh paths)")
    return (out, marks) if with_landmarks else out


def all_pairs(n: int) -> list[tuple[int, int]]:
    """Every unordered pair (i, j), i < j, of n shapes."""
    return [(i, j) for i in range(n) for j in range(i + 1, n)]


# -- inputs --------------------------------------------------------------------------------------


def _names_of(shapes: list) -> list[str]:
    names = []
    for i, s in enumerate(shapes):
        names.append(Path(s).stem if isinstance(s, (str, os.PathLike)) else str(i))
    if len(set(names)) < len(names):  # same stem in two folders: qualify by the folder
        names = [
            f"{Path(s).parent.name}_{Path(s).stem}" if isinstance(s, (str, os.PathLike)) else n
            for s, n in zip(shapes, names)
        ]
    if len(set(names)) < len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"shape names {dup} are not unique; pass shapes as a dict name -> shape")
    return names


def _spec(s) -> tuple:
    """What a prepare task needs to know about a shape (picklable)."""
    if isinstance(s, (str, os.PathLike)):
        return ("path", os.fspath(s))
    if isinstance(s, Shape):
        return (
            "mesh",
            s.mesh.vertices,
            s.mesh.faces,
            {k: s.descriptors(k) for k in s._descriptors},
        )
    try:
        m = as_mesh(s)
    except TypeError:
        raise TypeError(
            "shapes must be mesh file paths, hope_rs.Mesh or hope_rs.Shape objects, (vertices, "
            f"faces) pairs or objects with .vertices and .faces, got {type(s).__name__}"
        ) from None
    return ("mesh", m.vertices, m.faces, {})


def _resolve_pairs(pairs, names: list[str]) -> list[tuple[int, int]]:
    if pairs is None:
        return all_pairs(len(names))
    index = {n: i for i, n in enumerate(names)}
    out = []
    for p in pairs:
        if len(p) != 2:
            raise ValueError(f"each pair must have two entries, got {p!r}")
        ij = []
        for x in p:
            if isinstance(x, (int, np.integer)) and not isinstance(x, bool):
                if not 0 <= x < len(names):
                    raise ValueError(f"pair {p!r}: index {x} is outside [0, {len(names)})")
                ij.append(int(x))
            elif isinstance(x, str) and x in index:
                ij.append(index[x])
            else:
                raise ValueError(
                    f"pair {p!r}: {x!r} is neither a shape index nor one of the names "
                    f"{names[:5]}{'...' if len(names) > 5 else ''}"
                )
        out.append((ij[0], ij[1]))
    return out


# -- backends: submit tasks, wait for any to finish -----------------------------------------------


class _Task:
    """A task of the serial backend, run when it is waited for."""

    __slots__ = ("args", "fn")

    def __init__(self, fn, args):
        self.fn, self.args = fn, args


class _Serial:
    """Runs tasks in this process, one per :meth:`wait` (pairs before preparations, so each map
    is written as soon as possible)."""

    ships_data = False

    def __init__(self, threads: int | None):
        self.threads = threads

    def submit(self, fn, *args):
        return _Task(fn, args)

    def wait(self, handles):
        h = next((h for h in handles if h.fn is pair_task), handles[0])
        return [(h, h.fn(*h.args))]

    def close(self, abort: bool = False):
        pass


def die_with_parent(parent: int, poll: float = 1.0) -> None:
    """End this process when process ``parent`` ends, however it ends (even SIGKILL).

    On Linux the kernel sends SIGKILL at the parent's death (``prctl(PR_SET_PDEATHSIG)``);
    everywhere a daemon thread also checks every ``poll`` seconds that the parent is still
    this process's parent, and exits when it is not.
    """
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass  # no libc symbol: the thread below still applies
    if os.getppid() != parent:  # the parent died before the kernel watched it
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(poll)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="hope-rs-parent-watch", daemon=True).start()


def one_line_warning(message, category, filename, lineno, line=None) -> str:
    """``warnings.formatwarning`` for the command line and its workers: one line, no source."""
    return f"hope-rs: warning: {message}\n"


def _init_worker(threads: int, parent: int) -> None:
    limit_threads(threads)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the parent, which ends us
    warnings.formatwarning = one_line_warning
    die_with_parent(parent)


class _Pool:
    """A pool of ``jobs`` spawned processes (not forked: a forked Rust thread pool would hang).

    Workers ignore Ctrl-C (the parent ends them) and die with the parent process."""

    ships_data = False

    def __init__(self, jobs: int, threads: int):
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        self.threads = threads
        self.ex = ProcessPoolExecutor(
            max_workers=jobs, mp_context=mp.get_context("spawn"),
            initializer=_init_worker, initargs=(threads, os.getpid()),
        )  # fmt: skip

    def submit(self, fn, *args):
        return self.ex.submit(fn, *args)

    def wait(self, handles):
        from concurrent.futures import FIRST_COMPLETED, wait

        done, _ = wait(handles, return_when=FIRST_COMPLETED)
        out = []
        for h in done:
            try:
                out.append((h, h.result()))
            except Exception as e:  # noqa: BLE001 - a worker died (e.g. out of memory)
                out.append((h, {"error": f"worker process failed: {error_text(e)}"}))
        return out

    def close(self, abort: bool = False):
        """Wait for the workers to finish; with ``abort`` (an error, Ctrl-C), kill them first
        rather than wait for the pairs they are matching."""
        if abort:
            for proc in list((getattr(self.ex, "_processes", None) or {}).values()):
                proc.kill()
        self.ex.shutdown(wait=True, cancel_futures=True)


def cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def default_jobs() -> int:
    """Local worker processes by default: one per two cores. The Rust kernels already use every
    core they are given, and more processes with fewer threads each were not faster while they
    took more memory (docs/decisions.md#speed)."""
    return max(1, cpu_count() // 2)


def _check_backend(backend: str, jobs: int | None) -> int:
    """The number of local jobs, after checking both settings (before any work)."""
    jobs = default_jobs() if jobs is None else jobs
    if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1:
        raise ValueError(f"jobs must be a positive integer, got {jobs!r}")
    if backend not in ("local", "ray"):
        raise ValueError(f"unknown backend {backend!r}; choose 'local' or 'ray'")
    return int(jobs)


def _make_backend(backend: str, jobs: int | None, ray_options: dict | None):
    jobs = _check_backend(backend, jobs)
    threads = max(1, cpu_count() // jobs)
    if backend == "local":
        return _Serial(None) if jobs == 1 else _Pool(int(jobs), threads)
    if backend == "ray":
        return RayBackend(**(ray_options or {}))
    raise ValueError(f"unknown backend {backend!r}; choose 'local' or 'ray'")


# -- the batch -----------------------------------------------------------------------------------


class BatchProgress:
    """A progress bar with rate and ETA on one line of stderr (or a line per pair when the stream
    is not a terminal)."""

    def __init__(self, total: int, *, stream=None, enabled: bool = True):
        self.total, self.stream, self.enabled = total, stream or sys.stderr, enabled
        self.done = self.failed = self.skipped = 0
        self.t0 = time.perf_counter()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def __call__(self, r: PairResult) -> None:
        self.done += 1
        self.failed += not r.ok
        self.skipped += r.skipped
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.t0
        computed = self.done - self.skipped
        rate = computed / elapsed if computed and elapsed > 0 else 0.0
        left = self.total - self.done
        eta = f"{int(left / rate) // 60}m{int(left / rate) % 60:02d}s" if rate else "?"
        width = 24
        fill = int(width * self.done / max(self.total, 1))
        line = (
            f"[{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total} pairs"
            f" ({self.failed} failed, {self.skipped} skipped) {60 * rate:.1f}/min ETA {eta}"
        )
        if self.tty:
            self.stream.write("\r" + line + ("\n" if self.done == self.total else ""))
        else:
            status = "skipped" if r.skipped else ("ok" if r.ok else f"FAILED: {r.error}")
            self.stream.write(f"{line} | {r.a} -> {r.b}: {status}\n")
        self.stream.flush()


#: Map file formats of a batch and their suffixes.
MAP_FORMATS = {"txt": ".txt", "npy": ".npy"}


def map_name(a: str, b: str, map_format: str = "txt") -> str:
    """File name of the map of pair (a, b) in the output folder."""
    return f"{a}__{b}{MAP_FORMATS[map_format]}"


def existing_map(path: Path, n_a: int, n_b: int) -> tuple[np.ndarray | None, str | None]:
    """A map file left by an earlier run: ``(map, None)`` when it is whole (n_a indices in
    [0, n_b), text ending with its newline), else ``(None, why it must be redone)``."""
    try:
        m = read_map(path, n_a, n_b)
        if not text_map_is_complete(path):
            return None, f"map {str(path)!r} ends inside its last line (cut short)"
    except (ValueError, OSError) as e:
        return None, str(e)
    return m, None


def imatch_many(
    shapes,
    pairs=None,
    *,
    out_dir: str | os.PathLike | None = None,
    jobs: int | None = None,
    backend: str = "local",
    cache: ShapeCache | str | os.PathLike | bool | None = True,
    init: str = "shot",
    k_max: int = 8,
    progress=None,
    ray_options: dict | None = None,
    map_format: str = "txt",
    landmarks=None,
    **match_options,
) -> Generator[PairResult, None, None]:
    """Like :func:`match_many`, but yields each :class:`PairResult` as soon as it is done
    (finished pairs first, in no particular order). Closing the generator early (or an
    exception, Ctrl-C) ends the workers at once; the maps already written stay."""
    if isinstance(shapes, dict):
        names, shapes = [str(k) for k in shapes], list(shapes.values())
    else:
        shapes = list(shapes)
        names = _names_of(shapes)
    if not shapes:
        raise ValueError("no shapes given")
    if not isinstance(init, str) or init not in ("shot", "wks", "hks"):
        raise ValueError(f"init must be 'shot', 'wks' or 'hks' in a batch, got {init!r}")
    if map_format not in MAP_FORMATS:
        raise ValueError(f"map_format must be one of {sorted(MAP_FORMATS)}, got {map_format!r}")
    check_match_options(init=init, k_max=k_max, **match_options)
    if (match_options.get("config") or MatchConfig()).shape != ShapeConfig():
        raise ValueError(
            "match_many computes and caches shapes with the default ShapeConfig; for other "
            "descriptor settings match the pairs with hope_rs.match and Shape(..., config=...)"
        )
    _check_backend(backend, jobs)
    ij = _resolve_pairs(pairs, names)
    marks = _pair_landmarks(landmarks, pairs, len(ij))
    specs = [_spec(s) for s in shapes]
    out = check_writable_folder(out_dir, create=True) if out_dir is not None else None
    tmp = None
    if cache is True or cache is None:
        cache = ShapeCache()
    elif cache is False:
        tmp = tempfile.TemporaryDirectory(prefix="hope_rs-batch-")
        cache = ShapeCache(tmp.name)
    elif not isinstance(cache, ShapeCache):
        cache = ShapeCache(cache)
    kinds = (init,)
    report = progress if callable(progress) else BatchProgress(len(ij), enabled=bool(progress))

    # Each pair: (index, i, j, map path, whether an existing file is to be checked first).
    todo = []
    for n, (i, j) in enumerate(ij):
        path = out / map_name(names[i], names[j], map_format) if out is not None else None
        todo.append((n, i, j, path, path is not None and os.path.lexists(path)))
    try:
        ex = _make_backend(backend, jobs, ray_options)
    except BaseException:  # e.g. Ray missing or unreachable: no temporary cache left behind
        if tmp is not None:
            tmp.cleanup()
        raise
    finished = False
    try:
        cfg = match_options.get("config") or MatchConfig()
        cfg = cfg.with_options(**{k: v for k, v in match_options.items() if k in KEYWORDS})
        basis = cfg.spectral.k_end if cfg.spectral.enabled else 0
        job = {
            "cache_root": str(cache.root), "kinds": kinds, "k_max": k_max, "init": init,
            "options": match_options, "threads": getattr(ex, "threads", None), "basis": basis,
        }  # fmt: skip

        def failed_pair(n: int, i: int, j: int, path, error: str) -> PairResult:
            """The reported result of pair ``n`` that failed before it was matched."""
            r = PairResult(n, names[i], names[j], path=path)
            r.error = error
            report(r)
            return r

        handles: dict = {}  # handle -> ("prepare" | "size" | "pair", shape index or pair)
        submitted: dict[int, str] = {}  # shape -> "prepare" or "size"

        def prepare(s: int, full: bool) -> None:
            if submitted.get(s) == "prepare" or (not full and s in submitted):
                return
            submitted[s] = "prepare" if full else "size"
            # a size task only reads the mesh (its vertex count checks an existing map)
            args = (kinds, ex.ships_data, basis) if full else ((), False, 0)
            handles[ex.submit(prepare_task, specs[s], str(cache.root), *args)] = (
                "prepare" if full else "size", s,
            )  # fmt: skip

        for _, i, j, _, check in todo:
            if not check:
                prepare(i, True)
                prepare(j, True)
        for _, i, j, _, check in todo:
            if check:
                prepare(i, False)
                prepare(j, False)
        sizes: dict[int, int] = {}
        ready: dict[int, object] = {}
        failed: dict[int, str] = {}
        waiting = todo
        while handles:
            for h, value in ex.wait(list(handles)):
                kind, what = handles.pop(h)
                if kind in ("prepare", "size"):
                    if "error" in value:
                        failed[what] = f"{names[what]}: {value['error']}"
                    else:
                        sizes[what] = value["n_vertices"]
                        if kind == "prepare":
                            # a cache digest, or (Ray) a reference to the shape's arrays
                            ready[what] = value.get("token", value["digest"])
                    still = []
                    for t in waiting:
                        n, i, j, path, check = t
                        if i in failed or j in failed:
                            yield failed_pair(n, i, j, path, failed.get(i) or failed[j])
                            continue
                        if check:
                            if i not in sizes or j not in sizes:
                                still.append(t)
                                continue
                            assert path is not None  # a pair to check has a map file
                            m, why = existing_map(path, sizes[i], sizes[j])
                            if why is None and marks[n] is not None:
                                lm, bad = _checked_landmarks(marks[n], sizes[i], sizes[j])
                                if bad is not None:
                                    yield failed_pair(n, i, j, path, bad)
                                    continue
                                if (
                                    lm is not None
                                    and m is not None
                                    and (m[lm[:, 0]] != lm[:, 1]).any()
                                ):
                                    why = f"{path} does not keep the pair's landmarks"
                            if why is None:
                                r = PairResult(n, names[i], names[j], m, skipped=True, path=path)
                                report(r)
                                yield r
                                continue
                            warnings.warn(
                                f"{why}; computing it again", RuntimeWarning, stacklevel=2
                            )
                            t = (n, i, j, path, False)
                            prepare(i, True)
                            prepare(j, True)
                        if i in ready and j in ready:
                            # The indices, now that both sizes are known.
                            lm, bad = _checked_landmarks(marks[n], sizes[i], sizes[j])
                            if bad is not None:
                                yield failed_pair(n, i, j, path, bad)
                                continue
                            h = ex.submit(pair_task, job, ready[i], ready[j], lm)
                            handles[h] = ("pair", t)
                        else:
                            still.append(t)
                    waiting = still
                else:
                    n, i, j, path, _ = what
                    r = PairResult(n, names[i], names[j], path=path)
                    if "error" in value:
                        r.error = value["error"]
                    else:
                        r.map, r.timings = value["map"], value["timings"]
                        if path is not None:
                            write_map(path, r.map)
                    report(r)
                    yield r
        if waiting:  # every pair ends as a map, a skip or a failure: never dropped silently
            raise RuntimeError(f"{len(waiting)} pair(s) of the batch were never run")
        finished = True
    finally:
        ex.close(abort=not finished)
        if tmp is not None:
            tmp.cleanup()


def _checked_landmarks(landmarks, n_a: int, n_b: int) -> tuple:
    """(the pair's landmarks checked against its shapes' sizes, None) or (None, the error)."""
    try:
        return check_landmarks(landmarks, n_a, n_b), None
    except (TypeError, ValueError) as e:
        return None, error_text(e)


def _pair_landmarks(landmarks, pairs, n_pairs: int) -> list:
    """One landmark array (form checked; indices are checked per pair once its shapes are
    read) or ``None`` per pair."""
    if landmarks is None:
        return [None] * n_pairs
    if pairs is None:
        raise ValueError("landmarks belong to pairs: give the pairs they are for as well")
    try:
        marks = list(landmarks)
    except TypeError:
        raise TypeError(
            "landmarks must be a list with one entry per pair: None or an (m, 2) array"
        ) from None
    if len(marks) != n_pairs:
        raise ValueError(
            f"landmarks has {len(marks)} entries for {n_pairs} pairs; give one per pair"
        )
    for n, lm in enumerate(marks):
        try:
            check_landmarks(lm, None, None)
        except (TypeError, ValueError) as e:
            raise type(e)(f"landmarks[{n}] (for pairs[{n}]): {e}") from None
    return marks


def match_many(shapes, pairs=None, **kwargs) -> list[PairResult]:
    """Match many pairs of shapes, each shape precomputed once; one result per pair, in order.

    Parameters
    ----------
    shapes : list or dict
        Mesh file paths, :class:`~hope_rs.Mesh` or :class:`~hope_rs.Shape` objects (a dict maps
        names to them). Path shapes are named by their file stem, others by their position.
    pairs : list of (a, b), optional
        Indices into ``shapes`` or names; default every pair (i, j) with i < j.
    out_dir : path, keyword-only, optional
        Write each map to ``out_dir/<a>__<b>.txt`` (one B index per line) as soon as it is done,
        atomically; pairs whose file exists and is whole (right length, indices in range) are
        skipped (their map is read back), others are redone with a warning. The folder is
        created, and checked to be writable, before any work.
    map_format : {"txt", "npy"}
        Format of the map files (:func:`hope_rs.write_map`).
    jobs : int, optional
        Local worker processes (default :func:`default_jobs`: one per two cores, each with
        cores / jobs Rust threads); 1 runs in this process.
    backend : {"local", "ray"}
        ``"ray"`` runs the tasks on the Ray cluster ``ray.init()`` connects to (``pip install
        'hope-rs[ray]'``); ``ray_options`` are passed to :class:`hope_rs.batch.ray_backend.RayBackend`.
    cache : ShapeCache, path, True or False
        Per-shape cache (default :func:`hope_rs.batch.cache.default_cache_dir`); False keeps it in a
        temporary folder for this batch only.
    landmarks : list, optional
        One entry per pair of ``pairs`` (which must then be given): ``None`` or an (m, 2)
        array of (vertex of a, vertex of b) that the pair's map keeps, as for
        :func:`hope_rs.match`. Indices out of range fail that pair only, before it is matched.
    init, k_max, **match_options
        As for :func:`hope_rs.match` (``init`` must name descriptors).
    progress : bool or callable
        Show a progress bar on stderr, or call ``progress(result)`` per finished pair.

    Returns
    -------
    list of PairResult
        Failed pairs have ``error`` set and ``map`` None; they never stop the batch.
    """
    results = list(imatch_many(shapes, pairs, **kwargs))
    return sorted(results, key=lambda r: r.index)
