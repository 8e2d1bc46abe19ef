"""How close many landmarks bring ``hope_rs.match`` to a set's ground truth, scored on the
ground-truth pairs that are not landmarks.

For each pair, the ground-truth correspondences (one per vertex of A, each vertex of B once)
are split alternately: every other one is a candidate landmark, the rest are scored. The pair
is matched with every Nth candidate as landmarks for each N of ``--strides`` (all of them,
every 4th and every 16th by default), and the mean geodesic error on the held-out half is
printed (edge-graph geodesics / sqrt(area)).
It bounds what four landmarks can do on the set: a map that does not reach a given error
from hundreds of exact landmarks will not reach it from four.

The last column does without the matcher: each held-out vertex of A is placed on B from the
candidate landmarks (at most ``TRILATERATION_LANDMARKS`` of them, evenly spread) by
trilateration: its ``NEIGHBOURS`` nearest landmarks on A, their distances to it scaled by the
ratio of B's to A's distances among them, and the vertex of B whose distances to their
partners fit those best. It says how well the ground truth itself follows from its
neighbours at that density (``--strides ''`` prints this column alone).

    python scripts/landmark_ceiling.py                                  # tosca_nonisometric_r
    python scripts/landmark_ceiling.py --set faust_r --max-pairs 2

Needs ../shared/data (or HOPE_DATA).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import dijkstra

import hope_rs
from hope_rs.evaluation.datasets import pairs_of
from hope_rs.evaluation.evaluate import geodesic_errors
from hope_rs.evaluation.partial import edge_graph

DEFAULT_DATA = Path(
    os.environ.get("HOPE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
STRIDES = (1, 4, 16)
#: Landmarks each held-out vertex is trilaterated from; the offset (sqrt(area) units) keeps
#: the nearest landmarks' relative misfit from dominating the fit; at most this many
#: candidates (evenly spread), about the non-isometric set's count, so that sets of denser
#: ground truth are compared at about the same density.
NEIGHBOURS, FIT_OFFSET, TRILATERATION_LANDMARKS = 10, 0.02, 450


def one_to_one(ai: np.ndarray, bi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ground-truth rows with each vertex of A and of B once (the first of repeats)."""
    _, first = np.unique(ai, return_index=True)
    ai, bi = ai[np.sort(first)], bi[np.sort(first)]
    _, first = np.unique(bi, return_index=True)
    return ai[np.sort(first)], bi[np.sort(first)]


def trilaterate(ma, mb, la: np.ndarray, lb: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """For each vertex ``queries[i]`` of A, the vertex of B placed by trilateration from the
    landmarks ``(la[j], lb[j])`` (see the module notes; edge-graph distances)."""
    da = dijkstra(edge_graph(ma), indices=la) / ma.scale  # (landmarks, vertices of A)
    db = dijkstra(edge_graph(mb), indices=lb) / mb.scale
    out = np.empty(queries.size, dtype=np.int64)
    upper = np.triu_indices(NEIGHBOURS, 1)
    for i, q in enumerate(queries):
        near = np.argsort(da[:, q])[:NEIGHBOURS]
        ratio = db[np.ix_(near, lb[near])][upper] / np.maximum(
            da[np.ix_(near, la[near])][upper], 1e-12
        )
        want = np.median(ratio) * da[near, q]
        out[i] = np.argmin(
            (((db[near] - want[:, None]) / (want[:, None] + FIT_OFFSET)) ** 2).sum(0)
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--set", default="tosca_nonisometric_r")
    ap.add_argument("--max-pairs", type=int, default=None)
    ap.add_argument(
        "--strides",
        default=",".join(map(str, STRIDES)),
        help="match with every Nth candidate as landmarks, for each N (comma-separated; "
        "empty: the trilateration only)",
    )
    args = ap.parse_args()
    try:
        strides = [int(x) for x in args.strides.split(",") if x.strip()]
    except ValueError:
        strides = [0]
    if any(s < 1 for s in strides):
        ap.error(f"--strides takes comma-separated integers >= 1, got {args.strides!r}")
    try:
        pairs = pairs_of(args.data / args.set)[: args.max_pairs]
    except ValueError as e:
        ap.error(str(e))  # one line, before any matching
    print(
        "| pair | "
        + "".join(f"1/{s} of the candidates pinned | " for s in strides)
        + "trilateration from the candidates |"
    )
    print("|---|" + "---|" * (len(strides) + 1))
    means = []
    for p in pairs:
        ma, mb = hope_rs.load_mesh(p.a), hope_rs.load_mesh(p.b)
        sa, sb = hope_rs.Shape(ma), hope_rs.Shape(mb)
        ai, bi = one_to_one(*p.ground_truth(ma.n_vertices, mb.n_vertices, max_points=None))
        pinned = np.arange(ai.size) % 2 == 0
        row = []
        for stride in strides:
            lm = np.flatnonzero(pinned)[::stride]
            res = hope_rs.match(sa, sb, landmarks=np.stack([ai[lm], bi[lm]], axis=1))
            err = geodesic_errors(sb, res.map, a_idx=ai[~pinned], b_idx=bi[~pinned]).mean()
            row.append((lm.size, float(err)))
        held, cand = ~pinned, np.flatnonzero(pinned)
        spread = np.linspace(0, cand.size - 1, TRILATERATION_LANDMARKS).round().astype(np.int64)
        cand = cand[np.unique(spread)]
        f = np.zeros(ma.n_vertices, dtype=np.int64)
        f[ai[held]] = trilaterate(ma, mb, ai[cand], bi[cand], ai[held])
        err = geodesic_errors(sb, f, a_idx=ai[held], b_idx=bi[held]).mean()
        row.append((cand.size, float(err)))
        means.append([e for _, e in row])
        print(f"| {p.name} | " + " | ".join(f"{e:.4f} ({n})" for n, e in row) + " |", flush=True)
    print("| mean | " + " | ".join(f"{m:.4f}" for m in np.mean(means, axis=0)) + " |")


if __name__ == "__main__":
    main()
