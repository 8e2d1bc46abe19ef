"""``hope-rs bench``: every method on every pair of a folder of data sets, scored and timed.

Writes to the results folder, per data set ``SET``:

* ``SET.csv`` — one row per (pair, method): accuracy, smoothness and wall time, once every
  pair of the set has run (until then ``SET.csv.partial``, rewritten after each pair, which
  the tables leave out: an interrupted run never passes for a finished one);
* ``SET.md`` — the table of each method over the pairs it ran (errors pooled over pairs);
* ``SET_curves.png`` — % correspondences within geodesic error, 0..0.25 and 0..0.10;
* ``SET_best.png``, ``SET_worst.png`` — colour transfer of HOPE's best and worst pair;

and ``summary.md``, every data set's table in one file (rebuilt from all the ``SET.csv``
tables present, so separate runs into one folder add up; other CSV files are left alone).
Errors use surface geodesics (``method="surface"`` of
:func:`hope_rs.evaluation.evaluate.geodesic_errors`), normalised by sqrt(area) of the target.

A (pair, method) that raises (a mesh the method or the scoring cannot handle) gets a row with
only its ``failed`` reason, left out of the figures and listed under its table; the other
pairs and methods still run.
"""

from __future__ import annotations

import csv
import importlib.util
import io
import sys
import time
from pathlib import Path

import numpy as np

from ..geometry.map_io import atomic_write, check_writable_folder
from ..geometry.mesh import load_mesh
from .datasets import GIVE_PAIRS, Pair, datasets_in, pairs_of
from .evaluate import confidence_auroc, error_curve, geodesic_errors, score, smoothness
from .methods import (
    ABLATIONS,
    DEFAULT_METHODS,
    METHODS,
    PYFM_METHODS,
    PairContext,
    check_methods,
    run_method,
)
from .perturbed import shortcut_errors
from .show import render_pair

FIELDS = [
    "dataset", "pair", "method", "n_a", "n_b", "n_scored", "exact", "mean", "mean_x100", "auc",
    "auc_010", "edge_stretch", "coverage", "seconds", "start", "start_exact", "start_mean",
    "confidence_auroc", "likely_failed", "mean_a", "failed",
]  # fmt: skip


class BenchProgress:
    """A progress bar on stderr (one line per step when stderr is not a terminal)."""

    def __init__(self, total: int, *, enabled: bool = True):
        self.total, self.done, self.enabled = total, 0, enabled
        self.tty = sys.stderr.isatty()
        self.t0 = time.perf_counter()

    def step(self, what: str) -> None:
        self.done += 1
        if not self.enabled:
            return
        width = 24
        fill = int(width * self.done / max(self.total, 1))
        line = (
            f"[{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total} "
            f"{time.perf_counter() - self.t0:6.0f}s {what}"
        )
        sys.stderr.write(f"\r{line[:110]:110s}" if self.tty else line + "\n")
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            sys.stderr.write("\n")


def _errors(pair: Pair, ctx, mapping, ai, bi) -> np.ndarray:
    """Surface geodesic errors of ``mapping``; onto a welded B of a ``shortcuts`` set
    (:mod:`hope_rs.evaluation.perturbed`) on the clean B, a weld counting as either of its
    two vertices."""
    e = shortcut_errors(pair.b.parent, pair.b.stem, mapping, ai, bi)
    if e is None:
        e = geodesic_errors(ctx.b, mapping, a_idx=ai, b_idx=bi, method="surface")
    return e


def _score_row(pair: Pair, name: str, res, ctx, ai, bi, starts: dict) -> tuple[dict, np.ndarray]:
    e = _errors(pair, ctx, res.map, ai, bi)
    s, sm = score(e), smoothness(ctx.a, ctx.b, res.map)
    row = {
        "dataset": pair.dataset, "pair": pair.name, "method": name, "n_a": ctx.a.n_vertices,
        "n_b": ctx.b.n_vertices, "n_scored": int(ai.size), "exact": s.exact, "mean": s.mean,
        "mean_x100": s.mean_x100, "auc": s.auc, "auc_010": s.auc_010,
        "edge_stretch": sm.edge_stretch, "coverage": sm.coverage, "seconds": res.seconds,
        "start": res.start or "",
        # The mean error ÷ sqrt(area) of A instead of B: a whole → part pair is then measured
        # in the whole's units, as its part → whole counterpart is.
        "mean_a": s.mean * ctx.b.scale / ctx.a.scale,
    }  # fmt: skip
    if res.start and name.startswith("hope"):
        if res.start not in starts:
            starts[res.start] = score(_errors(pair, ctx, ctx.start_map(res.start), ai, bi))
        row["start_exact"], row["start_mean"] = starts[res.start].exact, starts[res.start].mean
    if res.confidence is not None:
        # How well MatchResult.confidence tells right (error <= 0.05) from wrong matches.
        row["confidence_auroc"] = confidence_auroc(res.confidence[ai], e)
    if res.quality is not None:
        row["likely_failed"] = int(res.quality.likely_failed)
    return row, e


