"""``hope-rs batch PAIRS_FILE --out DIR``: the command line of :mod:`hope_rs.batch`."""

from __future__ import annotations

import argparse
import os
import sys
import textwrap
import time

from .._terminate import interrupted_status
from ..batch.driver import imatch_many, read_pairs
from ..batch.pairs_file import landmark_files
from ..matching import check_match_options
from ..pipeline.config import MatchConfig, read_config

__all__ = [
    "ENVIRONMENT",
    "EXIT_STATUS",
    "add_batch_parser",
    "add_setting_arguments",
    "cmd_batch",
    "config_from_args",
    "environment_help",
]

#: Environment variables the command line reads, with what they do (the one list the help
#: texts print and the README is checked against).
ENVIRONMENT = {
    "HOPE_RS_CACHE": "per-shape cache folder (default $XDG_CACHE_HOME/hope_rs)",
    "XDG_CACHE_HOME": "base of the default cache folder (default ~/.cache)",
    "RAYON_NUM_THREADS": "threads of the Rust kernels (default: every core; in a batch, "
    "cores / jobs per worker)",
    "HOPE_NO_SIMD": "set: run the portable loops instead of the AVX2/AVX-512 ones",
    "HOPE_RS_DEBUG": "set to 1: print the traceback of an unexpected error",
}

#: Exit statuses of every subcommand.
EXIT_STATUS = {
    0: "success",
    1: "a runtime failure: a pair of a batch or of bench failed, an output could not be "
    "written, or an internal error",
    2: "a usage or input error: bad arguments, an unreadable or malformed input file, an "
    "unwritable output folder (nothing is computed)",
    130: "interrupted (Ctrl-C); a batch keeps the maps already written",
    143: "ended by SIGTERM (kill, timeout, a scheduler), cleaned up as after Ctrl-C",
}


def environment_help() -> str:
    """The ``exit status`` and ``environment`` sections of a help epilog."""

    def item(head: str, text: str, width: int) -> str:
        return textwrap.fill(
            text, 78, initial_indent=f"  {head:<{width}} ", subsequent_indent=" " * (width + 3)
        )

    lines = ["exit status:"]
    lines += [item(str(code), text, 4) for code, text in EXIT_STATUS.items()]
    lines.append("environment:")
    lines += [item(name, text, 18) for name, text in ENVIRONMENT.items()]
    return "\n".join(lines)


def add_setting_arguments(p) -> None:
    """The options of ``match`` and ``batch`` that set the MatchConfig (see
    :func:`config_from_args`): ``--config FILE`` and the shortcuts over it."""
    p.add_argument(
        "--config", metavar="SETTINGS.toml",
        help="every setting of the match, as MatchConfig.to_dict() nests them (stage tables, "
        "e.g. [refine] max_passes = 2); the options below are set over it",
    )  # fmt: skip
    p.add_argument(
        "--init", choices=["shot", "wks", "hks"], help="descriptors (default: shot, or --config's)"
    )
    p.add_argument("--k-max", type=int, help="largest hop radius (default: 8, or --config's)")
    path = p.add_mutually_exclusive_group()
    path.add_argument(
        "--multiscale",
        action="store_true",
        help="match coarse copies first, then fine passes (faster, less exact; the default above "
        "60,000 vertices)",
    )
    path.add_argument(
        "--no-multiscale",
        action="store_true",
        help="the full path at any size (slower on large meshes, more exact where the shapes "
        "share a triangulation)",
    )


def config_from_args(args) -> MatchConfig:
    """The MatchConfig of ``--config`` (default ``MatchConfig()``) with the command line's
    shortcuts set through the same :meth:`~hope_rs.MatchConfig.with_options` as
    :func:`hope_rs.match`'s keyword options, checked before any work."""
    config = read_config(args.config) if args.config else MatchConfig()
    if args.config:  # its values checked here, so that the message names the file
        try:
            check_match_options(config=config)
        except (TypeError, ValueError) as e:
            raise type(e)(f"settings file {str(args.config)!r}: {e}") from None
    options = {}
    if args.k_max is not None:
        options["k_max"] = args.k_max
    if args.multiscale or args.no_multiscale:
        options["multiscale"] = bool(args.multiscale)
    if args.no_spectral:
        options["spectral"] = False
    if args.no_shared_faces:
        options["shared_faces"] = False
    # The init kind is recorded in config.initial.descriptor, as match records it.
    return check_match_options(config=config, init=args.init, **options)


