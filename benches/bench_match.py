"""End-to-end accuracy and time of ``hope_rs.match`` on the shared benchmark meshes.

Edge-graph geodesics keep this quick; ``hope-rs bench`` is the full comparison (surface
geodesics, ZoomOut, ablations, plots). For every pair it prints the figures of the initial map,
of HOPE's map and of the final map after the spectral pass side by side (fraction exactly
right, mean geodesic error divided by sqrt(area) of the target, AUC of the 0..0.25 curve) and
the time of each stage. Default parameters throughout: one parameter set for every data set.

    python benches/bench_match.py                       # faust_reg, tosca, faust_r, tosca_r
    python benches/bench_match.py --sets faust_r --max-pairs 3 --out results.md
    python benches/bench_match.py --sets tosca --renumber 1   # both meshes renumbered at random

``--renumber SEED`` matches each pair with the vertices of both meshes put in a random order and
scores the map after undoing it. faust_reg and TOSCA pairs come numbered alike (their ground
truth is the identity), so a result that holds only as numbered has used that alignment; an
earlier version of the refinement did (see "A correction" in the README). Shapes now number
their vertices by position (``hope_rs.geometry.numbering``), so the maps, and every figure but the
times, come out the same with or without it.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

import hope_rs
from hope_rs.evaluation.datasets import Pair, pairs_of

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def renumbered(mesh: hope_rs.Mesh, rng: np.random.Generator):
    """The mesh with its vertices in a random order, and the order (new i = old order[i])."""
    order = rng.permutation(mesh.n_vertices)
    new_index = np.empty_like(order)
    new_index[order] = np.arange(order.size)
    return hope_rs.Mesh(mesh.vertices[order], new_index[mesh.faces]), order


def run_pair(pair: Pair, renumber: int | None = None, spectral: bool = True) -> dict:
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    a_in, b_in = a, b
    if renumber is not None:
        rng = np.random.default_rng(renumber)
        (a_in, order_a), (b_in, order_b) = renumbered(a, rng), renumbered(b, rng)
    t0 = time.perf_counter()
    res = hope_rs.match(a_in, b_in, spectral=spectral)
    seconds = time.perf_counter() - t0
    hope = res.map if res.hope_map is None else res.hope_map
    maps = res.init_map, hope, res.map
    if renumber is not None:  # back to the files' numbering (vertex order_a[i] of A, etc.)
        maps = tuple(np.empty_like(m) for m in maps)
        for out, m in zip(maps, (res.init_map, hope, res.map)):
            out[order_a] = order_b[m]
    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices, max_points=None)
    init, hope, final = (
        hope_rs.score(hope_rs.geodesic_errors(b, m, a_idx=ai, b_idx=bi)) for m in maps
    )
    return {
        "pair": pair.name,
        "n": f"{a.n_vertices}/{b.n_vertices}",
        "init": init,
        "hope": hope,
        "final": final,
        "seconds": seconds,
        "steps": len(res.history),
        "timings": res.timings,
    }


def table(rows: list[dict]) -> str:
    head = (
        "| set | pair | n | init exact / mean | HOPE exact / mean | final exact | final mean "
        "| final AUC | steps | descr (s) | init (s) | refine (s) | spectral (s) | faces (s) "
        "| total (s) |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in rows:
        t = r["timings"]
        lines.append(
            f"| {r['set']} | {r['pair']} | {r['n']} "
            f"| {100 * r['init'].exact:.1f}% / {r['init'].mean:.4f} "
            f"| {100 * r['hope'].exact:.1f}% / {r['hope'].mean:.4f} "
            f"| {100 * r['final'].exact:.1f}% | {r['final'].mean:.4f} | {r['final'].auc:.3f} "
            f"| {r['steps']} | {t.get('descriptors', 0):.2f} | {t.get('init', 0):.2f} "
            f"| {t['refine']:.2f} | {t.get('spectral', 0):.2f} | {t.get('faces', 0):.2f} "
            f"| {r['seconds']:.2f} |"
        )
    return head + "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", type=Path, default=Path(os.environ.get("HOPE_DATA", DEFAULT_DATA)))
    p.add_argument("--sets", default="faust_reg,tosca,faust_r,tosca_r")
    p.add_argument("--max-pairs", type=int, default=None, help="at most this many pairs per set")
    p.add_argument("--out", type=Path, help="also write the Markdown table here")
    p.add_argument(
        "--renumber", type=int, metavar="SEED", help="renumber both meshes at random (seeded)"
    )
    p.add_argument(
        "--no-spectral", action="store_true", help="match(..., spectral=False): HOPE's map only"
    )
    args = p.parse_args()
    print(f"load average: {os.getloadavg()}")
    rows = []
    for name in args.sets.split(","):
        for pair in pairs_of(args.data / name)[: args.max_pairs]:
            r = run_pair(pair, args.renumber, not args.no_spectral)
            r["set"] = name
            rows.append(r)
            print(
                f"{name} {r['pair']}: init [{r['init']}] HOPE [{r['hope']}] "
                f"final [{r['final']}] {r['seconds']:.1f}s"
            )
    md = table(rows)
    print(md)
    if args.out:
        args.out.write_text(md)


if __name__ == "__main__":
    main()
