"""Fit the coefficients of ``ConfidenceConfig`` (``weights``, ``intercept``) on training pairs.

Training pairs: ordered pairs of remeshed FAUST shapes that are not benchmark pairs (neither
direction is in ``faust_r/pairs.txt``), so that every held-out pair of
``scripts/confidence_table.py`` stays unseen. Each is matched with the default settings and,
for examples of failing maps, some with weakened ones (one refinement pass, no spectral pass;
HKS initial maps), cached as in ``confidence_table.py``. A logistic regression (L2, standardised
features) of "right" (geodesic error <= 0.05) on the features of
:data:`~hope_rs.pipeline.config.CONFIDENCE_FEATURES` is printed as the config's defaults.

    python scripts/confidence_fit.py [--pairs 12]
"""

from __future__ import annotations

import argparse
import itertools
import sys

import numpy as np
from confidence_table import DATA, WRONG_ABOVE, auroc, default_cache, features_of, matched
from sklearn.linear_model import LogisticRegression

from hope_rs import MatchConfig
from hope_rs.evaluation.datasets import Pair, pairs_of
from hope_rs.pipeline.config import CONFIDENCE_FEATURES


def training_pairs(n: int) -> list[Pair]:
    folder = DATA / "faust_r"
    held = {(p.a.stem, p.b.stem) for p in pairs_of(folder)}
    held |= {(b, a) for a, b in held}
    names = sorted(p.stem for p in folder.glob("*.off"))
    cand = [(a, b) for a, b in itertools.permutations(names, 2) if (a, b) not in held]
    pick = np.linspace(0, len(cand) - 1, n).round().astype(int)
    return [
        Pair(
            "faust_r",
            folder / f"{a}.off",
            folder / f"{b}.off",
            folder / "corres" / f"{a}.vts",
            folder / "corres" / f"{b}.vts",
        )
        for a, b in (cand[i] for i in pick)
    ]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", type=int, default=12, help="training pairs per variant")
    p.add_argument("--C", type=float, default=1.0, help="inverse L2 strength")
    args = p.parse_args(argv)
    cache = default_cache()
    base = MatchConfig()
    variants = [
        ("default", base, "shot"),
        ("short", base.with_options(max_passes=1, spectral=False), "shot"),
        ("hks", base.with_options(max_passes=1, spectral=False), "hks"),
    ]
    xs, ys, groups = [], [], []
    pairs = training_pairs(args.pairs)
    for vname, cfg, init in variants:
        for pair in pairs if vname == "default" else pairs[::2]:
            m = matched(pair, cfg, init, cache)
            x = features_of(pair, m, base)[m["a_idx"]]
            y = m["errors"] <= WRONG_ABOVE
            xs.append(x)
            ys.append(y)
            groups.append(vname)
            print(f"{vname} {pair.name}: wrong {1 - y.mean():.3f}", file=sys.stderr)
    x, y = np.concatenate(xs), np.concatenate(ys)
    mu, sd = x.mean(axis=0), x.std(axis=0)
    sd[sd == 0] = 1.0
    model = LogisticRegression(C=args.C, max_iter=1000).fit((x - mu) / sd, y)
    w = model.coef_[0] / sd
    b = float(model.intercept_[0] - (model.coef_[0] * mu / sd).sum())
    score = x @ w + b
    print(f"training AUROC {auroc(score, y):.3f} over {y.size} vertices, wrong {1 - y.mean():.3f}")
    for g in dict.fromkeys(groups):
        sel = np.concatenate([np.full(len(yy), gg == g) for yy, gg in zip(ys, groups)])
        print(f"  {g}: AUROC {auroc(score[sel], y[sel]):.3f}")
    for name, wi in zip(CONFIDENCE_FEATURES, w):
        print(f"  {name:28s} {wi:+.4f}")
    print("weights: tuple[float, ...] = (" + ", ".join(f"{v:.4g}" for v in w) + ")")
    print(f"intercept: float = {b:.4g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
