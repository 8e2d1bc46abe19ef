"""The ``hope-rs`` command line: ``match`` two mesh files, run the bundled ``demo``, ``bench``
methods on data sets (:mod:`hope_rs.evaluation.bench`), ``show`` a map (:mod:`hope_rs.evaluation.show`) or match a
``batch`` of pairs (:mod:`hope_rs.batch`)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import os
import sys
import traceback
import warnings

import numpy as np

from .._terminate import interrupted_status, sigterm_raises
from .._version import __version__
from ..batch.driver import one_line_warning
from ..evaluation import bench, partial, perturbed, resolution, show
from ..evaluation.demo import run_demo
from ..geometry.map_io import (
    atomic_writes,
    check_not_an_input,
    check_output_file,
    map_format,
    map_writer,
    read_landmarks,
    read_map,
    same_file,
)
from ..geometry.mesh import load_mesh
from ..matching import match
from ..pipeline.landmarks import check_landmarks
from ..pipeline.progress import ProgressBar
from .batch_cli import add_batch_parser, add_setting_arguments, config_from_args, environment_help


def _summary(res) -> dict:
    return {
        "n_vertices": int(res.map.size),
        "iterations": [
            {
                "k": h.k,
                "witness_fraction": h.witness_fraction,
                "changed": h.changed,
                "seconds": h.seconds,
                "pass": h.n_pass,
                "polish": h.polish,
                "cost_seconds": h.cost_seconds,
                "assign_seconds": h.assign_seconds,
            }
            for h in res.history
        ],
        "timings": res.timings,
        "stages": [dataclasses.asdict(s) for s in res.stages],
        "quality": None if res.quality is None else vars(res.quality),
    }


#: ``hope-rs match`` suggests ``--multiscale`` when both meshes have at least this many vertices.
HINT_VERTICES = 100_000


def max_vertices(a, b) -> int:
    """The larger vertex count of two meshes (what the path is chosen by)."""
    return max(a.n_vertices, b.n_vertices)


def _is_standard_output(path: str) -> bool:
    """Whether the file ``path`` is where standard output goes (``/dev/stdout``, or the file
    standard output is redirected to)."""
    try:
        st, out = os.stat(path), os.fstat(sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        return False
    return (st.st_dev, st.st_ino) == (out.st_dev, out.st_ino)


def cmd_match(args) -> int:
    config = config_from_args(args)  # before any work, like the outputs below
    if args.output == "-":  # the usual name of standard output
        if args.json:
            raise ValueError(
                "-o '-' is the standard output, which already carries the JSON summary; give "
                "a file name (without -o the JSON holds the map)"
            )
        args.output = None
    if sys.stdout is None and (args.json or not args.output):
        raise ValueError(
            "standard output is closed, and the "
            f"{'JSON summary' if args.json else 'map'} goes there; give -o FILE"
            f"{' and leave out --json' if args.json else ''}"
        )
    # Standard output carries the JSON, or the map when there is no -o: no file may go there too.
    for option, path, printed in [
        ("-o", args.output, args.json),
        ("--confidence-out", args.confidence_out, args.json or not args.output),
    ]:
        if path and printed and _is_standard_output(path):
            raise ValueError(
                f"{option} {path!r} is the standard output, which already carries "
                f"{'the JSON summary' if args.json else 'the map'}; give a file name "
                f"{'(without -o the JSON holds the map)' if option == '-o' else ''}".rstrip()
            )
    if args.output is not None and not args.output.strip():
        raise ValueError("-o names no file (an empty path); leave -o out to print the map")
    if args.init_map is not None and args.init is not None:
        raise ValueError(
            "give --init (the descriptors of the starting map) or --init-map (a starting map "
            "file), not both"
        )
    inputs = [args.a, args.b, args.landmarks, args.init_map, args.config]
    if args.output:  # before any work: a known suffix, a folder we can write to
        check_output_file(args.output, "-o")
        check_not_an_input(args.output, inputs, "-o")
        map_format(args.output)
    if args.confidence_out:
        if not args.confidence_out.endswith(".npy"):
            raise ValueError(
                f"--confidence-out {args.confidence_out!r} must end in .npy (a NumPy float array)"
            )
        check_output_file(args.confidence_out, "--confidence-out")
        check_not_an_input(args.confidence_out, inputs, "--confidence-out")
        if not config.confidence.enabled:
            raise ValueError(
                "--confidence-out needs the confidence stage, which the --config file turns "
                "off ([confidence] enabled = false): drop one of the two"
            )
        if args.output and same_file(args.output, args.confidence_out):
            raise ValueError(
                f"-o and --confidence-out name the same file {args.output!r}; the confidence "
                "would overwrite the map: give two file names"
            )
    landmarks = None if args.landmarks is None else read_landmarks(args.landmarks)
    # A starting map read before the meshes (its form), again with their sizes (its length
    # and range); without one, the descriptors of the settings.
    init = None if args.init_map is None else read_map(args.init_map)
    a, b = load_mesh(args.a), load_mesh(args.b)
    if args.init_map is not None:
        init = read_map(args.init_map, n=a.n_vertices, n_target=b.n_vertices)
    if landmarks is not None:  # again, with the meshes' sizes: a bad index named by its line
        landmarks = read_landmarks(args.landmarks, n_a=a.n_vertices, n_b=b.n_vertices)
        try:
            check_landmarks(landmarks, a.n_vertices, b.n_vertices)
        except (TypeError, ValueError) as e:
            raise type(e)(f"{args.landmarks}: {e}") from None
    if (
        not config.multiscale.enabled
        and (
            config.multiscale.enabled is False
            or max_vertices(a, b) <= config.multiscale.auto_vertices
        )
        and not args.quiet
        and min(a.n_vertices, b.n_vertices) >= HINT_VERTICES
    ):
        print(
            "hope-rs: hint: on meshes this large, --multiscale is about 3x faster, with a larger "
            "error (see docs/method.md, multiscale)",
            file=sys.stderr,
        )
    # The bar on a terminal; with -v the log says the same, one line per stage.
    bar = ProgressBar()
    show_bar = bar.live and not args.quiet and not args.verbose
    try:
        res = match(
            a,
            b,
            init=init,
            landmarks=landmarks,
            progress=bar if show_bar else None,
            config=config,
        )
    except ValueError as e:
        # A mesh that cannot be matched, named "a: ..." or "b: ...": named by its file here.
        which = {"a: ": args.a, "b: ": args.b}.get(str(e)[:3])
        if which is None:
            raise
        raise ValueError(f"cannot match {which!r}: {str(e)[3:]}") from None
    finally:
        bar.close()
    coarse = next((s for s in res.stages if s.name == "coarse"), None)
    if coarse is not None and not coarse.ran and not args.quiet and not args.verbose:
        print(f"hope-rs: note: --multiscale: {coarse.reason}", file=sys.stderr)
    # A warning about the map itself, printed with -q too (it is not progress).
    if res.quality is not None and res.quality.likely_failed:
        print(
            f"hope-rs: warning: this match likely failed ({res.quality.describe()}); "
            "look at it with hope-rs show --color-by confidence",
            file=sys.stderr,
        )
    # Both files, or neither (a full disk).
    files = [] if not args.output else [(args.output, map_writer(args.output, res.map))]
    if args.confidence_out:
        conf = res.confidence
        assert conf is not None  # checked above: the confidence stage is on
        files.append((args.confidence_out, lambda fh: np.save(fh, conf, allow_pickle=False)))
    atomic_writes(files)
    if not args.output and not args.json:
        sys.stdout.write("\n".join(map(str, res.map.tolist())) + "\n")
    if args.json:
        summary = _summary(res)
        if not args.output:
            # Standard output holds the one JSON document, so the map goes into it.
            summary["map"] = res.map.tolist()
        print(json.dumps(summary, indent=2))
    return 0


def cmd_demo(args) -> int:

    report = run_demo(verbose=not args.json)
    if args.json:
        print(json.dumps(report, indent=2))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="hope-rs",
        description="Dense 3D shape matching with HOPE.",
        epilog=environment_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"hope-rs {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    p.add_argument(
        "-v", "--verbose", action="count", default=0,
        help="log each stage with its time and why a stage was skipped (-vv: every step) on stderr",
    )  # fmt: skip
    m = sub.add_parser(
        "match",
        help="match mesh A to mesh B; writes one B vertex index per line",
        epilog=environment_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    m.add_argument("a", help="source mesh (OFF, OBJ, PLY, STL, GLB)")
    m.add_argument("b", help="target mesh")
    m.add_argument(
        "-o", "--output",
        help="map file: .txt or .csv (one B index per line) or .npy (NumPy int64); written "
        "atomically (default, or '-': standard output)",
    )  # fmt: skip
    add_setting_arguments(m)
    m.add_argument(
        "--landmarks", metavar="FILE",
        help="vertex pairs known to correspond, one 'A_VERTEX B_VERTEX' line each (0-based): "
        "mapped exactly, and the map around them follows",
    )  # fmt: skip
    m.add_argument(
        "--init-map", metavar="FILE",
        help="start from this map instead of descriptors: a map file as -o writes it (one "
        "0-based B vertex per vertex of A; .txt, .csv or .npy)",
    )  # fmt: skip
    m.add_argument(
        "--no-spectral",
        action="store_true",
        help="return HOPE's own map, without the spectral (ZoomOut) pass after it",
    )
    m.add_argument(
        "--no-shared-faces",
        action="store_true",
        help="skip the finishing rounds for shapes that share their triangulation",
    )
    m.add_argument(
        "--confidence-out", metavar="FILE.npy",
        help="write the per-vertex confidence of the map (float64 in [0, 1], one per vertex of "
        "A) for hope-rs show --color-by confidence --confidence FILE.npy",
    )  # fmt: skip
    m.add_argument(
        "--json", action="store_true",
        help="print timings and a summary as JSON (without -o, with the map as its \"map\")",
    )  # fmt: skip
    m.add_argument(
        "-q", "--quiet", action="store_true",
        help="no progress bar, hints or notes (a warning that the match likely failed still "
        "prints)",
    )  # fmt: skip
    m.add_argument(
        "-v", "--verbose", action="count", default=0, dest="match_verbose",
        help="as hope-rs -v, adding up with it: log each stage (-vv: every step) instead of "
        "the bar",
    )  # fmt: skip
    m.set_defaults(func=cmd_match)
    d = sub.add_parser(
        "demo", help="match the two bundled FAUST pairs and score them against ground truth"
    )
    d.add_argument("--json", action="store_true", help="print the report as JSON")
    d.set_defaults(func=cmd_demo)

    bench.add_parser(sub)
    partial.add_parser(sub)
    perturbed.add_parser(sub)
    resolution.add_parser(sub)
    show.add_parser(sub)
    add_batch_parser(sub)
    return p


#: Errors that are the input's or the user's, not the program's: exit status 2, one line.
USAGE_ERRORS = (
    ValueError, TypeError, FileNotFoundError, PermissionError, IsADirectoryError,
    NotADirectoryError,
)  # fmt: skip


def main(argv=None) -> int:
    """Run the command line; returns the exit status (see ``hope-rs --help``)."""
    args = build_parser().parse_args(argv)
    args.verbose += getattr(args, "match_verbose", 0)  # `hope-rs -v match -v` is -vv
    debug = os.environ.get("HOPE_RS_DEBUG", "") not in ("", "0")
    formatwarning, warnings.formatwarning = warnings.formatwarning, one_line_warning
    handler = _log_to_stderr(args.verbose)
    try:
        with sigterm_raises():
            return args.func(args)
    except KeyboardInterrupt as e:
        print("hope-rs: interrupted", file=sys.stderr)
        return interrupted_status(e)
    except BrokenPipeError:
        # The reader closed the pipe (`| head`): stop quietly, as other tools do; the output
        # goes nowhere from here, so the flush at exit cannot fail again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141  # 128 + SIGPIPE
    except MemoryError as e:  # a run too large for this machine: not the input's fault
        if debug:
            traceback.print_exc()
        print(f"hope-rs: error: out of memory: {e}", file=sys.stderr)
        return 1
    except USAGE_ERRORS as e:
        if debug:
            traceback.print_exc()
        print(f"hope-rs: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # e.g. a full disk while writing: the run failed, not its input
        if debug:
            traceback.print_exc()
        print(f"hope-rs: error: {e}", file=sys.stderr)
        return 1
    except Exception as e:  # noqa: BLE001 - a bug: one line and a hint, not a traceback
        if debug:
            traceback.print_exc()
        print(
            f"hope-rs: internal error: {type(e).__name__}: {e} (rerun with HOPE_RS_DEBUG=1 for "
            "the traceback, and please report it)",
            file=sys.stderr,
        )
        return 1
    finally:
        warnings.formatwarning = formatwarning
        if handler is not None:
            logger = logging.getLogger("hope_rs")
            logger.removeHandler(handler)
            logger.setLevel(handler.previous_level)


class _StderrHandler(logging.StreamHandler):
    """A handler that remembers the logger's level before it was added."""

    previous_level: int = logging.NOTSET


def _log_to_stderr(verbose: int) -> _StderrHandler | None:
    """With -v, the package logger's INFO lines (one per stage) on stderr; -vv adds DEBUG
    (one per refinement step). Returns the handler, to remove when the command ends."""
    if not verbose:
        return None
    handler = _StderrHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("hope-rs: %(message)s"))
    logger = logging.getLogger("hope_rs")
    handler.previous_level = logger.level
    logger.setLevel(logging.INFO if verbose == 1 else logging.DEBUG)
    logger.addHandler(handler)
    return handler
