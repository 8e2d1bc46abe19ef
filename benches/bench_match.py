"""End-to-end accuracy and time of ``hope_rs.match`` on the shared benchmark meshes.

Edge-graph geodesics keep this quick; ``hope-rs bench`` is the full comparison (surface
geodesics, ZoomOut, ablations, plots). For every pair it prints the initial map's and HOPE's figures side by side (fraction exactly right,
mean geodesic error divided by sqrt(area) of the target, AUC of the 0..0.25 curve) and the time of
each stage. Default parameters throughout: one parameter set for every data set.

    python benches/bench_match.py                       # faust_reg, tosca, faust_r, tosca_r
    python benches/bench_match.py --sets faust_r --max-pairs 3 --out results.md
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import hope_rs
from hope_rs.datasets import Pair, pairs_of

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def run_pair(pair: Pair) -> dict:
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    t0 = time.perf_counter()
    res = hope_rs.match(a, b)
    seconds = time.perf_counter() - t0
    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices, max_points=None)
    init = hope_rs.score(hope_rs.geodesic_errors(b, res.init_map, a_idx=ai, b_idx=bi))
    final = hope_rs.score(hope_rs.geodesic_errors(b, res.map, a_idx=ai, b_idx=bi))
    return {
        "pair": pair.name,
        "n": f"{a.n_vertices}/{b.n_vertices}",
        "init": init,
        "hope": final,
        "seconds": seconds,
        "steps": len(res.history),
        "timings": res.timings,
    }


def table(rows: list[dict]) -> str:
    head = (
        "| set | pair | n | init exact | init mean | HOPE exact | HOPE mean | HOPE AUC | steps "
        "| descr (s) | init (s) | refine (s) | total (s) |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in rows:
        t = r["timings"]
        lines.append(
            f"| {r['set']} | {r['pair']} | {r['n']} | {100 * r['init'].exact:.1f}% "
            f"| {r['init'].mean:.4f} | {100 * r['hope'].exact:.1f}% | {r['hope'].mean:.4f} "
            f"| {r['hope'].auc:.3f} | {r['steps']} | {t.get('descriptors', 0):.2f} "
            f"| {t.get('init', 0):.2f} | {t['refine']:.2f} | {r['seconds']:.2f} |"
        )
    return head + "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", type=Path, default=Path(os.environ.get("HOPE_DATA", DEFAULT_DATA)))
    p.add_argument("--sets", default="faust_reg,tosca,faust_r,tosca_r")
    p.add_argument("--max-pairs", type=int, default=None, help="at most this many pairs per set")
    p.add_argument("--out", type=Path, help="also write the Markdown table here")
    args = p.parse_args()
    print(f"load average: {os.getloadavg()}")
    rows = []
    for name in args.sets.split(","):
        for pair in pairs_of(args.data / name)[: args.max_pairs]:
            r = run_pair(pair)
            r["set"] = name
            rows.append(r)
            print(f"{name} {r['pair']}: init [{r['init']}] HOPE [{r['hope']}] {r['seconds']:.1f}s")
    md = table(rows)
    print(md)
    if args.out:
        args.out.write_text(md)


if __name__ == "__main__":
    main()
