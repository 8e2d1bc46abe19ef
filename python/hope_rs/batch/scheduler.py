"""The scheduler of a batch: which task to start next, what to do with each result.

Prepare tasks (one per shape) fill the cache; a pair starts as soon as both its shapes are
ready. A pair whose map file exists is first checked (both shapes' digests and sizes, read by
cheap *size* tasks, against the file and the manifest) and skipped when nothing changed. The
parent process writes each map and its manifest entry as soon as its pair is done. Anything
that goes wrong with one shape or pair (a mesh that cannot be read, a worker that dies, a map
that cannot be written) fails that shape's or pair's results only.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..geometry.map_io import read_map, text_map_is_complete, write_map
from ..pipeline.landmarks import check_landmarks
from ..pipeline.result import MatchQuality
from .backends import Backend
from .manifest import Manifest, landmarks_digest, map_digest
from .tasks import error_text, pair_task, prepare_task

__all__ = ["PairResult", "Plan", "existing_map", "run"]


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
        Why the pair failed (e.g. the mesh could not be read, the map file could not be
        written: the message names it).
    skipped : bool
        The map file and its manifest entry already matched the pair (same meshes,
        landmarks, settings and code), so the pair was not recomputed (``map`` is read from
        the file).
    path : Path or None
        The map file, when an output folder was given.
    timings : dict
        ``MatchResult.timings`` of the pair, plus "load" (seconds to get both shapes ready).
    quality : MatchQuality or None
        ``MatchResult.quality`` of the pair (``likely_failed``: look at the map before using
        it); for a skipped pair as the manifest recorded it. ``None`` without a confidence
        (``ConfidenceConfig.enabled`` off), for a failed pair, or for a skipped one whose
        entry an older hope_rs wrote.
    """

    index: int
    a: str
    b: str
    map: np.ndarray | None = None
    error: str | None = None
    skipped: bool = False
    path: Path | None = None
    timings: dict = field(default_factory=dict)
    quality: MatchQuality | None = None

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def likely_failed(self) -> bool:
        """Whether the pair's map likely failed (its :attr:`quality` says so)."""
        return self.quality is not None and self.quality.likely_failed


@dataclass
class Plan:
    """Everything a batch runs, checked: built by :func:`hope_rs.batch.driver.imatch_many`."""

    names: list[str]  # shape names
    specs: list[dict]  # what a prepare task needs per shape
    pairs: list[tuple[int, int]]
    paths: list[Path | None]  # map file per pair
    landmarks: list  # (m, 2) array or None per pair
    landmark_files: list  # the file each pair's landmarks were read from, or None
    settings: list[str]  # settings key per pair
    job: dict  # what every pair task gets (the MatchConfig, the cache folder, ...)
    kinds: tuple[str, ...]  # descriptors computed per shape
    basis: int  # eigenpairs of the spectral pass cached per shape (0: none)
    code: str  # code version
    manifest: Manifest | None


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


def _checked_landmarks(landmarks, n_a: int, n_b: int, file: str | None) -> tuple:
    """(the pair's landmarks checked against its shapes' sizes, None) or (None, the error,
    naming the landmark file they were read from)."""
    try:
        return check_landmarks(landmarks, n_a, n_b), None
    except (TypeError, ValueError) as e:
        return None, ("" if file is None else f"landmark file {file!r}: ") + error_text(e)


def _quality(fields: dict | None) -> MatchQuality | None:
    """A :class:`MatchQuality` from its fields as a pair task or the manifest gives them;
    ``None`` for anything else (an entry another version wrote, or one edited by hand)."""
    names = [f.name for f in dataclasses.fields(MatchQuality)]
    if not isinstance(fields, dict) or sorted(fields) != sorted(names):
        return None
    numbers = [fields[n] for n in names if n != "likely_failed"]
    if not isinstance(fields["likely_failed"], bool) or not all(
        isinstance(x, (int, float)) and not isinstance(x, bool) for x in numbers
    ):
        return None
    return MatchQuality(**fields)


