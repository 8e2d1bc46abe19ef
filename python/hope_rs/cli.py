"""The ``hope-rs`` command line: ``match`` two mesh files, run the bundled ``demo``, ``bench``
methods on data sets (:mod:`hope_rs.bench`), ``show`` a map (:mod:`hope_rs.show`) or match a
``batch`` of pairs (:mod:`hope_rs.batch`)."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import traceback
import warnings

from . import __version__
from .batch_cli import add_batch_parser, environment_help
from .map_io import check_writable_folder, map_format, write_map


class Progress:
    """A one-line progress report on stderr, rewritten after every refinement step.

    The number of passes depends on convergence, so it shows steps done, the current pass's
    position in the k schedule and the elapsed time rather than a fixed-length bar.
    """

    def __init__(self, steps_per_pass: int, *, enabled: bool):
        self.per_pass, self.done, self.enabled = steps_per_pass, 0, enabled
        self.t0 = time.perf_counter()

    def step(self, it) -> None:
        self.done += 1
        if not self.enabled:
            return
        n_pass, in_pass = divmod(self.done - 1, self.per_pass)
        width = 16
        fill = int(width * (in_pass + 1) / self.per_pass)
        sys.stderr.write(
            f"\rrefining pass {n_pass + 1} [{'#' * fill}{'.' * (width - fill)}] k={it.k} "
            f"witnesses {100 * it.witness_fraction:4.1f}% changed {it.changed:6d} "
            f"{time.perf_counter() - self.t0:6.1f}s"
        )
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.done:
            sys.stderr.write("\n")


def _summary(res) -> dict:
    return {
        "n_vertices": int(res.map.size),
        "iterations": [
            {
                "k": h.k,
                "witness_fraction": h.witness_fraction,
                "changed": h.changed,
                "seconds": h.seconds,
            }
            for h in res.history
        ],
        "timings": res.timings,
    }


#: ``hope-rs match`` suggests ``--multiscale`` when both meshes have at least this many vertices.
HINT_VERTICES = 100_000


def cmd_match(args) -> int:
    from .matching import match
    from .mesh import load_mesh
    from .refine import default_schedule

    if args.output:  # before any work: a known suffix, a folder we can write to
        if os.path.isdir(args.output):
            raise ValueError(f"output {args.output!r} is a folder; give a file name")
        map_format(args.output)
        check_writable_folder(os.path.dirname(os.path.abspath(args.output)))
    a, b = load_mesh(args.a), load_mesh(args.b)
    if not args.multiscale and not args.quiet and min(a.n_vertices, b.n_vertices) >= HINT_VERTICES:
        print(
            "hope-rs: hint: on meshes this large, --multiscale is about 3x faster, with a larger "
            "error (see the README)",
            file=sys.stderr,
        )
    # One global repair step (k = 0) starts every pass.
    progress = Progress(
        len(default_schedule(args.k_max)) + 1, enabled=not args.quiet and sys.stderr.isatty()
    )
    try:
        res = match(
            a, b, init=args.init, k_max=args.k_max, multiscale=args.multiscale,
            spectral=not args.no_spectral, shared_faces=not args.no_shared_faces,
            callback=progress.step,
        )  # fmt: skip
    finally:
        progress.close()
    if args.output:
        write_map(args.output, res.map)
    elif not args.json:
        sys.stdout.write("\n".join(map(str, res.map.tolist())) + "\n")
    if args.json:
        print(json.dumps(_summary(res), indent=2))
    return 0


def cmd_demo(args) -> int:
    from .demo import run_demo

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
    m = sub.add_parser(
        "match",
        help="match mesh A to mesh B; writes one B vertex index per line",
        epilog=environment_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    m.add_argument("a", help="source mesh (OFF, OBJ, PLY, STL)")
    m.add_argument("b", help="target mesh")
    m.add_argument(
        "-o", "--output",
        help="map file: .txt or .csv (one B index per line) or .npy (NumPy int64); written "
        "atomically (default: standard output)",
    )  # fmt: skip
    m.add_argument("--init", default="shot", choices=["shot", "wks", "hks"], help="descriptors")
    m.add_argument("--k-max", type=int, default=8, help="largest hop radius (default 8)")
    m.add_argument(
        "--multiscale",
        action="store_true",
        help="for large meshes: match coarse copies first, then one or two fine passes (faster, less exact)",
    )
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
    m.add_argument("--json", action="store_true", help="print timings and a summary as JSON")
    m.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    m.set_defaults(func=cmd_match)
    d = sub.add_parser(
        "demo", help="match the bundled FAUST pair and score it against ground truth"
    )
    d.add_argument("--json", action="store_true", help="print the report as JSON")
    d.set_defaults(func=cmd_demo)
    from . import bench, show  # light imports: matplotlib, pyFM load only when run

    bench.add_parser(sub)
    show.add_parser(sub)
    add_batch_parser(sub)
    return p


#: Errors that are the input's or the user's, not the program's: exit status 2, one line.
USAGE_ERRORS = (
    ValueError, TypeError, FileNotFoundError, PermissionError, IsADirectoryError,
    NotADirectoryError,
)  # fmt: skip


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    return f"hope-rs: warning: {message}\n"


def main(argv=None) -> int:
    """Run the command line; returns the exit status (see ``hope-rs --help``)."""
    args = build_parser().parse_args(argv)
    debug = os.environ.get("HOPE_RS_DEBUG", "") not in ("", "0")
    formatwarning, warnings.formatwarning = warnings.formatwarning, _one_line_warning
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("hope-rs: interrupted", file=sys.stderr)
        return 130
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


if __name__ == "__main__":
    sys.exit(main())
