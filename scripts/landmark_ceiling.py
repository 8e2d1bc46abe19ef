"""How close many landmarks bring ``hope_rs.match`` to a set's ground truth, scored on the
ground-truth pairs that are not landmarks.

For each pair, the ground-truth correspondences (one per vertex of A, each vertex of B once)
are split alternately: every other one is a candidate landmark, the rest are scored. The pair
is matched with all candidates, then with every 4th and every 16th of them, as landmarks, and
the mean geodesic error on the held-out half is printed (edge-graph geodesics / sqrt(area)).
It bounds what four landmarks can do on the set: a map that does not reach a given error
from hundreds of exact landmarks will not reach it from four.

    python scripts/landmark_ceiling.py                                  # tosca_nonisometric_r
    python scripts/landmark_ceiling.py --set faust_r --max-pairs 2

Needs ../shared/data (or HOPE_DATA).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

import hope_rs
from hope_rs.evaluation.datasets import pairs_of
from hope_rs.evaluation.evaluate import geodesic_errors

DEFAULT_DATA = Path(
    os.environ.get("HOPE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
STRIDES = (1, 4, 16)


def one_to_one(ai: np.ndarray, bi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ground-truth rows with each vertex of A and of B once (the first of repeats)."""
    _, first = np.unique(ai, return_index=True)
    ai, bi = ai[np.sort(first)], bi[np.sort(first)]
    _, first = np.unique(bi, return_index=True)
    return ai[np.sort(first)], bi[np.sort(first)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--set", default="tosca_nonisometric_r")
    ap.add_argument("--max-pairs", type=int, default=None)
    args = ap.parse_args()
    try:
        pairs = pairs_of(args.data / args.set)[: args.max_pairs]
    except ValueError as e:
        ap.error(str(e))  # one line, before any matching
    print("| pair | " + " | ".join(f"1/{s} of the candidates pinned" for s in STRIDES) + " |")
    print("|---|" + "---|" * len(STRIDES))
    means = []
    for p in pairs:
        ma, mb = hope_rs.load_mesh(p.a), hope_rs.load_mesh(p.b)
        sa, sb = hope_rs.Shape(ma), hope_rs.Shape(mb)
        ai, bi = one_to_one(*p.ground_truth(ma.n_vertices, mb.n_vertices, max_points=None))
        pinned = np.arange(ai.size) % 2 == 0
        row = []
        for stride in STRIDES:
            lm = np.flatnonzero(pinned)[::stride]
            res = hope_rs.match(sa, sb, landmarks=np.stack([ai[lm], bi[lm]], axis=1))
            err = geodesic_errors(sb, res.map, a_idx=ai[~pinned], b_idx=bi[~pinned]).mean()
            row.append((lm.size, float(err)))
        means.append([e for _, e in row])
        print(f"| {p.name} | " + " | ".join(f"{e:.4f} ({n})" for n, e in row) + " |", flush=True)
    print("| mean | " + " | ".join(f"{m:.4f}" for m in np.mean(means, axis=0)) + " |")


if __name__ == "__main__":
    main()
