"""Write docs/confidence.md: how well ``MatchResult.confidence`` separates right from wrong
matches on the held-out remeshed pairs (the ``pairs.txt`` pairs of faust_r, tosca_r and
tosca_nonisometric_r).

Each pair is matched once with the default settings; its maps (final, HOPE's, ZoomOut's) and
per-vertex geodesic errors (edge-graph geodesics / sqrt(area), ``hope_rs.geodesic_errors``)
are cached under ``--cache`` (default: a folder in the system's temp directory), keyed by
every setting, so a rerun takes seconds (other confidence coefficients match again: the
confidence's rule decides whether the orient stage runs, and a part's scale trial is chosen
by its confidence). A whole pair's confidence is computed from the cached maps by the same
functions the pipeline's confidence stage runs. A match is "right" when its error is at most
0.05.

    python scripts/confidence_table.py                 # match (or reuse), write docs/confidence.md
    python scripts/confidence_table.py --max-pairs 4   # at most 4 pairs per set (faster)
    python scripts/confidence_table.py --extra-sets DIR  # + the sets `hope-rs perturb-set` or
                                                         # `partial-set` wrote (repeatable)
    python scripts/confidence_table.py --derived       # + the benchmark's perturbed, reversed
                                                         # and partial sets, written by its rules

A shortcuts set is scored on the clean B, a welded vertex counting as either of its two
(:func:`hope_rs.evaluation.perturbed.shortcut_errors`).

Needs ../shared/data (or HOPE_DATA). ``scripts/confidence_fit.py`` fits the coefficients on
training pairs with the same helpers.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from benchmarks import (
    DATA,
    PARTIAL_PAIRS,
    PARTIAL_SOURCES,
    PERTURBED,
    PERTURBED_SOURCES,
    REVERSED_SOURCES,
    ROOT,
    partial_conditions,
    partial_sets,
    perturbed_sets,
    reversed_sets,
    write_derived,
)

import hope_rs
from hope_rs import MatchConfig, Shape
from hope_rs.evaluation.datasets import Pair, pairs_of
from hope_rs.evaluation.evaluate import confidence_auroc
from hope_rs.evaluation.perturbed import shortcut_errors
from hope_rs.pipeline.confidence import (
    MatchQuality,
    confidence_features,
    flipped_share,
    judged_shapes,
    match_quality,
    vertex_confidence,
)
from hope_rs.pipeline.denoise import denoised
from hope_rs.pipeline.runner import run_match

HELD_OUT = ["faust_r", "tosca_r", "tosca_nonisometric_r"]
#: A match is right when its geodesic error (sqrt(area) units) is at most this.
WRONG_ABOVE = 0.05
#: A pair should be flagged ``likely_failed`` when more than FLAG_FAR of its vertices lie
#: farther than FAR_ABOVE from their true match, and not when fewer than FLAG_NEAR do.
FAR_ABOVE, FLAG_FAR, FLAG_NEAR = 0.15, 0.20, 0.05
LEVELS = (0.1, 0.3, 0.5, 0.7, 0.9)


def default_cache() -> Path:
    return Path(tempfile.gettempdir()) / "hope_rs_confidence_cache"


def errors_of(pair: Pair, mb, mapping, a_idx, b_idx) -> np.ndarray:
    """Edge-graph geodesic errors of ``mapping``; on a welded B (a shortcuts set) measured on
    the clean B, a weld counting as either of its two vertices."""
    e = shortcut_errors(pair.b.parent, pair.b.stem, mapping, a_idx, b_idx, method="graph")
    if e is None:
        e = hope_rs.geodesic_errors(mb, mapping, a_idx=a_idx, b_idx=b_idx)
    return e


def matched(pair: Pair, config: MatchConfig, init: str, cache: Path) -> dict:
    """The pair's cached maps (input numbering) and scored errors: keys ``map``, ``hope``,
    ``zoomout`` (all -1 without one), ``judged`` (the map when the confidence stage runs,
    before the deformation pass), ``a_idx``, ``errors``, ``seconds``; for a part and its
    whole also ``confidence`` and ``quality`` (the match's own ``MatchResult.confidence`` and
    its mean confidence, confident share, likely-failed flag and turned-over share, see
    :func:`part_pair`). The cache is keyed by every setting: the confidence's change maps too
    (its rule triggers the orient stage; a part's scale trial is chosen by its confidence)."""
    path = cache / config.key()[:16] / init / pair.dataset / f"{pair.name}.npz"
    if path.exists():
        with np.load(path) as z:
            return {**z, "cached": True}
    ma, mb = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    a = Shape(ma, k_max=config.k_max, config=config.shape)
    b = Shape(mb, k_max=config.k_max, config=config.shape)
    seen = {}

    def grab(state, name):
        if name == "spectral" and state.zoomout is not None:
            seen["zoomout"] = a.map_out(b, state.zoomout)
        if name == "confidence" and state.f is not None:
            seen["judged"] = a.map_out(b, state.f)

    t = time.perf_counter()
    # A part's confidence is the match's own, not recomputed from the cached maps.
    res = run_match(a, b, init, config, on_stage=grab)
    seconds = time.perf_counter() - t
    a_idx, b_idx = pair.ground_truth(ma.n_vertices, mb.n_vertices)
    part = {}
    # The "partial" stage is recorded only when one shape is a part of the other.
    partial = any(s.name == "partial" and s.ran for s in res.stages)
    if partial and res.confidence is not None and res.quality is not None:
        q = res.quality
        part = {
            "confidence": res.confidence,
            "quality": np.array(
                [q.mean_confidence, q.share_confident, float(q.likely_failed), q.flipped_share]
            ),
        }
    out = {
        "map": res.map,
        "hope": res.hope_map,
        "zoomout": seen.get("zoomout", np.full(ma.n_vertices, -1, dtype=np.int64)),
        "judged": seen.get("judged", res.map),
        "a_idx": np.asarray(a_idx, dtype=np.int64),
        "errors": errors_of(pair, mb, res.map, a_idx, b_idx),
        "seconds": np.float64(seconds),
        **part,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **out)
    os.replace(tmp, path)
    return {**out, "cached": False}


def derived_sets(folder: Path) -> list[Path]:
    """The derived sets ``scripts/benchmarks.py`` scores, written by the same rules into
    ``folder`` (each command's output once; kept for the next run): the perturbed targets and
    the reversed pairs (``hope-rs perturb-set``) and the partial sets (``hope-rs partial-set``,
    the first PARTIAL_PAIRS pairs, only the whole -> part sets the benchmark has). The set
    folders, in table order. Each command's folder is named by a hash of its arguments, so
    other sources, conditions or pair counts write new sets; the maps' cache knows a pair by
    its set's and its own names, so after a change to a set's rule (its code) remove the
    whole cache folder, not only these sets."""
    jobs = [
        ("perturb-set", PERTURBED_SOURCES, ",".join(PERTURBED), None),
        ("perturb-set", REVERSED_SOURCES, "reversed", None),
        ("partial-set", PARTIAL_SOURCES, partial_conditions(), PARTIAL_PAIRS),
    ]
    wanted = set(perturbed_sets() + reversed_sets() + partial_sets())
    out = []
    for i, (command, sources, conditions, max_pairs) in enumerate(jobs):
        args = repr((command, tuple(sources), conditions, max_pairs)).encode()
        done = folder / f"{i}-{command}-{hashlib.sha256(args).hexdigest()[:12]}"
        if not done.is_dir():
            # Written beside, then renamed: an interrupted run leaves no half-written set.
            tmp = folder / f".{done.name}.tmp"
            if tmp.exists():
                shutil.rmtree(tmp)
            write_derived(command, tmp, sources, conditions, max_pairs, stdout=subprocess.DEVNULL)
            os.replace(tmp, done)
        out += sorted(d for d in done.iterdir() if d.name in wanted and (d / "pairs.txt").is_file())
    missing = wanted - {d.name for d in out}
    if missing:
        raise RuntimeError(f"the derived sets {', '.join(sorted(missing))} were not written")
    return out


def _internal(pair: Pair, m: dict, config: MatchConfig):
    """``(a, b, f, features, flipped)`` of the cached maps, in the shapes' internal numbering:
    ``f`` the map the confidence stage judges, ``flipped`` the final map's turned-over share
    (as :func:`~hope_rs.pipeline.confidence.state_quality` reads them)."""
    a = Shape(hope_rs.load_mesh(pair.a), k_max=config.k_max, config=config.shape)
    b = Shape(hope_rs.load_mesh(pair.b), k_max=config.k_max, config=config.shape)
    # The shapes the match ran on: a noisy one replaced by its smoothed copy (same numbering).
    a, b = denoised(a, b, config)
    z = None if (m["zoomout"] < 0).any() else a.map_in(b, m["zoomout"])
    f = a.map_in(b, m.get("judged", m["map"]))
    flipped = flipped_share(a, b, a.map_in(b, m["map"]))
    # As the stage measures them: a noisy scan much denser than the other shape smoothed.
    a, b = judged_shapes(a, b, config.confidence)
    x = confidence_features(
        a,
        b,
        f,
        a.map_in(b, m["hope"]),
        z,
        config.confidence,
        min_consistent=config.refine.min_consistent,
        repair=config.refine.repair,
    )
    return a, b, f, x, flipped


def features_of(pair: Pair, m: dict, config: MatchConfig) -> tuple[np.ndarray, float]:
    """:func:`confidence_features` of the cached maps, rows in A's input numbering, and the
    final map's :func:`flipped_share` (the model's inputs, for ``scripts/confidence_fit.py``)."""
    a, _, _, x, flipped = _internal(pair, m, config)
    return x[a.rank], flipped


def confidence_of(pair: Pair, m: dict, config: MatchConfig) -> tuple[np.ndarray, float]:
    """The confidence stage's :func:`vertex_confidence` of the cached maps, in A's input
    numbering, and the final map's :func:`flipped_share`."""
    a, b, f, x, flipped = _internal(pair, m, config)
    return vertex_confidence(a, b, f, x, config.confidence)[a.rank], flipped


def auroc(score: np.ndarray, right: np.ndarray) -> float:
    """:func:`hope_rs.evaluation.evaluate.confidence_auroc` of ``score`` for right/wrong labels."""
    return confidence_auroc(score, np.where(right, 0.0, 1.0), wrong_above=0.5)


def part_pair(m: dict) -> bool:
    """Whether the cached match is of a part and its whole (its partial stage ran). Its
    confidence is the match's own: the confidence stage's on the map the partial stage
    kept, with the part measured at the whole's scale, and 0 where a whole's vertex has no
    counterpart on the part, which the features of the maps at the shapes' own scales would
    not reproduce."""
    return "confidence" in m


def scored(pair: Pair, m: dict, config: MatchConfig) -> tuple[np.ndarray, np.ndarray, MatchQuality]:
    """(confidence at the scored vertices, right or not, the pair's :class:`MatchQuality`)."""
    if part_pair(m):
        mean, share, failed, flipped = (float(x) for x in m["quality"])
        quality = MatchQuality(mean, share, bool(failed), flipped)
        return m["confidence"][m["a_idx"]], m["errors"] <= WRONG_ABOVE, quality
    c, flipped = confidence_of(pair, m, config)
    quality = match_quality(c, config.confidence, flipped=flipped)
    return c[m["a_idx"]], m["errors"] <= WRONG_ABOVE, quality


def pairs(folders: list[Path], max_pairs: int | None) -> dict[str, list[Pair]]:
    """The pairs of each set folder, by the folder's name (unique: the maps' cache knows a
    pair by its set's name)."""
    out = {}
    for folder in folders:
        name = folder.name
        if name in out:
            raise ValueError(f"two sets named {name}: give each --extra-sets folder other names")
        ps = pairs_of(folder)
        if max_pairs is not None and len(ps) > max_pairs:
            # Evenly spaced, always the same ones.
            ps = [ps[i] for i in np.linspace(0, len(ps) - 1, max_pairs).round().astype(int)]
        out[name] = ps
    return out


def _git(*args: str) -> str:
    try:
        return subprocess.run(
            ["git", *args], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def render(
    command: str,
    rows: dict,
    per_pair: list,
    sampled: bool,
    seconds: float,
    matched_now: int,
    match_s: float,
    extra: list[str],
) -> str:
    config = MatchConfig()
    lines = [
        "# Per-vertex confidence: calibration on held-out pairs",
        "",
        f"Generated by `{command}`; do not edit by hand.",
        "",
        (
            f"- commit `{_git('rev-parse', '--short', 'HEAD')}`, "
            f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC"
        ),
        f"- machine: {platform.machine()}, {os.cpu_count()} cores, {platform.platform()}",
        f"- data: the `pairs.txt` pairs of {', '.join(HELD_OUT)} "
        + ("(sampled: `--max-pairs`)" if sampled else "(all of them)")
        + "; none of them is a training pair of `scripts/confidence_fit.py`"
        + (f"; and the sets {', '.join(extra)}{derived_note(extra)}" if extra else ""),
        (
            f"- a match is right when its geodesic error is at most {WRONG_ABOVE} sqrt(area) "
            "(edge-graph geodesics, at the vertices with ground truth)"
        ),
        (
            f"- default settings; the table took {seconds:.0f} s, {matched_now} of "
            f"{len(per_pair)} pairs matched in this run, the others' maps from the cache; the "
            f"matches took {match_s:.0f} s in all when they ran"
        ),
        "",
        "`MatchResult.confidence[i]` estimates the probability that `map[i]` is right. For each",
        "level c: of the vertices with confidence >= c, the share that is right (precision), and",
        "their share of all scored vertices (coverage). AUROC: how well the confidence ranks",
        "right above wrong matches (1 = perfectly, 0.5 = not at all), all vertices of the set's",
        "pairs pooled; `n/a` when the set has no wrong match.",
        "",
    ]
    head = "| set | pairs | wrong | AUROC | " + " | ".join(f"c={c}" for c in LEVELS) + " |"
    lines += [head, "|" + "---|" * (4 + len(LEVELS))]
    for name, (conf, right, n_pairs) in rows.items():
        cells = []
        for c in LEVELS:
            keep = conf >= c
            prec = f"{right[keep].mean():.3f}" if keep.any() else "-"
            cells.append(f"{prec} / {keep.mean():.2f}")
        a = auroc(conf, right)
        lines.append(
            f"| {name} | {n_pairs} | {1 - right.mean():.3f} | "
            + ("n/a" if np.isnan(a) else f"{a:.3f}")
            + " | "
            + " | ".join(cells)
            + " |"
        )
    lines += [
        "",
        "Cells: precision / coverage.",
        "",
        "## How the confidence is computed",
        "",
        "The confidence stage (`hope_rs.pipeline.confidence`) reads the final map, HOPE's map",
        "and ZoomOut's and computes per vertex of A: LMD's consistent share of the 2-ring and",
        "its mean distortion; the share of 32 farthest-point anchors (among LMD-consistent",
        "vertices) whose geodesic distance the map keeps, and the mean bend of those distances;",
        "how far on B HOPE's and ZoomOut's images lie from the final one; the B/A ratio of edge",
        "lengths under the map; and the pair's mean consistent share. The regional features are",
        f"averaged over {config.confidence.rings} rings, so that regions, not single vertices,",
        "lose confidence. A logistic regression of 'right' on these features",
        "(`ConfidenceConfig.weights`, `.intercept`) was fitted by `scripts/confidence_fit.py` on",
        "remeshed FAUST pairs outside `pairs.txt`: default matches, and one-pass matches from",
        "SHOT and HKS initial maps (for examples of failing maps), each kind weighed equally.",
        "A part's confidence is the match's own: the confidence stage on the map the partial",
        "stage kept, the part measured at the whole's scale; 0 on a whole's vertices without a",
        "counterpart on the part.",
        "",
        "## Per pair",
        "",
        (
            f"`quality.likely_failed`: mean confidence < {config.confidence.failed_mean}, "
            f"fewer than {config.confidence.failed_share:.0%} of the vertices at confidence >= "
            f"{config.confidence.threshold}, or more than {config.confidence.failed_flipped:.0%} "
            "of A's area turned over by the map (`quality.flipped_share`)."
        ),
        "",
        flag_check(per_pair),
        "",
        (
            f"| set | pair | mean error | wrong | far (> {FAR_ABOVE}) | mean confidence "
            "| area turned over | likely failed | AUROC |"
        ),
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, pair, err, conf, right, q in per_pair:
        a = auroc(conf, right)
        lines.append(
            f"| {name} | {pair} | {err.mean():.3f} | {1 - right.mean():.3f} | "
            f"{np.mean(err > FAR_ABOVE):.3f} | "
            f"{q.mean_confidence:.3f} | {q.flipped_share:.3f} | "
            f"{'yes' if q.likely_failed else 'no'} | "
            + ("n/a" if np.isnan(a) else f"{a:.3f}")
            + " |"
        )
    return "\n".join(lines) + "\n"


#: What a derived set's name says about it, for the sets of ``perturb-set`` and
#: ``partial-set``: a pattern its name matches, and the words.
DERIVED_NAMES = {
    r"_noise\d+$": "`_noise02`, `_noise05`: B with vertex noise of 0.2% or 0.5% of sqrt(area)",
    r"_shortcuts$": (
        "`_shortcuts`: B welded by topological shortcuts, scored on the clean B, a weld "
        "counting as either of its two"
    ),
    r"_reversed$": "`_reversed`: the pairs matched the other way",
    r"_cut\d+": "`_cut30`, `_cut50`: A cut by a plane removing 30% or 50% of its vertices",
    r"_holes": "`_holes`: 3-5 geodesic discs punched out of A",
    r"_rev$": (
        "`_rev` after a cut: the whole A matched to the cut B, scored where A has a "
        "counterpart; a part's confidence is the match's own"
    ),
}


def derived_note(extra: list[str]) -> str:
    """What the derived sets ``extra`` (set names) are, from the patterns of their names."""
    said = [text for key, text in DERIVED_NAMES.items() if any(re.search(key, n) for n in extra)]
    built = "built by `hope-rs perturb-set` and `hope-rs partial-set` from the sets above"
    return f" ({built}; " + "; ".join(said) + ")" if said else ""


def flag_check(per_pair: list) -> str:
    """One line: how many pairs with more than FLAG_FAR of their vertices beyond FAR_ABOVE
    are flagged, and how many with fewer than FLAG_NEAR are flagged anyway."""
    far = [float(np.mean(err > FAR_ABOVE)) for _, _, err, *_ in per_pair]
    flagged = [q.likely_failed for *_, q in per_pair]
    bad = [f for x, f in zip(far, flagged) if x > FLAG_FAR]
    good = [f for x, f in zip(far, flagged) if x < FLAG_NEAR]
    return (
        f"Pairs with more than {FLAG_FAR:.0%} of their vertices farther than {FAR_ABOVE} from "
        f"the true match: {len(bad)}, of them flagged {sum(bad)}. Pairs with fewer than "
        f"{FLAG_NEAR:.0%}: {len(good)}, of them flagged {sum(good)}."
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cache", type=Path, default=default_cache())
    p.add_argument("--max-pairs", type=int, default=None, help="pairs per set at most")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "confidence.md")
    p.add_argument(
        "--extra-sets",
        type=Path,
        action="append",
        default=[],
        help="a folder of derived sets (each a folder with a pairs.txt, as `hope-rs perturb-set` "
        "and `hope-rs partial-set` write them) to score beside the held-out ones; repeatable",
    )
    p.add_argument(
        "--derived",
        action="store_true",
        help="also score the benchmark's perturbed, reversed and partial sets, written by its "
        "rules under the cache folder (docs/confidence.md is made this way)",
    )
    args = p.parse_args(argv)
    if not DATA.is_dir():
        print(f"no data folder {DATA}; set HOPE_DATA", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    config = MatchConfig()
    rows, per_pair, matched_now, match_s = {}, [], 0, 0.0
    folders = [DATA / name for name in HELD_OUT]
    extra = [
        d for top in args.extra_sets for d in sorted(top.iterdir()) if (d / "pairs.txt").is_file()
    ]
    if args.derived:
        args.cache.mkdir(parents=True, exist_ok=True)
        extra += derived_sets(args.cache / "derived-sets")
    folders += extra
    for name, ps in pairs(folders, args.max_pairs).items():
        confs, rights = [], []
        for pair in ps:
            m = matched(pair, config, config.initial.descriptor, args.cache)
            matched_now += not m["cached"]
            match_s += float(m["seconds"])
            conf, right, quality = scored(pair, m, config)
            confs.append(conf)
            rights.append(right)
            per_pair.append((name, pair.name, m["errors"], conf, right, quality))
            print(f"{name} {pair.name}: mean error {m['errors'].mean():.3f}", file=sys.stderr)
        rows[name] = (np.concatenate(confs), np.concatenate(rights), len(ps))
    seconds = time.perf_counter() - t0
    command = "python scripts/confidence_table.py" + "".join(
        [
            f" --max-pairs {args.max_pairs}" if args.max_pairs is not None else "",
            " --derived" if args.derived else "",
            *(f" --extra-sets {d}" for d in args.extra_sets),
        ]
    )
    text = render(
        command,
        rows,
        per_pair,
        args.max_pairs is not None,
        seconds,
        matched_now,
        match_s,
        [d.name for d in extra],
    )
    args.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