def run(plan: Plan, ex: Backend, report: Callable) -> Iterator[PairResult]:
    """Run the pairs of ``plan`` on ``ex``; yields each :class:`PairResult` as it is done and
    calls ``report`` with it first. Every pair ends as a map, a skip or a failure."""
    names, specs, cache_root = plan.names, plan.specs, plan.job["cache_root"]
    manifest = plan.manifest

    def result(n: int, **kw) -> PairResult:
        i, j = plan.pairs[n]
        r = PairResult(n, names[i], names[j], path=plan.paths[n], **kw)
        report(r)
        return r

    def entry(n: int) -> dict:
        i, j = plan.pairs[n]
        return {
            "a": names[i], "b": names[j], "a_digest": digests[i], "b_digest": digests[j],
            "landmarks": landmarks_digest(plan.landmarks[n]), "settings": plan.settings[n],
            "code": plan.code,
        }  # fmt: skip

    handles: dict = {}  # handle -> ("prepare" | "size", shape) or ("pair", pair)
    submitted: dict[int, str] = {}  # shape -> "prepare" or "size"

    def prepare(s: int, full: bool) -> None:
        if submitted.get(s) == "prepare" or (not full and s in submitted):
            return
        submitted[s] = "prepare" if full else "size"
        # a size task only reads the mesh: its size and digest check an existing map
        args = (plan.kinds, ex.ships_data, plan.basis) if full else ((), False, 0)
        handles[ex.submit(prepare_task, specs[s], cache_root, *args)] = (
            "prepare" if full else "size", s,
        )  # fmt: skip

    # Each waiting pair: (pair, whether an existing map file is to be checked first).
    waiting = []
    for n, path in enumerate(plan.paths):
        waiting.append((n, path is not None and os.path.lexists(path)))
    for n, check in waiting:
        if not check:
            prepare(plan.pairs[n][0], True)
            prepare(plan.pairs[n][1], True)
    for n, check in waiting:
        if check:
            prepare(plan.pairs[n][0], False)
            prepare(plan.pairs[n][1], False)

    sizes: dict[int, int] = {}
    digests: dict[int, str] = {}
    ready: dict[int, dict] = {}
    failed: dict[int, str] = {}

    def forget(n: int, stale: bool) -> str | None:
        """The pair's map is about to be redone: its old entry goes first; with ``stale`` (the
        map is unusable, or was made from other meshes or landmarks) the map file too, so that
        a failed or interrupted redo leaves no map that is wrong for today's inputs. A map of
        the same inputs made with other settings stays until the new one replaces it. The
        error, if either cannot be removed."""
        path = plan.paths[n]
        if manifest is not None and path is not None:
            try:
                manifest.forget(path.name)
            except OSError as e:
                return f"cannot update the batch manifest {str(manifest.path)!r}: {e.strerror or e}"
        if stale and path is not None:
            try:
                path.unlink(missing_ok=True)
            except OSError as e:
                return f"cannot remove the outdated map {str(path)!r}: {e.strerror or e}"
        return None

    def finish(n: int, value: dict) -> PairResult:
        """The result of a pair task: its map written (and recorded), or its failure."""
        path = plan.paths[n]
        if "error" in value:
            error = value["error"]
            if value.get("died"):
                i, j = plan.pairs[n]
                where = f" (map {str(path)!r})" if path is not None else ""
                error = f"{names[i]} -> {names[j]}{where}: {error} while matching it"
            return result(n, error=error)
        if path is not None:
            try:
                write_map(path, value["map"])
            except OSError as e:
                return result(n, error=f"cannot write the map {str(path)!r}: {e.strerror or e}")
            if manifest is not None:
                try:
                    manifest.record(
                        path.name,
                        entry(n)
                        | {"map_digest": map_digest(value["map"]), "quality": value["quality"]},
                    )
                except OSError as e:
                    warnings.warn(
                        f"cannot update the batch manifest {str(manifest.path)!r} "
                        f"({e.strerror or e}); a rerun computes {path.name} again",
                        RuntimeWarning,
                        stacklevel=2,
                    )
        return result(
            n, map=value["map"], timings=value["timings"], quality=_quality(value["quality"])
        )

    def loop() -> Iterator[PairResult]:
        """Start tasks as their inputs are ready; yield each pair's result."""
        nonlocal waiting
        while handles:
            for h, value in ex.wait(list(handles)):
                kind, what = handles.pop(h)
                if kind == "pair":
                    yield finish(what, value)
                    continue
                if "error" in value:
                    failed[what] = f"{names[what]}: {value['error']}"
                else:
                    sizes[what], digests[what] = value["n_vertices"], value["digest"]
                    if kind == "prepare":
                        # the arrays themselves (Ray), else the cache digest and the shape's config
                        ready[what] = value.get("token") or {
                            "digest": value["digest"], "config": specs[what]["config"],
                        }  # fmt: skip
                still: list[tuple[int, bool]] = []
                for n, check in waiting:
                    i, j = plan.pairs[n]
                    if i in failed or j in failed:
                        yield result(n, error=failed.get(i) or failed.get(j))
                        continue
                    if check:
                        if i not in sizes or j not in sizes:
                            still.append((n, check))
                            continue
                        lm, bad = _checked_landmarks(
                            plan.landmarks[n], sizes[i], sizes[j], plan.landmark_files[n]
                        )
                        if bad is not None:
                            yield result(n, error=bad)
                            continue
                        path = plan.paths[n]
                        assert path is not None  # a pair to check has a map file
                        if os.path.isdir(path):  # no map can be written there: fail now
                            yield result(
                                n,
                                error=f"cannot write the map {str(path)!r}: a folder is there; "
                                "move it away",
                            )
                            continue
                        m, why = existing_map(path, sizes[i], sizes[j])
                        old = {} if manifest is None else manifest.entries.get(path.name, {})
                        stale = why is not None or (
                            manifest is not None and manifest.inputs_changed(path.name, entry(n))
                        )
                        if manifest is not None and (why is None or "map_digest" in old):
                            # A whole map is checked against its entry, digest included; for
                            # one that no longer fits its meshes the entry says what changed (a
                            # mesh, the settings), not only the map's length.
                            digest = map_digest(m) if why is None else old["map_digest"]
                            why = (
                                manifest.why_redo(path.name, entry(n) | {"map_digest": digest})
                                or why
                            )
                        if why is None:
                            yield result(
                                n, map=m, skipped=True, quality=_quality(old.get("quality"))
                            )
                            continue
                        warnings.warn(
                            f"{path.name}: {why}; computing it again",
                            RuntimeWarning,
                            stacklevel=2,
                        )
                        check = False
                        bad = forget(n, stale)
                        if bad is not None:
                            yield result(n, error=bad)
                            continue
                        prepare(i, True)
                        prepare(j, True)
                    if i in ready and j in ready:
                        lm, bad = _checked_landmarks(
                            plan.landmarks[n], sizes[i], sizes[j], plan.landmark_files[n]
                        )
                        if bad is not None:
                            yield result(n, error=bad)
                            continue
                        handles[ex.submit(pair_task, plan.job, ready[i], ready[j], lm)] = (
                            "pair",
                            n,
                        )
                    else:
                        still.append((n, check))
                waiting = still
        for n, _ in waiting:  # every pair ends as a map, a skip or a failure: never dropped
            yield result(n, error="not run: its shapes were never prepared (an internal error)")

    yield from loop()
