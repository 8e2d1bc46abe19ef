"""``hope-rs batch PAIRS_FILE --out DIR``: the command line of :mod:`hope_rs.batch`."""

from __future__ import annotations

import sys
import time


def add_batch_parser(sub) -> None:
    """Register the ``batch`` subcommand on an argparse subparsers object."""
    p = sub.add_parser(
        "batch",
        help="match every pair of a pairs file; one map file per pair in --out",
        description="Match every pair listed in PAIRS_FILE (one pair per line: two mesh paths, "
        "relative ones resolved against the file's folder). Each map is written atomically to "
        "OUT/<a>__<b>.txt as soon as it is done; a rerun skips pairs already written. Exit "
        "status 1 when some pair failed (the others still finish).",
    )
    p.add_argument("pairs", metavar="PAIRS_FILE", help="text file, one pair of mesh paths a line")
    p.add_argument("--out", required=True, help="output folder (created if missing)")
    p.add_argument("--ext", default="", help="suffix appended to names without it, e.g. .off")
    p.add_argument(
        "-j", "--jobs", type=int, help="local worker processes (default: one per two cores)"
    )
    p.add_argument("--backend", default="local", choices=["local", "ray"], help="where to run")
    p.add_argument("--ray-address", help="Ray cluster address (default: ray.init()'s choice)")
    p.add_argument("--cache", help="per-shape cache folder (default: ~/.cache/hope_rs)")
    p.add_argument("--no-cache", action="store_true", help="keep the cache for this run only")
    p.add_argument("--init", default="shot", choices=["shot", "wks", "hks"], help="descriptors")
    p.add_argument("--k-max", type=int, default=8, help="largest hop radius (default 8)")
    p.add_argument(
        "--multiscale", action="store_true", help="match(..., multiscale=True) for every pair"
    )
    p.add_argument(
        "--no-spectral", action="store_true", help="match(..., spectral=False) for every pair"
    )
    p.add_argument(
        "--no-shared-faces",
        action="store_true",
        help="match(..., shared_faces=False) for every pair",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=cmd_batch)


def cmd_batch(args) -> int:
    from .batch import imatch_many, read_pairs

    if args.no_cache and args.cache:
        raise ValueError("give either --cache DIR or --no-cache, not both")
    if args.backend != "ray" and args.ray_address:
        raise ValueError("--ray-address needs --backend ray")
    pairs = read_pairs(args.pairs, ext=args.ext)
    shapes = list(dict.fromkeys(p for pair in pairs for p in pair))
    index = {p: i for i, p in enumerate(shapes)}
    t0 = time.perf_counter()
    counts = {"matched": 0, "skipped": 0, "failed": 0}
    failures = []
    for r in imatch_many(
        shapes,
        [(index[a], index[b]) for a, b in pairs],
        out_dir=args.out,
        jobs=args.jobs,
        backend=args.backend,
        cache=False if args.no_cache else (args.cache or True),
        init=args.init,
        k_max=args.k_max,
        multiscale=args.multiscale,
        spectral=not args.no_spectral,
        shared_faces=not args.no_shared_faces,
        progress=not args.quiet,
        ray_options={"address": args.ray_address} if args.backend == "ray" else None,
    ):
        counts["skipped" if r.skipped else ("matched" if r.ok else "failed")] += 1
        if not r.ok:
            failures.append(f"{r.a} -> {r.b}: {r.error}")
    seconds = time.perf_counter() - t0
    for line in failures:
        print(f"hope-rs: pair failed: {line}", file=sys.stderr)
    rate = 60 * counts["matched"] / seconds if seconds > 0 else 0.0
    print(
        f"{len(pairs)} pairs: {counts['matched']} matched, {counts['skipped']} skipped, "
        f"{counts['failed']} failed in {seconds:.1f} s ({rate:.1f} pairs/min) -> {args.out}"
    )
    return 1 if counts["failed"] else 0
