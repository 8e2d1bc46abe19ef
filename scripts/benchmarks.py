"""Regenerate docs/benchmarks.md and the README's results table from one run of the current code.

Runs ``hope-rs bench`` (surface geodesic errors over every pair of every shared data set, HOPE
and ZoomOut from the same SHOT initial map, wall time from meshes to map), the same on the
partial-shape sets, and ``benches/bench_landmarks.py`` (each remeshed pair without and with
four landmarks), then writes
``docs/benchmarks.md`` with the commit, date and machine, and replaces the table between the
``results:start`` / ``results:end`` markers of README.md. Each section's tables and provenance
are kept in docs/results, so a ``--*-only`` run on any clone renders the other sections from
their last run.

    python scripts/benchmarks.py                 # run, then write both documents
    python scripts/benchmarks.py --render-only   # rewrite them from docs/results
    python scripts/benchmarks.py --partial-only  # the partial-shape sets only, then rewrite
    python scripts/benchmarks.py --landmarks-only  # the landmark bench only, then rewrite
    python scripts/benchmarks.py --resolution-only  # the mixed-resolution sets only, then rewrite
    python scripts/benchmarks.py --perturbed-only  # the noise and shortcut sets only, then rewrite
    python scripts/benchmarks.py --reversed-only  # the reversed pairs only, then rewrite
    python scripts/benchmarks.py --partial-resolution-only  # parts at another resolution only, then rewrite

Needs the eval extra (pyFM, potpourri3d) and ../shared/data (or HOPE_DATA).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
from provenance import header, load

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("HOPE_DATA", ROOT.parent / "shared" / "data"))
RUN = ROOT / "bench-results" / "benchmarks"
#: The tables and provenance of the last run of each section, kept in the repository so that
#: one section can be run again on any clone and the document rendered with the others.
RESULTS = ROOT / "docs" / "results"
KEPT = ("*.csv", "*.jsonl", "provenance*.txt")
METHODS = ["init", "hope", "zoomout"]
#: Data sets in the order of the tables, with a line on what each exercises.
SETS = {
    "faust_reg": "FAUST registrations, same triangulation, 6.9k vertices",
    "tosca": "TOSCA cat, two poses, 28k vertices, 94% shared edges",
    "faust_r": "FAUST remeshed independently, ~5k vertices",
    "tosca_r": "TOSCA remeshed independently, ~5k vertices",
    "tosca_nonisometric_r": "man / woman / gorilla remeshed, non-isometric",
}
#: Partial-shape sets written by ``hope-rs partial-set`` from faust_r and tosca_r (the first
#: PARTIAL_PAIRS pairs of each), in the order of their table.
PARTIAL = {
    "cut30": "A cut by a plane removing 30% of its vertices, matched to the whole B",
    "cut50": "A cut by a plane removing 50% of its vertices",
    "holes": "3-5 geodesic discs punched out of A",
    "cut30_rev": "the whole A matched to B cut by a plane removing 30% (scored where A has a counterpart)",
    "cut_both": "A and B each cut by a plane removing 30%, with opposite normals (two parts that overlap only partly; scored where both keep the point)",
}
PARTIAL_SOURCES = ("faust_r", "tosca_r")
PARTIAL_PAIRS = 9
PARTIAL_METHODS = ["init", "hope"]
#: Mixed-resolution sets written by ``hope-rs resolution-set`` (the first RESOLUTION_PAIRS
#: pairs of each source), in the order of their table; "_rev" is the same pairs reversed.
RESOLUTION = {
    "sub1": "B subdivided once (about 4x its vertices)",
    "sub2": "B subdivided twice (about 16x its vertices)",
    "dec1k": "A clustered to about 1,000 vertices",
}
RESOLUTION_SOURCES = ("faust_r", "faust_reg")
RESOLUTION_PAIRS = 3
RESOLUTION_METHODS = ["hope", "hope-fullres"]
#: Parts at another resolution: ``hope-rs partial-set`` (PARTIAL_RESOLUTION_CONDITION, no
#: whole -> part sets) of the RESOLUTION_PAIRS pairs of these mixed-resolution sets of
#: faust_r (a part of A against a denser B, and a part of a denser A against B).
PARTIAL_RESOLUTION = ("sub1", "sub1_rev", "sub2", "sub2_rev")
PARTIAL_RESOLUTION_CONDITION = "cut30"
#: Perturbed-target sets written by ``hope-rs perturb-set`` from every pair of the sources,
#: in the order of their table (a shortcuts set scored on the clean B by ``hope-rs bench``).
PERTURBED = {
    "noise02": "B with Gaussian vertex noise of 0.2% of sqrt(area)",
    "noise05": "B with Gaussian vertex noise of 0.5% of sqrt(area)",
    "shortcuts": "B with 3-10 topological shortcuts (welds), scored on the clean B, a welded "
    "vertex counting as either of its two",
}
PERTURBED_SOURCES = ("faust_r", "tosca_r", "tosca_nonisometric_r")
#: Sets whose pairs are also matched the other way (``perturb-set --conditions reversed``):
#: pairs of the same shapes that no setting was chosen on.
REVERSED_SOURCES = ("tosca_nonisometric_r",)
#: "hope-noorient" times the orient stage's cost: each pair again without it, in the same run.
PERTURBED_METHODS = ["init", "hope", "hope-noorient"]
#: The landmark bench: its sets, landmarks per pair, and the swap rule (share of the scored
#: vertices farther than SWAP_ERROR from their match, sqrt(area) units).
LANDMARK_SETS = ("faust_r", "tosca_r", "tosca_nonisometric_r")
LANDMARKS, SWAP_ERROR, SWAP_SHARE = 4, 0.3, 0.05
MARK_START, MARK_END = "<!-- results:start -->", "<!-- results:end -->"


def _kept(folder: Path) -> list[Path]:
    """The tables, landmark rows and provenance files in ``folder``."""
    return sorted(f for pattern in KEPT for f in folder.glob(pattern))


def _copy_results(src: Path, dst: Path) -> None:
    """``dst``'s tables, landmark rows and provenance replaced by exactly those of ``src``
    (one run at a time per clone: both folders are shared by every run)."""
    dst.mkdir(parents=True, exist_ok=True)
    _remove(_kept(dst))
    for f in _kept(src):
        shutil.copy2(f, dst / f.name)


def _remove(paths) -> None:
    for f in paths:
        if f.is_dir():
            shutil.rmtree(f)
        elif f.exists():
            f.unlink()


def bench(argv: list, names) -> None:
    """``hope-rs bench ARGV`` writing the tables of the sets ``names``. A failed pair (exit
    status 1 with every table written) is listed in its table and in the document; any other
    failure stops the run."""
    done = subprocess.run([sys.executable, "-m", "hope_rs.cli", "bench", *map(str, argv)])
    written = all((RUN / f"{n}.csv").is_file() for n in names)
    if done.returncode not in (0, 1) or not written:
        raise subprocess.CalledProcessError(done.returncode, done.args)


def run_shared() -> None:
    """Every shared set; the CSVs and provenance of every earlier run are removed first."""
    _remove(RUN.glob("*"))
    start = header()
    bench([DATA, "--methods", ",".join(METHODS), "--sets", ",".join(SETS), "--no-render",
           "--out", RUN], SETS)  # fmt: skip
    (RUN / "provenance.txt").write_text(start + f"{load()} at the end\n")


def write_derived(
    command: str, folder: Path, sources, conditions: str, max_pairs=None, **run_options
) -> None:
    """``hope-rs COMMAND FOLDER`` (``perturb-set``, ``partial-set``...) on the ``sources``
    sets of DATA with ``conditions``, their first ``max_pairs`` pairs (``None``: all);
    ``run_options`` go to ``subprocess.run``."""
    cmd = [sys.executable, "-m", "hope_rs.cli", command, str(folder), "--from",
           ",".join(str(DATA / s) for s in sources), "--conditions", conditions]  # fmt: skip
    if max_pairs is not None:
        cmd += ["--max-pairs", str(max_pairs)]
    subprocess.run(cmd, check=True, **run_options)


def run_derived(
    kind: str, command: str, sources, conditions: str, methods, names, max_pairs=None
) -> None:
    """Write the derived sets of ``hope-rs COMMAND`` afresh from ``sources`` into
    ``RUN/KIND-data`` (the CSVs of ``names`` and the folder of an earlier run removed first),
    run ``hope-rs bench`` with ``methods`` on them and record the provenance."""
    _remove([RUN / f"{n}.{ext}" for n in names for ext in ("csv", "md")])
    folder = RUN / f"{kind}-data"
    _remove([folder])
    start = header()
    write_derived(command, folder, sources, conditions, max_pairs)
    bench([folder, "--methods", ",".join(methods), "--sets", ",".join(names), "--no-render",
           "--out", RUN], names)  # fmt: skip
    (RUN / f"provenance_{kind}.txt").write_text(start + f"{load()} at the end\n")


def run_partial() -> None:
    """The partial-shape sets, written afresh from the source sets, with their provenance."""
    run_derived(
        "partial", "partial-set", PARTIAL_SOURCES, partial_conditions(), PARTIAL_METHODS,
        partial_sets(), PARTIAL_PAIRS,
    )  # fmt: skip


def partial_sets() -> list[str]:
    return [f"{s}_{c}" for s in PARTIAL_SOURCES for c in PARTIAL]


def partial_conditions() -> str:
    """``partial-set``'s conditions for PARTIAL (it writes each one's whole -> part set too)."""
    return ",".join(c for c in PARTIAL if not c.endswith("_rev"))


def perturbed_sets() -> list[str]:
    return [f"{s}_{c}" for c in PERTURBED for s in PERTURBED_SOURCES]


def run_perturbed() -> None:
    """The noise and shortcut sets, written afresh from the source sets, with their
    provenance."""
    run_derived(
        "perturbed",
        "perturb-set",
        PERTURBED_SOURCES,
        ",".join(PERTURBED),
        PERTURBED_METHODS,
        perturbed_sets(),
    )


def reversed_sets() -> list[str]:
    return [f"{s}_reversed" for s in REVERSED_SOURCES]


def run_reversed() -> None:
    """The pairs of REVERSED_SOURCES matched the other way, with their provenance."""
    run_derived(
        "reversed", "perturb-set", REVERSED_SOURCES, "reversed", PERTURBED_METHODS,
        reversed_sets(),
    )  # fmt: skip


def perturbed() -> str:
    """The perturbed-target section's table: a row per set (HOPE), with the flagged pairs."""
    head = (
        "| set | what | pairs | init mean error | HOPE mean error | HOPE worst pair's mean "
        "| HOPE confidence AUROC | HOPE pairs flagged likely failed (their mean errors) "
        "| HOPE median s / pair | without the orient stage: median s / pair "
        "| time with / without it per pair: median (max) |"
    )
    out = [head, "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in perturbed_sets() + reversed_sets():
        rows = _rows(name)
        h, i = _stats(rows, "hope"), _stats(rows, "init")
        if h is None:
            continue
        cond = name.split("_")[-1]
        what = PERTURBED.get(cond, "the pairs matched the other way (B as A, A as B)")
        auroc = f"{h['auroc']:.3f}" if h["auroc"] is not None else "–"
        im = f"{i['mean']:.4f}" if i else "–"
        flagged = f"{len(h['flagged'])}" + (
            f" ({', '.join(f'{e:.3f}' for e in sorted(h['flagged']))})" if h["flagged"] else ""
        )
        ratios = _time_ratios(rows, "hope", "hope-noorient")
        off = _stats(rows, "hope-noorient")
        cost = (
            f"{off['seconds']:.1f} | {np.median(ratios):.2f} ({ratios.max():.2f})"
            if off is not None and ratios.size
            else "– | –"
        )
        out.append(
            f"| {name} | {what} | {h['pairs']} | {im} | **{h['mean']:.4f}** | {h['worst']:.4f} "
            f"| {auroc} | {flagged} | {h['seconds']:.1f} | {cost} |"
        )
    return "\n".join(out) + "\n" if len(out) > 2 else ""


def _resolution_sets() -> list[str]:
    return [f"{s}_{c}{r}" for s in RESOLUTION_SOURCES for c in RESOLUTION for r in ("", "_rev")]


def run_resolution() -> None:
    """The mixed-resolution sets, written afresh from the source sets, with their provenance."""
    run_derived(
        "resolution",
        "resolution-set",
        RESOLUTION_SOURCES,
        ",".join(RESOLUTION),
        RESOLUTION_METHODS,
        _resolution_sets(),
        RESOLUTION_PAIRS,
    )


def _partial_resolution_sets() -> list[str]:
    return [f"faust_r_{c}_{PARTIAL_RESOLUTION_CONDITION}" for c in PARTIAL_RESOLUTION]


def run_partial_resolution() -> None:
    """Parts at another resolution: the mixed-resolution sets of faust_r written afresh, then
    cut by ``hope-rs partial-set``; HOPE on them, with the provenance."""
    names = _partial_resolution_sets()
    _remove([RUN / f"{n}.{ext}" for n in names for ext in ("csv", "md")])
    folder, parts = RUN / "partial-resolution-src", RUN / "partial-resolution-data"
    _remove([folder, parts])
    start = header()
    cli = [sys.executable, "-m", "hope_rs.cli"]
    conditions = ",".join(dict.fromkeys(c.removesuffix("_rev") for c in PARTIAL_RESOLUTION))
    subprocess.run(
        [*cli, "resolution-set", str(folder), "--from", str(DATA / "faust_r"), "--conditions",
         conditions, "--max-pairs", str(RESOLUTION_PAIRS)],
        check=True,
    )  # fmt: skip
    sources = ",".join(str(folder / f"faust_r_{c}") for c in PARTIAL_RESOLUTION)
    subprocess.run(
        [*cli, "partial-set", str(parts), "--from", sources, "--conditions",
         PARTIAL_RESOLUTION_CONDITION, "--max-pairs", str(RESOLUTION_PAIRS), "--no-reverse"],
        check=True,
    )  # fmt: skip
    bench(
        [parts, "--methods", "hope", "--sets", ",".join(names), "--no-render", "--out", RUN], names
    )
    _remove([folder])
    (RUN / "provenance_partial_resolution.txt").write_text(start + f"{load()} at the end\n")


def partial_resolution() -> str:
    """The parts-at-another-resolution section's table: every pair (HOPE), with its flag."""
    out = [
        "| set | pair | vertices A → B | HOPE mean error | HOPE exact % "
        "| HOPE confidence AUROC | flagged | HOPE s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    names = _partial_resolution_sets()
    for name in names:
        for r in _rows(name):
            if r["method"] != "hope" or r.get("failed"):
                continue
            auroc = r.get("confidence_auroc") or ""
            auroc = f"{float(auroc):.3f}" if auroc and np.isfinite(float(auroc)) else "–"
            flag = {"1": "yes", "0": "no"}.get(r.get("likely_failed", ""), "–")
            out.append(
                f"| {name} | {r['pair']} | {r['n_a']} → {r['n_b']} | {float(r['mean']):.4f} "
                f"| {100 * float(r['exact']):.1f} | {auroc} | {flag} | {float(r['seconds']):.1f} |"
            )
    if len(out) == 2:
        return _failures(names)
    return "\n".join(out) + "\n" + _failures(names)


def resolution() -> str:
    """The mixed-resolution section's table: a row per set, the default match against the
    same match at each shape's own resolution."""
    head = (
        "| set | what | pairs | HOPE mean error | HOPE exact % | HOPE worst pair's mean "
        "| pairs flagged likely failed | HOPE s / pair | own resolution: mean error | exact % "
        "| s / pair |"
    )
    out = [head, "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in _resolution_sets():
        rows = _rows(name)
        h, f = _stats(rows, "hope"), _stats(rows, "hope-fullres")
        if h is None:
            continue
        cond = name.split("_", 2)[-1]
        what = RESOLUTION[cond.removesuffix("_rev")] + (
            ", reversed" if cond.endswith("_rev") else ""
        )
        full = "| – | – | – " if f is None else (
            f"| {f['mean']:.4f} | {f['exact']:.1f} | {f['seconds']:.1f} "
        )  # fmt: skip
        out.append(
            f"| {name} | {what} | {h['pairs']} | **{h['mean']:.4f}** | {h['exact']:.1f} "
            f"| {h['worst']:.4f} | {len(h['flagged'])} | {h['seconds']:.1f} {full}|"
        )
    if len(out) == 2:
        return _failures(_resolution_sets())
    return "\n".join(out) + "\n" + _failures(_resolution_sets()) + _resolution_pairs()


def _resolution_pairs() -> str:
    """Every pair of the mixed-resolution sets: HOPE's mean error, seconds and flag, and the
    same at each shape's own resolution."""
    out = [
        "\nEvery pair (mean error ÷ sqrt(area) of B; *flagged*: `quality.likely_failed`):\n",
        "| set | pair | vertices A → B | HOPE mean error | HOPE s | flagged "
        "| own resolution: mean error | s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name in _resolution_sets():
        rows = [r for r in _rows(name) if not r.get("failed")]
        for pair in dict.fromkeys(r["pair"] for r in rows):
            by = {r["method"]: r for r in rows if r["pair"] == pair}
            h, f = by.get("hope"), by.get("hope-fullres")
            if h is None:
                continue
            own = (
                "| – | – "
                if f is None
                else f"| {float(f['mean']):.4f} | {float(f['seconds']):.1f} "
            )
            flag = {"1": "yes", "0": "no"}.get(h.get("likely_failed", ""), "–")
            out.append(
                f"| {name} | {pair} | {h['n_a']} → {h['n_b']} | {float(h['mean']):.4f} "
                f"| {float(h['seconds']):.1f} | {flag} {own}|"
            )
    return "\n".join(out) + "\n" if len(out) > 3 else ""


def run_landmarks() -> None:
    """``benches/bench_landmarks.py`` on the remeshed sets (surface geodesics), afresh."""
    rows = RUN / "landmarks.jsonl"
    _remove([rows])
    start = header()
    subprocess.run(
        [sys.executable, str(ROOT / "benches" / "bench_landmarks.py"), "--data", str(DATA),
         "--sets", *LANDMARK_SETS, "--landmarks", str(LANDMARKS), "--geodesics", "surface",
         "--swap-error", str(SWAP_ERROR), "--swap-share", str(SWAP_SHARE), "--rows", str(rows)],
        check=True,
    )  # fmt: skip
    (RUN / "provenance_landmarks.txt").write_text(start + f"{load()} at the end\n")


def _rows(name: str) -> list[dict]:
    path = RUN / f"{name}.csv"
    if not path.exists():
        return []
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _stats(rows: list[dict], method: str) -> dict | None:
    """Figures of ``method`` over the pairs it scored (a failed pair is left out: see
    :func:`_failures`); ``None`` when it scored none."""
    rs = [r for r in rows if r["method"] == method and not r.get("failed")]
    if not rs:
        return None

    def col(k):
        return np.array([float(r[k]) for r in rs])

    aurocs = [float(r.get("confidence_auroc") or "nan") for r in rs]
    aurocs = [x for x in aurocs if np.isfinite(x)]
    per_a = col("mean_a") if all(r.get("mean_a") for r in rs) else None
    return {
        "a_mean": None if per_a is None else per_a.mean(),
        "a_worst": None if per_a is None else per_a.max(),
        "pairs": len(rs), "exact": 100 * col("exact").mean(), "mean": col("mean").mean(),
        "worst": col("mean").max(), "auc": col("auc").mean(), "seconds": float(np.median(col("seconds"))),
        "auroc": float(np.mean(aurocs)) if aurocs else None,
        "flagged": [float(r["mean"]) for r in rs if r.get("likely_failed") == "1"],
        "judged": any(r.get("likely_failed") not in (None, "") for r in rs),
    }  # fmt: skip


def _time_ratios(rows: list[dict], method: str, other: str) -> np.ndarray:
    """Per pair that both methods matched, ``method``'s seconds over ``other``'s."""
    by = {(r["pair"], r["method"]): float(r["seconds"]) for r in rows if not r.get("failed")}
    return np.array(
        [t / by[(p, other)] for (p, m), t in by.items() if m == method and (p, other) in by]
    )


def _failures(names) -> str:
    """The (pair, method) rows of the sets ``names`` that failed, a line each with the reason."""
    bad = [(n, r) for n in names for r in _rows(n) if r.get("failed")]
    if not bad:
        return ""
    return "\nFailed, left out of the table:\n\n" + "".join(
        f"- {n} {r['pair']} {r['method']}: {r['failed']}\n" for n, r in bad
    )


def headline() -> str:
    lines = [
        (
            "| data set | pairs | HOPE mean error | HOPE exact % | ZoomOut mean error "
            "| ZoomOut exact % | HOPE s / pair | ZoomOut s / pair |"
        ),
        "|---|---|---|---|---|---|---|---|",
    ]
    for name in SETS:
        rows = _rows(name)
        h, z = _stats(rows, "hope"), _stats(rows, "zoomout")
        if h is None:
            continue
        zm = f"{z['mean']:.4f}" if z else "–"
        ze = f"{z['exact']:.1f}" if z else "–"
        zs = f"{z['seconds']:.1f}" if z else "–"
        lines.append(
            f"| {name} | {h['pairs']} | **{h['mean']:.4f}** | {h['exact']:.1f} | {zm} | {ze} "
            f"| {h['seconds']:.1f} | {zs} |"
        )
    return "\n".join(lines) + "\n"


def detailed() -> str:
    out = []
    for name, what in SETS.items():
        rows = _rows(name)
        if not rows:
            continue
        out.append(f"### {name}\n\n{what}.\n")
        out.append(_method_table(rows, METHODS))
    return "\n".join(out)


def _method_table(rows: list[dict], methods: list[str]) -> str:
    head = (
        "| method | pairs | mean error | worst pair's mean | exact % | AUC 0–0.25 "
        "| confidence AUROC | median s / pair |\n|---|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for m in methods:
        s = _stats(rows, m)
        if s:
            auroc = f"{s['auroc']:.3f}" if s["auroc"] is not None else "–"
            lines.append(
                f"| {m} | {s['pairs']} | {s['mean']:.4f} | {s['worst']:.4f} "
                f"| {s['exact']:.1f} | {s['auc']:.3f} | {auroc} | {s['seconds']:.1f} |"
            )
    return "\n".join(lines) + "\n"


def partial() -> str:
    """The partial-shape section: one table per condition, a row per source set (HOPE)."""
    out = []
    for cond, what in PARTIAL.items():
        # A whole -> part set is also given ÷ sqrt(area) of A, the whole: its part -> whole
        # counterpart's B, so both are measured in the same units.
        rev = cond.endswith("_rev")
        lines = [
            f"### {cond}\n\n{what}; the first {PARTIAL_PAIRS} pairs of each source set.\n",
            (
                "| source set | pairs | init mean error | HOPE mean error | HOPE worst pair's mean "
                + ("| HOPE mean / worst ÷ sqrt(area) of A " if rev else "")
                + "| HOPE confidence AUROC | HOPE pairs flagged likely failed (their mean errors) "
                "| HOPE median s / pair |"
            ),
            "|---|---|---|---|---|---|---|---|" + ("---|" if rev else ""),
        ]
        for src in PARTIAL_SOURCES:
            rows = _rows(f"{src}_{cond}")
            h, i = _stats(rows, "hope"), _stats(rows, "init")
            if h is None:
                continue
            auroc = f"{h['auroc']:.3f}" if h["auroc"] is not None else "–"
            im = f"{i['mean']:.4f}" if i else "–"
            flagged = f"{len(h['flagged'])}" + (
                f" ({', '.join(f'{e:.3f}' for e in sorted(h['flagged']))})" if h["flagged"] else ""
            )
            if not h["judged"]:  # results from before the bench recorded the flag
                flagged = "–"
            by_a = ""
            if rev:
                by_a = (
                    "| – " if h["a_mean"] is None else f"| {h['a_mean']:.4f} / {h['a_worst']:.4f} "
                )
            lines.append(
                f"| {src} | {h['pairs']} | {im} | **{h['mean']:.4f}** | {h['worst']:.4f} "
                f"{by_a}| {auroc} | {flagged} | {h['seconds']:.1f} |"
            )
        if len(lines) > 3:
            out.append("\n".join(lines) + "\n")
    return "\n".join(out)


def landmarks() -> str:
    """The landmark section's table: a row per set, without → with landmarks."""
    path = RUN / "landmarks.jsonl"
    if not path.exists():
        return ""
    rows = [json.loads(line) for line in path.read_text().splitlines() if line]
    head = (
        "| data set | pairs | mean error without → with | worst pair's mean without → with "
        "| pairs ≤ 0.03 with | pairs with a swapped region without → with "
        "| landmarks kept | median s / pair with |"
    )
    out = [head, "|---|---|---|---|---|---|---|---|"]
    for name in dict.fromkeys(r["set"] for r in rows):
        mine = [r for r in rows if r["set"] == name]

        def col(run: str, key: str, mine=mine) -> np.ndarray:
            return np.array([r[run][key] for r in mine], dtype=float)

        wo, wi = col("without", "mean"), col("with", "mean")
        swaps = [int((col(run, "far") > SWAP_SHARE).sum()) for run in ("without", "with")]
        kept = sum(bool(r["with"]["pinned"]) for r in mine)
        out.append(
            f"| {name} | {len(mine)} | {wo.mean():.4f} → **{wi.mean():.4f}** "
            f"| {wo.max():.4f} → {wi.max():.4f} | {int((wi <= 0.03).sum())} "
            f"| {swaps[0]} → {swaps[1]} | {kept} of {len(mine)} "
            f"| {np.median(col('with', 'seconds')):.1f} |"
        )
    return "\n".join(out) + "\n"


def _provenance(name: str) -> list[str]:
    path = RUN / name
    return path.read_text().strip().splitlines() if path.exists() else []


def render() -> None:
    prov = _provenance("provenance.txt")
    prov_partial = _provenance("provenance_partial.txt")
    prov_landmarks = _provenance("provenance_landmarks.txt")
    prov_resolution = _provenance("provenance_resolution.txt")
    prov_perturbed = _provenance("provenance_perturbed.txt") + [
        f"reversed pairs: {line}" for line in _provenance("provenance_reversed.txt")
    ]
    lm_table = landmarks()
    res_table = resolution()
    part_res_table = partial_resolution()
    prov_part_res = _provenance("provenance_partial_resolution.txt")
    pert_table = perturbed()
    doc = (
        "# Benchmarks\n\n"
        "Generated by `python scripts/benchmarks.py` from one run of the code; do not edit by "
        "hand.\n\n"
        + "".join(f"- {line}\n" for line in prov)
        + "\nEvery pair listed by each data set's `pairs.txt` (every pair of shapes for the "
        "identity sets) in `../shared/data`. Errors are surface geodesic distances between the "
        "matched and the true vertex, divided by sqrt(area) of the target, averaged over the "
        "ground-truth vertices of a pair and then over pairs; *exact* is the share of vertices "
        "matched to their true vertex. `init` is the SHOT initial map both refinements start "
        "from; `zoomout` is pyFM's ZoomOut (20 → 100 eigenfunctions) from that map; `hope` is "
        "`hope_rs.match` with default settings. Seconds are wall time from the two meshes in "
        "memory to the map, medians over pairs, on the machine above.\n\n"
        "## Summary\n\n"
        + headline()
        + "\n## Per data set\n\n"
        + detailed()
        + "\n## Partial shapes\n\n"
        + "".join(f"- {line}\n" for line in prov_partial)
        + ("\n" if prov_partial else "")
        + "Written by `hope-rs partial-set` from the pairs of the "
        "source sets (ground truth carried over); `init` is the SHOT map at each shape's own "
        "scale, `hope` is `hope_rs.match` (which measures a part at the whole's scale). Errors "
        "are divided by sqrt(area) of the target; for the whole → part set only the vertices "
        "of the whole with a counterpart on the part are scored, and its table also gives them "
        "divided by sqrt(area) of the whole A, the units its part → whole counterpart is "
        "scored in (a part's sqrt(area) is usually smaller than a whole's, so the same "
        "distances read larger in its units).\n\n"
        + partial()
        + "\nThe confidence AUROC ranks the vertices with error above 0.05 below the others "
        "(`MatchResult.confidence`; 1 is perfect, 0.5 is chance), per pair, averaged over "
        "pairs; docs/confidence.md gives it with every set's vertices pooled.\n"
        + (
            "\n## Perturbed targets\n\n"
            + "".join(f"- {line}\n" for line in prov_perturbed)
            + "\nWritten by `hope-rs perturb-set` from every pair of "
            f"{', '.join(PERTURBED_SOURCES)} (A unchanged, B perturbed, ground truth carried "
            "over; the noise is seeded by the pair's index), and of "
            f"{', '.join(REVERSED_SOURCES)} matched the other way (the reversed sets, whose "
            "pairs no setting was chosen on). A shortcut weld merges two "
            "vertices closer than 0.1 sqrt(area) in space but farther than 0.3 along the "
            "surface; only poses with at least 3 such welds are kept, and a map onto the "
            "welded B is scored on the clean B. Errors ÷ sqrt(area) of the (clean) B."
            + (
                " Each pair is matched again with the orient stage off (`hope-noorient`, "
                "right after `hope` in the same process, each from new shapes): the last "
                "column is the orient stage's cost, the time with it over the time without "
                "it, pair by pair."
                if any(
                    r["method"] == "hope-noorient"
                    for n in perturbed_sets() + reversed_sets()
                    for r in _rows(n)
                )
                else ""
            )
            + "\n\n"
            + pert_table
            if pert_table
            else ""
        )
        + (
            "\n## Landmarks\n\n"
            + "".join(f"- {line}\n" for line in prov_landmarks)
            + "\n`benches/bench_landmarks.py`: every pair of each remeshed set matched without "
            f"and with {LANDMARKS} landmarks (`match(a, b, landmarks=L)`), farthest-point "
            "samples among the ground-truth vertices of A (the one nearest the centroid left "
            "out) with their ground-truth matches on B. Surface geodesic errors ÷ sqrt(area) of "
            "B over the ground-truth vertices; a pair has a swapped region when more than "
            f"{SWAP_SHARE:.0%} of them lie farther than {SWAP_ERROR} from their match; "
            "*landmarks kept*: pairs whose map sends every landmark to its partner.\n\n" + lm_table
            if lm_table
            else ""
        )
        + (
            "\n## Mixed resolutions\n\n"
            + "".join(f"- {line}\n" for line in prov_resolution)
            + "\nWritten by `hope-rs resolution-set` from the first "
            f"{RESOLUTION_PAIRS} pairs of {', '.join(RESOLUTION_SOURCES)} (ground truth carried "
            "over: a subdivided mesh keeps its vertices first; a clustered one, whose every vertex "
            "is a vertex of A merged with its neighbours by manifold-keeping edge collapses, "
            "keeps the ground-truth lines whose point of A it keeps). `hope` is the default match "
            "(which matches a much denser shape at the other's resolution, "
            "`hope_rs.pipeline.resolution`); *own resolution* is the same with "
            "`MatchConfig.resolution.enabled=False`. Errors ÷ sqrt(area) of B over the "
            "ground-truth vertices (every original vertex for faust_reg).\n\n" + res_table
            if res_table
            else ""
        )
        + (
            "\n## Parts at another resolution\n\n"
            + "".join(f"- {line}\n" for line in prov_part_res)
            + f"\n`hope-rs partial-set --conditions {PARTIAL_RESOLUTION_CONDITION}` of the "
            f"mixed-resolution sets {', '.join(PARTIAL_RESOLUTION)} of faust_r (their "
            f"{RESOLUTION_PAIRS} pairs, written by `hope-rs resolution-set`): a part of a "
            "remeshed shape against a subdivided, denser whole, and a part of a subdivided shape "
            "against a remeshed whole. `hope` is the default match (the part measured at the "
            "whole's scale and matched at the common resolution). Errors ÷ sqrt(area) of B over "
            "the ground-truth vertices; *flagged*: `quality.likely_failed`.\n\n" + part_res_table
            if part_res_table
            else ""
        )
    )
    (ROOT / "docs" / "benchmarks.md").write_text(doc)
    readme = ROOT / "README.md"
    text = readme.read_text()
    if MARK_START in text and MARK_END in text:
        head, rest = text.split(MARK_START, 1)
        _, tail = rest.split(MARK_END, 1)
        commit = prov[0].split(" ", 1)[1] if prov else "unknown"
        table = (
            f"{MARK_START}\n{headline()}\n"
            f"Mean geodesic error (÷ sqrt(area)); generated by `scripts/benchmarks.py` at "
            f"{commit}; details per data set in `docs/benchmarks.md`.\n{MARK_END}"
        )
        readme.write_text(head + table + tail)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    only = p.add_mutually_exclusive_group()
    only.add_argument(
        "--render-only", action="store_true", help="rewrite the documents from docs/results"
    )
    only.add_argument(
        "--partial-only",
        action="store_true",
        help="run the partial-shape sets again, reuse the other results",
    )
    only.add_argument(
        "--resolution-only",
        action="store_true",
        help="run the mixed-resolution sets again, reuse the other results",
    )
    only.add_argument(
        "--perturbed-only",
        action="store_true",
        help="run the noise and shortcut sets again, reuse the other results",
    )
    only.add_argument(
        "--reversed-only",
        action="store_true",
        help="run the reversed pairs again, reuse the other results",
    )
    only.add_argument(
        "--partial-resolution-only",
        action="store_true",
        help="run the parts at another resolution again, reuse the other results",
    )
    only.add_argument(
        "--landmarks-only",
        action="store_true",
        help="run the landmark bench again, reuse the other results",
    )
    args = p.parse_args()
    RUN.mkdir(parents=True, exist_ok=True)
    only = (
        args.partial_only
        or args.landmarks_only
        or args.resolution_only
        or args.perturbed_only
        or args.reversed_only
        or args.partial_resolution_only
        or args.render_only
    )
    if only:
        if not (RESULTS / "provenance.txt").exists() and (RUN / "provenance.txt").exists():
            _copy_results(RUN, RESULTS)  # a full run from before the results were kept
        if not (RESULTS / "provenance.txt").exists():
            # The document is rendered from every section's results: without the shared
            # sets' the rewrite would drop their tables.
            p.error(f"no earlier full run in {RESULTS}; run scripts/benchmarks.py without --*-only")
        _copy_results(RESULTS, RUN)
    if args.resolution_only:
        run_resolution()
    elif args.perturbed_only:
        run_perturbed()
    elif args.reversed_only:
        run_reversed()
    elif args.partial_resolution_only:
        run_partial_resolution()
    elif not args.render_only:
        if not (args.partial_only or args.landmarks_only):
            run_shared()
        if not args.landmarks_only:
            run_partial()
        if not args.partial_only:
            run_landmarks()
        if not (args.partial_only or args.landmarks_only):
            run_resolution()
            run_perturbed()
            run_reversed()
            run_partial_resolution()
    if not args.render_only:
        _copy_results(RUN, RESULTS)
    render()
    return 0


if __name__ == "__main__":
    sys.exit(main())
