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
import dataclasses
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
    p.add_argument("--rings", type=int, default=None, help="ConfidenceConfig.rings to fit for")
    args = p.parse_args(argv)
    cache = default_cache()
    base = MatchConfig()
    if args.rings is not None:
        base = dataclasses.replace(
            base, confidence=dataclasses.replace(base.confidence, rings=args.rings)
        )
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
            x = features_of(pair, m, base)[0][m["a_idx"]]
            y = m["errors"] <= WRONG_ABOVE
            xs.append(x)
            ys.append(y)
            groups.append(vname)
            print(f"{vname} {pair.name}: wrong {1 - y.mean():.3f}", file=sys.stderr)
    x, y = np.concatenate(xs), np.concatenate(ys)
    mu, sd = x.mean(axis=0), x.std(axis=0)
    sd[sd == 0] = 1.0
    # Each variant weighs as much as the default matches in total.
    n_of = {g: sum(len(yy) for yy, gg in zip(ys, groups) if gg == g) for g in set(groups)}
    weight = np.concatenate([np.full(len(yy), 1.0 / n_of[g]) for yy, g in zip(ys, groups)])
    weight *= weight.size / weight.sum()
    model = LogisticRegression(C=args.C, max_iter=1000)
    model.fit((x - mu) / sd, y, sample_weight=weight)
    w = model.coef_[0] / sd
    b = float(model.intercept_[0] - (model.coef_[0] * mu / sd).sum())
    score = x @ w + b
    print(f"training AUROC {auroc(score, y):.3f} over {y.size} vertices, wrong {1 - y.mean():.3f}")
    for g in dict.fromkeys(groups):
        sel = np.concatenate([np.full(len(yy), gg == g) for yy, gg in zip(ys, groups)])
        prob = 1 / (1 + np.exp(-score[sel]))
        print(
            f"  {g}: AUROC {auroc(score[sel], y[sel]):.3f}, right {y[sel].mean():.3f}, "
            f"mean confidence {prob.mean():.3f}"
        )
    for name, wi in zip(CONFIDENCE_FEATURES, w):
        print(f"  {name:28s} {wi:+.4f}")
    print("weights: tuple[float, ...] = (" + ", ".join(f"{v:.4g}" for v in w) + ")")
    print(f"intercept: float = {b:.4g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
