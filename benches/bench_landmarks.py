"""What a few user landmarks do to ``hope_rs.match`` on the remeshed benchmark sets.

For every pair of each set, four well-spread landmarks are taken from the ground truth:
farthest-point samples on A (edge-graph geodesics) among the vertices with a ground-truth
match, the first sample (the one nearest the centroid) left out so that the four sit on the
extremities, each mapped to B through the ground truth. Each pair is matched without and with
them, and a table per set prints the mean geodesic error (sqrt(area) units; edge-graph
geodesics, or surface ones with ``--geodesics surface`` as ``hope-rs bench`` uses), the worst
pair's mean error, and how many pairs have a swapped region (more than ``--swap-share`` of the
scored vertices farther than ``--swap-error`` from their match).

    python benches/bench_landmarks.py                        # faust_r, tosca_r, tosca_nonisometric_r
    python benches/bench_landmarks.py --sets faust_r --max-pairs 3
    python benches/bench_landmarks.py --rows rows.jsonl      # also keep (and reuse) per-pair rows

With ``--rows``, pairs already in the file are not matched again (a run can be resumed).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

import hope_rs
from hope_rs.evaluation.datasets import Pair, pairs_of
from hope_rs.evaluation.evaluate import geodesic_errors
from hope_rs.pipeline.anchors import farthest_witnesses

DEFAULT_DATA = Path(os.environ.get("HOPE_DATA", "/work/shared/data"))
REMESHED = ("faust_r", "tosca_r", "tosca_nonisometric_r")


def ground_truth_landmarks(sa: hope_rs.Shape, ai: np.ndarray, bi: np.ndarray, n: int = 4):
    """(n, 2) landmarks (input numbering): farthest-point samples of A among the ground-truth
    vertices, the centroid-nearest start left out, with their ground-truth matches on B."""
    first = {}
    for x, y in zip(ai.tolist(), bi.tolist()):
        first.setdefault(x, y)
    cand_in = np.array(sorted(first))
    chosen, _ = farthest_witnesses(sa, np.sort(sa.rank[cand_in]), n + 1)
    a_in = sa.order[chosen[1:]]
    return np.stack([a_in, [first[int(x)] for x in a_in]], axis=1).astype(np.int64)


def run_pair(
    pair: Pair,
    n_landmarks: int,
    swap_error: float,
    without: dict | None = None,
    geodesics: str = "graph",
) -> dict:
    ma, mb = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    sa, sb = hope_rs.Shape(ma), hope_rs.Shape(mb)
    ai, bi = pair.ground_truth(ma.n_vertices, mb.n_vertices, max_points=None)
    lm = ground_truth_landmarks(sa, ai, bi, n_landmarks)
    row = {"set": pair.dataset, "pair": pair.name, "landmarks": lm.tolist()}
    runs = (("without", None), ("with", lm))
    if without is not None:  # today's map does not change with the landmark code
        row["without"] = without
        runs = runs[1:]
    for name, given in runs:
        t0 = time.perf_counter()
        res = hope_rs.match(sa, sb, landmarks=given)
        seconds = time.perf_counter() - t0
        err = geodesic_errors(sb, res.map, a_idx=ai, b_idx=bi, method=geodesics)
        row[name] = {
            "mean": float(err.mean()),
            "far": float((err > swap_error).mean()),
            "seconds": seconds,
            "pinned": bool(given is None or (res.map[lm[:, 0]] == lm[:, 1]).all()),
        }
    return row


def table(rows: list[dict], swap_share: float) -> str:
    out = [
        "| set | pairs | landmarks | mean error | worst pair mean | pairs with a swapped region |",
        "|---|---|---|---|---|---|",
    ]
    for s in dict.fromkeys(r["set"] for r in rows):
        mine = [r for r in rows if r["set"] == s]
        for name in ("without", "with"):
            means = np.array([r[name]["mean"] for r in mine])
            swapped = sum(r[name]["far"] > swap_share for r in mine)
            out.append(
                f"| {s} | {len(mine)} | {name} | {means.mean():.4f} | {means.max():.4f} | "
                f"{swapped} |"
            )
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=DEFAULT_DATA)
    p.add_argument("--sets", nargs="+", default=list(REMESHED))
    p.add_argument("--max-pairs", type=int, default=None, help="first pairs of each set only")
    p.add_argument("--landmarks", type=int, default=4, help="landmarks per pair (default 4)")
    p.add_argument("--swap-error", type=float, default=0.3, help="sqrt(area) units")
    p.add_argument("--swap-share", type=float, default=0.05)
    p.add_argument("--geodesics", choices=("graph", "surface"), default="graph")
    p.add_argument("--rows", type=Path, default=None, help="JSON lines of per-pair results")
    p.add_argument(
        "--reuse-without", type=Path, default=None,
        help="a --rows file of an earlier run: its maps without landmarks are not recomputed",
    )  # fmt: skip
    args = p.parse_args(argv)
    rows = []
    if args.rows is not None and args.rows.exists():
        rows = [json.loads(line) for line in args.rows.read_text().splitlines() if line]
    done = {(r["set"], r["pair"]) for r in rows}
    earlier = {}
    if args.reuse_without is not None:
        for line in args.reuse_without.read_text().splitlines():
            r = json.loads(line)
            earlier[(r["set"], r["pair"])] = r["without"]
    for s in args.sets:
        for pair in pairs_of(args.data / s)[: args.max_pairs]:
            if (pair.dataset, pair.name) in done:
                continue
            key = (pair.dataset, pair.name)
            row = run_pair(pair, args.landmarks, args.swap_error, earlier.get(key), args.geodesics)
            rows.append(row)
            w, o = row["with"], row["without"]
            print(
                f"{s} {pair.name}: without {o['mean']:.4f} ({100 * o['far']:.1f}% far), "
                f"with {w['mean']:.4f} ({100 * w['far']:.1f}% far), pinned {w['pinned']}",
                flush=True,
            )
            if args.rows is not None:
                with open(args.rows, "a") as fh:
                    fh.write(json.dumps(row) + "\n")
    wanted = [r for r in rows if r["set"] in args.sets]
    print(table(wanted, args.swap_share))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
