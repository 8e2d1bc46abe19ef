"""Batch throughput: every pair of the 10 FAUST remeshes (45 pairs), or one template against
many shapes (``--template N``), cold and warm cache.

A *cold* run starts from an empty per-shape cache (each mesh is parsed and its SHOT descriptors
computed once, then shared by its 9 pairs); a *warm* run finds them on disk. Both pay the full
refinement of every pair, so the cache speed-up is bounded by the share of per-shape work. The
per-shape costs (parse, neighbourhoods, SHOT; and the cache's load) are measured separately.

    python benches/bench_batch.py                       # 45 pairs cold, then warm
    python benches/bench_batch.py --compare-jobs 6      # also 1 vs 2 processes on 6 pairs
    python benches/bench_batch.py --template 20         # tr_reg_000 against 20 shapes

One-to-many (``--template N``): the set's first shape against N others, its other shapes and,
to reach N, copies of them with their vertices relabelled (a fixed permutation per copy, so
each copy is a new shape to the cache and its ground truth is known).
"""

from __future__ import annotations

import argparse
import itertools
import os
import tempfile
import time
from pathlib import Path

import numpy as np

import hope_rs
from hope_rs.batch.cache import ShapeCache, cached_shape

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def per_shape_costs(paths: list[Path]) -> dict:
    """Mean seconds per shape: parse, k-hop graph, SHOT; then the same from a warm cache."""
    t = {"parse": 0.0, "graph": 0.0, "shot": 0.0, "cached load": 0.0}
    with tempfile.TemporaryDirectory() as d:
        cache = ShapeCache(d)
        for p in paths:
            t0 = time.perf_counter()
            m = hope_rs.load_mesh(p)
            t1 = time.perf_counter()
            s = hope_rs.Shape(m)
            t2 = time.perf_counter()
            s.descriptors("shot")
            t3 = time.perf_counter()
            t["parse"] += t1 - t0
            t["graph"] += t2 - t1
            t["shot"] += t3 - t2
            cached_shape(p, cache=cache)  # fill
        for p in paths:
            t0 = time.perf_counter()
            cached_shape(p, cache=cache)  # mesh + SHOT from disk, graph rebuilt
            t["cached load"] += time.perf_counter() - t0
    return {k: v / len(paths) for k, v in t.items()}


def run(shapes, pairs, *, cache, jobs, out) -> tuple[float, list]:
    t0 = time.perf_counter()
    res = hope_rs.match_many(shapes, pairs, out_dir=out, cache=cache, jobs=jobs, progress=True)
    return time.perf_counter() - t0, res


def relabelled_copies(shapes: list[Path], n: int, folder: Path) -> tuple[list[Path], dict]:
    """``n`` shapes: ``shapes`` and, to reach ``n``, copies with relabelled vertices written to
    ``folder``; returns them and, per copy, (original path, permutation: copy vertex i is
    original vertex perm[i])."""
    out, origin = [], {}
    for c in range(n):
        src = shapes[c % len(shapes)]
        if c < len(shapes):
            out.append(src)
            continue
        m = hope_rs.load_mesh(src)
        perm = np.random.default_rng(c).permutation(m.n_vertices)
        rank = np.argsort(perm)
        path = folder / f"{src.stem}_copy{c}.off"
        lines = [f"OFF\n{m.n_vertices} {len(m.faces)} 0\n"]
        lines += [f"{x!r} {y!r} {z!r}\n" for x, y, z in m.vertices[perm].tolist()]
        lines += [f"3 {i} {j} {k}\n" for i, j, k in rank[m.faces].tolist()]
        path.write_text("".join(lines))
        out.append(path)
        origin[path] = (src, perm)
    return out, origin