def _write_csv(path: Path, rows: list[dict]) -> None:
    text = io.StringIO(newline="")
    w = csv.DictWriter(text, fieldnames=FIELDS)
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    atomic_write(path, _writer(text.getvalue()))


#: Suffix of a set's table while its pairs run (not ``.csv``: the tables leave it out).
PARTIAL = ".partial"


#: Columns a results table has (an older table may lack later ones); a CSV file without them
#: is not one of this module's tables.
TABLE_COLUMNS = {"dataset", "pair", "method", "n_scored", "failed"}


def _is_table(path: Path) -> bool:
    """Whether ``path`` is one of this module's tables, read from its header only."""
    try:
        with open(path, newline="") as fh:
            header = next(csv.reader(fh), [])
    except (OSError, UnicodeDecodeError, csv.Error):
        return False
    return set(header) >= TABLE_COLUMNS


def _read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _table(rows: list[dict], methods: list[str]) -> str:
    """Markdown table: one line per method, figures averaged over its pairs."""
    head = (
        "| method | pairs | exact % | mean err | mean ×100 | AUC 0.25 | AUC 0.10 | edge stretch "
        "| coverage % | start mean ×100 | confidence AUROC | s / pair |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for m in methods:
        rs = [r for r in rows if r["method"] == m and not r.get("failed")]
        if not rs:
            continue

        def avg(k, rs=rs):
            vals = [float(r[k]) for r in rs if r.get(k) not in (None, "")]
            return float(np.mean(vals)) if vals else float("nan")

        start = avg("start_mean")
        # Mean over the pairs where it is defined (a pair with no wrong match has none).
        aurocs = [float(r.get("confidence_auroc") or "nan") for r in rs]
        conf = float(np.nanmean(aurocs)) if not np.isnan(aurocs).all() else float("nan")
        lines.append(
            f"| {m} | {len(rs)} | {100 * avg('exact'):.1f} | {avg('mean'):.4f} "
            f"| {avg('mean_x100'):.2f} | {avg('auc'):.3f} | {avg('auc_010'):.3f} "
            f"| {avg('edge_stretch'):.2f} | {100 * avg('coverage'):.1f} "
            f"| {'' if np.isnan(start) else f'{100 * start:.2f}'} "
            f"| {'' if np.isnan(conf) else f'{conf:.3f}'} | {avg('seconds'):.1f} |"
        )
    return head + "\n".join(lines) + "\n"


def _failure(pair: Pair, method: str, err: Exception, a=None, b=None) -> dict:
    """The row of a (pair, method) that raised: its reason on one line."""
    reason = " ".join(f"{type(err).__name__}: {err}".split())
    return {
        "dataset": pair.dataset, "pair": pair.name, "method": method,
        "n_a": "" if a is None else a.n_vertices, "n_b": "" if b is None else b.n_vertices,
        "failed": reason[:300],
    }  # fmt: skip


def _failed_lines(rows: list[dict]) -> str:
    bad = [r for r in rows if r.get("failed")]
    if not bad:
        return ""
    return f"\nFailed ({len(bad)}, left out of the figures above):\n\n" + "".join(
        f"- {r['pair']} {r['method']}: {r['failed']}\n" for r in bad
    )


def _set_markdown(name: str, rows: list[dict], methods: list[str]) -> str:
    ran = {r["method"] for r in rows if not r.get("failed")}
    methods = [m for m in methods if m in ran]
    pairs = list(dict.fromkeys(r["pair"] for r in rows))
    main = [m for m in methods if m not in ABLATIONS]
    abl = [m for m in methods if m in ABLATIONS]
    n_scored = sorted({int(r["n_scored"]) for r in rows if not r.get("failed")})
    md = [
        f"## {name}\n",
        (
            f"{len(pairs)} pairs: {', '.join(pairs)}. Scored correspondences per pair: "
            f"{'/'.join(map(str, n_scored))}. Errors: surface geodesic / sqrt(area of target); "
            "figures are means over pairs; seconds are wall time from meshes to map; confidence "
            "AUROC: how well MatchResult.confidence ranks right matches (error <= 0.05) above "
            "wrong ones (0.5: not at all), over the pairs with both.\n"
        ),
        _table(rows, main),
    ]
    if _failed_lines(rows):
        md.append(_failed_lines(rows))
    if abl:
        abl_pairs = sorted({r["pair"] for r in rows if r["method"] in abl}, key=pairs.index)
        same = [r for r in rows if r["pair"] in abl_pairs]
        md += [
            (
                f"\nAblations, on the pairs they ran ({', '.join(abl_pairs)}); HOPE on the same pairs "
                "for reference. 'start mean' is the error of the map HOPE started from.\n"
            ),
            _table(same, [m for m in ("init", "hope") if m in methods] + abl),
        ]
    return "\n".join(md)


def _plot_curves(name: str, errors: dict[str, list[np.ndarray]], n_pairs: dict, path: Path):
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.6), dpi=90)
    for ax, top in zip(axes, (0.25, 0.10)):
        for m, es in errors.items():
            t, c = error_curve(np.concatenate(es), max_error=top)
            style = "--" if m in ABLATIONS else "-"
            ax.plot(t, 100 * c, style, lw=1.4, label=f"{m} ({n_pairs[m]} pairs)")
        ax.set_xlim(0, top)
        ax.set_ylim(0, 100)
        ax.set_xlabel("geodesic error / sqrt(area)")
        ax.set_ylabel("% correspondences")
        ax.grid(alpha=0.3)
    axes[0].set_title(f"{name}: 0..0.25", fontsize=10)
    axes[1].set_title(f"{name}: 0..0.10", fontsize=10)
    axes[1].legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _writer(text: str):
    """What :func:`~hope_rs.geometry.map_io.atomic_write` writes for ``text`` (UTF-8)."""
    data = text.encode("utf-8")
    return lambda fh: fh.write(data)


