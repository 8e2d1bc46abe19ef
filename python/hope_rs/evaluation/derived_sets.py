"""What the derived benchmark sets share (``hope-rs partial-set``, ``perturb-set``,
``resolution-set``): the sources and conditions checked, each set written to a scratch folder
and moved into place once complete, OFF and ``.vts`` writers, and the command line."""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from ..geometry.map_io import check_writable_folder, naming_errors
from ..geometry.mesh import Mesh
from .datasets import GIVE_PAIRS, Pair, pairs_of

__all__ = ["add_set_parser", "run_set_command", "set_jobs", "write_off", "write_sets", "write_vts"]


def write_off(path: Path, mesh: Mesh) -> None:
    """``mesh`` as an OFF file at ``path``; an OSError names the file."""
    with naming_errors(path), open(path, "w") as fh:
        fh.write(f"OFF\n{mesh.n_vertices} {mesh.n_faces} 0\n")
        np.savetxt(fh, mesh.vertices, fmt="%.9g")
        np.savetxt(fh, np.column_stack([np.full(mesh.n_faces, 3), mesh.faces]), fmt="%d")


def write_vts(path: Path, idx: np.ndarray) -> None:
    """0-based vertex indices as a ``.vts`` file (1-based, one a line); an OSError names the
    file."""
    with naming_errors(path):
        path.write_text("".join(f"{int(i) + 1}\n" for i in idx))


def set_jobs(
    sources,
    conditions: Sequence[str],
    known: Mapping[str, str],
    max_pairs: int | None,
    *,
    what: str = "condition",
    vts_needed: str | None = None,
) -> list[tuple[Path, list[Pair]]]:
    """``(source folder, its first max_pairs pairs)`` per source, checked before any work:
    at least one source, each with pairs and a folder name no other source has (the sets
    are named after it: the folder's own name, ``.`` included); every condition a key of
    ``known``; with ``vts_needed`` (the reason), every pair with ``.vts`` ground truth. The
    folders come back absolute."""
    if isinstance(sources, (str, os.PathLike)):
        sources = [sources]
    if not sources:
        raise ValueError("no data-set folder given (--from): give one or more, comma-separated")
    bad = [c for c in conditions if c not in known]
    if bad:
        raise ValueError(f"unknown {what} {', '.join(bad)}; the {what}s are {', '.join(known)}")
    twice = sorted({c for c in conditions if list(conditions).count(c) > 1})
    if twice:
        raise ValueError(f"{what} {', '.join(twice)} is given twice; list each once")
    jobs: list[tuple[Path, list[Pair]]] = []
    for src in sources:
        # Absolute, so that "." and ".." are named by the folder they stand for.
        folder = Path(os.path.abspath(src))
        if not folder.name:
            raise ValueError(
                f"{str(src)!r} is the root folder, which has no name to call the sets by; "
                "give a data-set folder"
            )
        same = [s for s, _ in jobs if s.name == folder.name]
        if same and same[0].resolve() == folder.resolve():
            raise ValueError(f"{str(src)!r} is given twice; list it once")
        if same:
            raise ValueError(
                f"{str(same[0])!r} and {str(src)!r} have the same folder name, and the sets "
                "written from each would replace the other's; rename one, or run them apart"
            )
        pairs = pairs_of(src)
        if not pairs:
            raise ValueError(f"{str(src)!r} has no pair to derive sets from: {GIVE_PAIRS}")
        if vts_needed is not None and any(p.a_vts is None for p in pairs):
            raise ValueError(f"{str(src)!r} has identity ground truth; {vts_needed}")
        jobs.append((folder, pairs[:max_pairs]))
    return jobs


def write_sets(
    out,
    jobs: list[tuple[Path, list[Pair]]],
    conditions: Sequence[str],
    names: Callable[[Path, str], list[str]],
    write: Callable[[list[Pair], str, list[Path]], bool],
) -> list[Path]:
    """For each source and condition, ``write(pairs, condition, folders)`` into scratch
    folders, one per name of ``names(source, condition)``, then each moved to ``out / name``
    (replacing an older one): an error or an interrupt leaves no half-written set. ``write``
    returns False when the condition kept no pair: then nothing is written. Returns the
    folders written. An ``out`` that is a source folder or inside one is refused first."""
    target = Path(os.path.realpath(out))
    for src, _ in jobs:
        if target.is_relative_to(os.path.realpath(src)):
            where = "is" if target == Path(os.path.realpath(src)) else "is inside"
            raise ValueError(
                f"output folder {os.fspath(out)!r} {where} the source data set {str(src)!r}, "
                "and the sets would be written into it; choose a folder outside it"
            )
    out = check_writable_folder(out, create=True)
    written = []
    for src, pairs in jobs:
        for cond in conditions:
            final = names(src, cond)
            scratch = [out / f".{n}.tmp" for n in final]
            try:
                if not write(pairs, cond, scratch):
                    continue
                for tmp, n in zip(scratch, final):
                    if (out / n).exists():
                        shutil.rmtree(out / n)
                    tmp.rename(out / n)
                    written.append(out / n)
            finally:
                for tmp in scratch:
                    shutil.rmtree(tmp, ignore_errors=True)
    return written


def add_set_parser(
    sub,
    name: str,
    *,
    help: str,
    description: str,
    conditions: Mapping[str, str],
    sources_help: str,
    max_pairs: int | None,
    func: Callable,
):
    """Register the command ``name`` that writes derived sets; returns its parser (for
    options of its own)."""
    p = sub.add_parser(
        name,
        help=help,
        description=description + "; ".join(f"{k}: {v}" for k, v in conditions.items()),
    )
    p.add_argument("out", help="output folder (created; not a --from folder nor inside one)")
    p.add_argument(
        "--from", dest="sources", required=True,
        help=f"comma-separated {sources_help}",
    )  # fmt: skip
    p.add_argument("--conditions", default=",".join(conditions), help="comma-separated")
    p.add_argument(
        "--max-pairs", type=int, default=max_pairs,
        help="first N pairs of each set" + (f" (default {max_pairs})" if max_pairs else ""),
    )  # fmt: skip
    p.set_defaults(func=func)
    return p


def run_set_command(args, write: Callable[..., list[Path]], note: str = "", **options) -> int:
    """Run a derived-set command: ``write(sources, out, conditions=..., max_pairs=...,
    **options)``, then one line saying what was written."""
    if args.max_pairs is not None and args.max_pairs < 1:
        raise ValueError(f"--max-pairs must be at least 1, got {args.max_pairs}")
    written = write(
        [s.strip() for s in args.sources.split(",") if s.strip()], args.out,
        conditions=[c.strip() for c in args.conditions.split(",")], max_pairs=args.max_pairs,
        **options,
    )  # fmt: skip
    # Pairs per set: a condition can leave pairs out (a shortcut set keeps only the pairs
    # whose B takes at least 3 welds).
    counts = {p.name: len(pairs_of(p)) for p in written}
    sizes = ", ".join(f"{k}: {n} pair{'' if n == 1 else 's'}" for k, n in counts.items())
    sizes = f" ({sizes})" if sizes else ""
    print(f"{len(written)} data sets written to {args.out}{sizes}; run: hope-rs bench "
          f"{args.out} --out RESULTS{note}")  # fmt: skip
    return 0