def add_batch_parser(sub) -> None:
    """Register the ``batch`` subcommand on an argparse subparsers object."""
    p = sub.add_parser(
        "batch",
        help="match every pair of a pairs file; one map file per pair in --out",
        description=textwrap.fill(
            "Match every pair listed in PAIRS_FILE (one pair per line: two mesh paths, relative "
            "ones resolved against the file's folder; quote paths holding spaces or separate "
            "the two with a tab; an optional third field names the pair's landmark file, as "
            "hope-rs match --landmarks reads it). Each map is written atomically to "
            "OUT/<a>__<b>.txt (or .npy) as soon as it is done, and recorded in "
            "OUT/hope-rs-manifest.jsonl with the digests of both meshes and of the landmarks, "
            "the settings and the code version; a rerun (e.g. after Ctrl-C or a crash) skips "
            "pairs whose map file is whole and whose record matches, and redoes the others, "
            "saying why. Exit status 1 when some pair failed (the others still finish).",
            78,
        ),
        epilog=environment_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "pairs",
        metavar="PAIRS_FILE",
        help="text file, one pair of mesh paths a line (and optionally a landmark file)",
    )
    p.add_argument("--out", required=True, help="output folder (created if missing)")
    p.add_argument(
        "--format", default="txt", choices=["txt", "npy"],
        help="map files: txt (one B index per line, default) or npy (NumPy int64)",
    )  # fmt: skip
    p.add_argument(
        "--ext", default="", help="suffix appended to names without a mesh suffix, e.g. .off"
    )
    p.add_argument(
        "-j", "--jobs", type=int, help="local worker processes (default: one per two cores)"
    )
    p.add_argument("--backend", default="local", choices=["local", "ray"], help="where to run")
    p.add_argument("--ray-address", help="Ray cluster address (default: ray.init()'s choice)")
    p.add_argument("--cache", help="per-shape cache folder (default: $HOPE_RS_CACHE)")
    p.add_argument("--no-cache", action="store_true", help="keep the cache for this run only")
    add_setting_arguments(p)
    p.add_argument(
        "--no-spectral", action="store_true", help="match(..., spectral=False) for every pair"
    )
    p.add_argument(
        "--no-shared-faces",
        action="store_true",
        help="match(..., shared_faces=False) for every pair",
    )
    p.add_argument(
        "-q", "--quiet", action="store_true", help="no progress output (warnings still print)"
    )
    p.set_defaults(func=cmd_batch)


def cmd_batch(args) -> int:

    if args.no_cache and args.cache:
        raise ValueError("give either --cache DIR or --no-cache, not both")
    if args.backend != "ray" and args.ray_address:
        raise ValueError("--ray-address needs --backend ray")
    if args.jobs is not None and args.jobs < 1:
        raise ValueError(f"--jobs must be a positive integer, got {args.jobs}")
    config = config_from_args(args)
    pairs, landmarks = read_pairs(args.pairs, ext=args.ext, with_landmarks=True)
    shapes = list(dict.fromkeys(p for pair in pairs for p in pair))
    missing = [p for p in shapes if not os.path.isfile(p)]
    if missing:  # a warning, not progress: -q keeps it
        # Their pairs fail, the others run; a name without a suffix hints at the cause.
        hint = (
            "; names without a suffix need --ext (e.g. --ext .off)"
            if not args.ext and any(not p.suffix for p in missing)
            else ""
        )
        print(
            f"hope-rs: warning: {len(missing)} mesh file(s) of the pairs file do not exist "
            f"(e.g. {os.fspath(missing[0])!r}); their pairs will fail{hint}",
            file=sys.stderr,
        )
    index = {p: i for i, p in enumerate(shapes)}
    t0 = time.perf_counter()
    counts = {"matched": 0, "skipped": 0, "failed": 0}
    failures, doubtful = [], []
    results = imatch_many(
        shapes,
        [(index[a], index[b]) for a, b in pairs],
        out_dir=args.out,
        jobs=args.jobs,
        backend=args.backend,
        cache=False if args.no_cache else (args.cache or True),
        config=config,
        progress=not args.quiet,
        ray_options={"address": args.ray_address} if args.backend == "ray" else None,
        map_format=args.format,
        # Each pair's landmark file (its form checked above), so that a pair's error names it.
        landmarks=None
        if all(lm is None for lm in landmarks)
        else landmark_files(args.pairs, ext=args.ext),
    )
    interrupted: KeyboardInterrupt | None = None
    started = False
    try:
        for r in results:
            started = True
            counts["skipped" if r.skipped else ("matched" if r.ok else "failed")] += 1
            if not r.ok:
                failures.append(f"{r.a} -> {r.b}: {r.error}")
            elif r.quality is not None and r.quality.likely_failed:
                doubtful.append(f"{r.a} -> {r.b}: likely failed ({r.quality.describe()})")
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM (hope_rs._terminate)
        interrupted, started = e, True
    finally:
        results.close()  # on any early exit: end the workers now
        if started:
            seconds = time.perf_counter() - t0
            _summary(args, len(pairs), counts, failures, doubtful, seconds, interrupted is not None)
    if interrupted is not None:
        print(
            "hope-rs: interrupted; the maps written are kept, rerun the same command to finish",
            file=sys.stderr,
        )
        return interrupted_status(interrupted)
    return 1 if counts["failed"] else 0


def _summary(
    args,
    total: int,
    counts: dict,
    failures: list,
    doubtful: list,
    seconds: float,
    interrupted: bool,
):
    for line in failures:
        print(f"hope-rs: pair failed: {line}", file=sys.stderr)
    for line in doubtful:
        print(f"hope-rs: warning: {line}", file=sys.stderr)
    rate = 60 * counts["matched"] / seconds if seconds > 0 else 0.0
    left = total - sum(counts.values())
    print(
        f"{total} pairs: {counts['matched']} matched, {counts['skipped']} skipped, "
        f"{counts['failed']} failed, {left} not run"
        + (f", {len(doubtful)} likely failed" if doubtful else "")
        + (" (interrupted)" if interrupted else "")
        + f" in {seconds:.1f} s ({rate:.1f} pairs/min) -> {args.out}",
        flush=True,
    )  # fmt: skip