def write_tables(out) -> None:
    """(Re)write ``SET.md`` and ``summary.md`` from the ``SET.csv`` files in ``out``."""
    out = Path(out)
    parts = ["# Benchmark results\n"]
    for path in sorted(p for p in out.glob("*.csv") if _is_table(p)):
        rows = _read_csv(path)
        if rows:
            md = _set_markdown(path.stem, rows, list(dict.fromkeys(r["method"] for r in rows)))
            atomic_write(path.with_suffix(".md"), _writer(md))
            parts.append(md)
    atomic_write(out / "summary.md", _writer("\n".join(parts)))


#: The render's up axes (:func:`hope_rs.evaluation.show.render_pair`).
UP_AXES = ("auto", "x", "y", "z")


def _parse_up(up: str, names) -> dict[str, str]:
    """``--up``: comma-separated items, each an axis (for every set) or ``SET=AXIS`` for the
    data set ``SET``, one of ``names``; checked before any work."""
    out = {}
    for item in (s.strip() for s in up.split(",")):
        if not item:
            continue
        k, eq, v = (x.strip() for x in item.partition("="))
        if not eq:
            k, v = "*", k
        elif k not in names:
            raise ValueError(f"--up {item!r}: no data set {k!r}; found {', '.join(sorted(names))}")
        if v not in UP_AXES:
            raise ValueError(f"--up {item!r}: the axis must be one of {', '.join(UP_AXES)}")
        out[k] = v
    return out


def _select(folders: list[Path], names, data_dir) -> list[Path]:
    if not names:
        return folders
    wanted = [s.strip() for s in (names.split(",") if isinstance(names, str) else names)]
    missing = [s for s in wanted if s not in {f.name for f in folders}]
    if missing:
        raise ValueError(
            f"no data set {', '.join(missing)} in {str(data_dir)!r}; found "
            + ", ".join(f.name for f in folders)
        )
    return [f for f in folders if f.name in wanted]