def accuracy(shapes: list[Path], pairs, results, origin=None) -> tuple[float, float]:
    """Mean over pairs of the fraction exact and mean geodesic error on the .vts landmarks."""
    origin = origin or {}
    exact, mean = [], []
    for (i, j), r in zip(pairs, results):
        a, b = shapes[i], shapes[j]
        b_src, perm = origin.get(b, (b, None))
        vts = a.parent / "corres"
        b_idx = hope_rs.load_vts(vts / f"{b_src.stem}.vts")
        if perm is not None:  # the copy's vertex for each ground-truth vertex of the original
            b_idx = np.argsort(perm)[b_idx]
        e = hope_rs.geodesic_errors(
            hope_rs.load_mesh(b), r.map,
            a_idx=hope_rs.load_vts(vts / f"{a.stem}.vts"),
            b_idx=b_idx,
        )  # fmt: skip
        s = hope_rs.score(e)
        exact.append(s.exact)
        mean.append(s.mean)
    return float(np.mean(exact)), float(np.mean(mean))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", type=Path, default=Path(os.environ.get("HOPE_DATA", DEFAULT_DATA)))
    p.add_argument("--set", default="faust_r")
    p.add_argument("--jobs", type=int, default=None, help="worker processes (default: package's)")
    p.add_argument("--max-pairs", type=int, default=None)
    p.add_argument("--compare-jobs", type=int, default=0, metavar="N",
                   help="also time 1 vs 2 processes on the first N pairs (warm cache)")  # fmt: skip
    p.add_argument("--ray-check", type=int, default=0, metavar="N",
                   help="also run the first N pairs on a local Ray instance and compare the maps")  # fmt: skip
    p.add_argument("--skip-full", action="store_true", help="only the per-shape and jobs parts")
    p.add_argument("--template", type=int, default=0, metavar="N",
                   help="one-to-many: the first shape against N others")  # fmt: skip
    args = p.parse_args()
    shapes = sorted((args.data / args.set).glob("*.off"))
    copies = tempfile.TemporaryDirectory(prefix="hope_rs-bench-")
    origin = {}
    if args.template:
        originals = shapes
        others, origin = relabelled_copies(shapes[1:], args.template, Path(copies.name))
        shapes = [shapes[0], *others]
        pairs = [(0, j) for j in range(1, len(shapes))]
    else:
        originals = shapes
        pairs = list(itertools.combinations(range(len(shapes)), 2))[: args.max_pairs]
    print(f"load average: {os.getloadavg()}; {len(shapes)} shapes, {len(pairs)} pairs", flush=True)

    costs = per_shape_costs(originals)
    print("\n| per shape (mean s) | " + " | ".join(costs) + " |")
    print("|---" * (len(costs) + 1) + "|")
    print("| " + args.set + " | " + " | ".join(f"{v:.3f}" for v in costs.values()) + " |\n")

    rows = []
    with tempfile.TemporaryDirectory() as d:
        cache = Path(d) / "cache"
        if not args.skip_full:
            for label in ("cold", "warm"):
                secs, res = run(shapes, pairs, cache=cache, jobs=args.jobs, out=Path(d) / label)
                ok = [r for r in res if r.ok]
                assert len(ok) == len(pairs), [r.error for r in res if not r.ok]
                ex, me = accuracy(shapes, pairs, res, origin)
                rows.append((label, secs, 60 * len(pairs) / secs, ex, me))
                print(f"{label}: {secs:.1f} s, {60 * len(pairs) / secs:.2f} pairs/min", flush=True)
        if args.compare_jobs:
            sub = pairs[: args.compare_jobs]
            hope_rs.match_many(shapes, sub[:1], cache=cache, jobs=1)  # warm this subset's shapes
            for jobs in (1, 2):
                secs, _ = run(shapes, sub, cache=cache, jobs=jobs, out=Path(d) / f"jobs{jobs}")
                rows.append((f"warm, {len(sub)} pairs, jobs={jobs}", secs, 60 * len(sub) / secs,
                             float("nan"), float("nan")))  # fmt: skip
                print(f"jobs={jobs}: {secs:.1f} s", flush=True)
        if args.ray_check:
            import ray

            sub = pairs[: args.ray_check]
            secs, local = run(shapes, sub, cache=cache, jobs=args.jobs, out=None)
            ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
            try:
                t0 = time.perf_counter()
                remote = hope_rs.match_many(shapes, sub, cache=cache, backend="ray")
                rsecs = time.perf_counter() - t0
            finally:
                ray.shutdown()
            same = sum(np.array_equal(a.map, b.map) for a, b in zip(local, remote))
            print(f"\nRay vs local, {len(sub)} pairs: {same}/{len(sub)} maps identical "
                  f"(local {secs:.1f} s, Ray {rsecs:.1f} s incl. start-up)")  # fmt: skip
    print("\n| run | seconds | pairs/min | mean exact (vts) | mean error (vts) |")
    print("|---|---|---|---|---|")
    for label, secs, rate, ex, me in rows:
        print(f"| {label} | {secs:.1f} | {rate:.2f} | {100 * ex:.1f}% | {me:.4f} |")
    if len(rows) >= 2 and rows[0][0] == "cold":
        print(f"\ncache speed-up (cold time / warm time): {rows[0][1] / rows[1][1]:.3f}x")


if __name__ == "__main__":
    main()