def missing_packages(methods) -> list[str]:
    """The packages (pip names) :func:`run_bench` needs for ``methods`` that are not
    installed: potpourri3d (surface geodesics), matplotlib (the curves), pyFM (ZoomOut)."""
    needs = {"potpourri3d": "potpourri3d", "matplotlib": "matplotlib"}
    if any(m in PYFM_METHODS for m in methods):
        needs["pyFM"] = "pyfmaps"
    return [pip for module, pip in needs.items() if importlib.util.find_spec(module) is None]


def run_bench(
    data_dir,
    out,
    *,
    methods=DEFAULT_METHODS,
    sets=None,
    max_pairs: int | None = None,
    ablation_pairs: int | None = None,
    ablation_sets=None,
    render: bool = True,
    up: str = "auto",
    progress: bool = True,
) -> list[dict]:
    """Run ``methods`` on the pairs of each data set in ``data_dir`` and write the results to
    ``out`` (see the module notes). Returns the per-pair rows.

    Parameters
    ----------
    max_pairs : int, optional
        At most this many pairs per data set (the first ones of ``pairs.txt``).
    ablation_pairs : int, optional
        Ablation methods (``hope-*``) run on at most this many pairs per data set.
    ablation_sets : list of str or comma-separated str, optional
        Data sets the ablations run on (default: all).
    up : str
        Up axis of the renders: "auto", "x", "y", "z", or per set as "SET=AXIS,...".
    """

    methods = check_methods(methods)
    missing = missing_packages(methods)
    if "pyfmaps" in missing:
        raise ValueError(
            "the zoomout methods need pyFM: pip install pyfmaps (Python >= 3.10), or leave "
            "zoomout out of --methods"
        )
    if missing:
        raise ValueError(
            f"hope-rs bench needs {', '.join(missing)} for scoring and plots: "
            f"pip install {' '.join(missing)} (or hope-rs[eval])"
        )
    found = datasets_in(data_dir)
    folders = _select(found, sets, data_dir)
    abl_sets = {f.name for f in _select(folders, ablation_sets, data_dir)}
    ups = _parse_up(up, {f.name for f in found})
    plan = []
    for folder in folders:
        pairs = pairs_of(folder)[:max_pairs]
        for i, pair in enumerate(pairs):
            ms = [
                m
                for m in methods
                if m not in ABLATIONS
                or (folder.name in abl_sets and (ablation_pairs is None or i < ablation_pairs))
            ]
            plan.append((pair, ms))
    if not plan:
        raise ValueError(f"no pair to run in {str(data_dir)!r}; for each data set, {GIVE_PAIRS}")
    out = check_writable_folder(out, create=True)
    bar = BenchProgress(sum(len(ms) for _, ms in plan), enabled=progress)
    all_rows: list[dict] = []
    try:
        for folder in folders:
            rows: list[dict] = []
            partial = out / f"{folder.name}.csv{PARTIAL}"
            errors: dict[str, list[np.ndarray]] = {}
            shown: list[tuple[float, Pair, np.ndarray]] = []
            show_method = "hope" if "hope" in methods else methods[-1]
            for pair, ms in (p for p in plan if p[0].dataset == folder.name):
                a = b = None
                try:
                    a, b = load_mesh(pair.a), load_mesh(pair.b)
                    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices)
                except Exception as err:  # one pair that cannot be read never stops the bench
                    for m in ms:
                        rows.append(_failure(pair, m, err, a, b))
                        bar.step(f"{folder.name} {pair.name} {m} FAILED {rows[-1]['failed']}")
                    _write_csv(partial, rows)
                    continue
                ctx = PairContext(a, b)
                starts: dict = {}
                for m in ms:
                    try:
                        res = run_method(m, ctx)
                        row, e = _score_row(pair, m, res, ctx, ai, bi, starts)
                    except Exception as err:  # nor one method that fails on one pair
                        rows.append(_failure(pair, m, err, a, b))
                        bar.step(f"{folder.name} {pair.name} {m} FAILED {rows[-1]['failed']}")
                        continue
                    rows.append(row)
                    errors.setdefault(m, []).append(e)
                    if m == show_method:
                        shown.append((row["mean"], pair, res.map))
                    bar.step(f"{folder.name} {pair.name} {m} x100 {row['mean_x100']:.2f}")
                _write_csv(partial, rows)
            if not rows:
                continue
            _write_csv(out / f"{folder.name}.csv", rows)  # the set is whole
            partial.unlink(missing_ok=True)
            all_rows += rows
            n_pairs = {m: len(es) for m, es in errors.items()}
            if errors:
                _plot_curves(folder.name, errors, n_pairs, out / f"{folder.name}_curves.png")
            if render and shown:
                _render_extremes(folder.name, shown, show_method, ups, out)
            write_tables(out)
    finally:
        bar.close()
    return all_rows


def _render_extremes(name, shown, method, ups, out: Path) -> None:

    shown = sorted(shown, key=lambda s: s[0])
    for tag, (mean, pair, f) in (("best", shown[0]), ("worst", shown[-1])):
        render_pair(
            load_mesh(pair.a), load_mesh(pair.b), f, out / f"{name}_{tag}.png",
            title=f"{name} {pair.name}\n{method}, {tag} pair: mean error ×100 {100 * mean:.2f}",
            up=ups.get(name, ups.get("*", "auto")),
        )  # fmt: skip


def methods_help() -> str:
    """The method list of ``hope-rs bench --help``: one line per entry of
    :data:`hope_rs.evaluation.methods.METHODS`, ablations marked."""
    width = max(map(len, METHODS)) + 2
    lines = [
        f"  {name:<{width}}{'ablation: ' if name in ABLATIONS else ''}{what}"
        for name, (what, _) in METHODS.items()
    ]
    return "methods (--methods, comma-separated, or 'all'):\n" + "\n".join(lines)


def methods_markdown() -> str:
    """The same list as a Markdown table (for the README), from the same registry."""
    rows = [
        f"| `{name}` | {'ablation: ' if name in ABLATIONS else ''}{what} |"
        for name, (what, _) in METHODS.items()
    ]
    return "| method | what |\n|---|---|\n" + "\n".join(rows) + "\n"


def add_parser(sub) -> None:
    """Register ``hope-rs bench``."""
    import argparse

    p = sub.add_parser(
        "bench",
        help="score and time methods on every pair of a folder of data sets",
        description="Runs every method on every pair and writes SET.csv, SET.md, SET_curves.png, "
        "SET_best/worst.png and summary.md.",
        epilog=methods_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data_dir", help="a data-set folder, or a folder of data-set folders")
    p.add_argument("--out", required=True, help="results folder (created)")
    p.add_argument(
        "--methods", default=",".join(DEFAULT_METHODS),
        help=f"comma-separated (default {','.join(DEFAULT_METHODS)}); 'all' for every method",
    )  # fmt: skip
    p.add_argument("--sets", help="comma-separated data-set names (default: all)")
    p.add_argument("--max-pairs", type=int, help="at most N pairs per data set")
    p.add_argument("--ablation-pairs", type=int, help="run hope-* ablations on at most N pairs")
    p.add_argument("--ablation-sets", help="data sets to run the ablations on (default: all)")
    p.add_argument("--up", default="auto", help="render up axis: auto|x|y|z or SET=AXIS,...")
    p.add_argument("--no-render", action="store_true", help="skip the best/worst pair PNGs")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_bench)


def cmd_bench(args) -> int:
    for flag in ("max_pairs", "ablation_pairs"):
        v = getattr(args, flag)
        if v is not None and v < 1:
            raise ValueError(f"--{flag.replace('_', '-')} must be at least 1, got {v}")
    methods = list(METHODS) if args.methods == "all" else args.methods
    rows = run_bench(
        args.data_dir, args.out, methods=methods, sets=args.sets, max_pairs=args.max_pairs,
        ablation_pairs=args.ablation_pairs, ablation_sets=args.ablation_sets, render=not args.no_render, up=args.up,
        progress=not args.quiet,
    )  # fmt: skip
    failed = [r for r in rows if r.get("failed")]
    print(
        f"{len(rows) - len(failed)} of {len(rows)} results scored; tables written to {args.out} "
        "(summary.md, SET.csv, SET.md and the plots of the scored ones)"
    )
    if failed:
        print(f"{len(failed)} failed (listed in the tables):", file=sys.stderr)
        for r in failed:
            print(f"  {r['dataset']} {r['pair']} {r['method']}: {r['failed']}", file=sys.stderr)
    # Like a batch: the tables are written either way, the status says that a pair failed.
    return 1 if failed else 0
