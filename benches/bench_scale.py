"""Per-pair time and peak memory of ``hope_rs.match`` from 5k to 250k vertices.

Large meshes are made by midpoint subdivision of the FAUST registrations tr_reg_012 → tr_reg_018
(same connectivity on both, so the ground truth is the identity; original vertices keep their
indices and are the ones scored). Subdividing every face multiplies the vertex count by about 4
(6890 → 27554 → 110204); for sizes in between, the last level subdivides only the faces on one
side of a plane (the same faces on both shapes), which leaves a seam of T-junctions there.

Each size runs in its own process; the table gives each stage's seconds and the peak resident
memory (sampled every 20 ms) during that stage, and the process's overall peak (ru_maxrss).

    python benches/bench_scale.py                          # 5k (faust_r), 28k (TOSCA), 100k, 250k
    python benches/bench_scale.py --cases faust100k --timeout 600
    python benches/bench_scale.py --cases faust100k,faust250k --multiscale
    python benches/bench_scale.py --cases faust100k --compare   # default path against --full

``match``'s default chooses the path by size (``MultiscaleConfig.auto_vertices``);
``--multiscale`` forces the coarse-to-fine path and ``--full`` the full one. ``--compare``
runs each case on the default path and on the full one (the path before the size rule), one
after the other, and prints the ratios of time and error.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"

#: name -> (data set, mesh A, mesh B, target vertex count or None for the mesh as it is)
CASES = {
    "faust_r5k": ("faust_r", "tr_reg_000", "tr_reg_001", None),
    "faust7k": ("faust_reg", "tr_reg_012", "tr_reg_018", None),
    "tosca28k": ("tosca", "cat0", "cat6", None),
    "faust28k": ("faust_reg", "tr_reg_012", "tr_reg_018", 27_554),
    "faust100k": ("faust_reg", "tr_reg_012", "tr_reg_018", 110_204),
    "faust250k": ("faust_reg", "tr_reg_012", "tr_reg_018", 250_000),
}


def subdivide_to(va: np.ndarray, vb: np.ndarray, faces: np.ndarray, target: int):
    """Subdivide two meshes of one connectivity identically until about ``target`` vertices.

    Returns the new vertices of both and the shared faces; the original vertices come first.
    """
    from trimesh.remesh import subdivide

    while va.shape[0] < target:
        n_edges = len({tuple(sorted(e)) for e in faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)})
        if va.shape[0] + n_edges <= target * 1.02:
            index = None  # the whole mesh
        else:
            # Faces on one side of a plane through A, chosen to add about the missing vertices.
            c = va[faces].mean(axis=1)
            axis = np.linalg.svd(c - c.mean(axis=0), full_matrices=False)[2][0]
            order = np.argsort(c @ axis)
            frac = (target - va.shape[0]) / n_edges
            index = np.sort(order[: int(frac * faces.shape[0] * 1.0)])
        na, fa = subdivide(va, faces, face_index=index)
        nb, fb = subdivide(vb, faces, face_index=index)
        assert np.array_equal(fa, fb)
        va, vb, faces = na, nb, fa
    return va, vb, faces


class PeakSampler(threading.Thread):
    """Samples this process's resident memory; ``mark(stage)`` closes the previous stage."""

    def __init__(self, period: float = 0.02):
        super().__init__(daemon=True)
        self.period, self.peak, self.stages = period, 0, {}
        self.page = os.sysconf("SC_PAGE_SIZE")

    def rss(self) -> int:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * self.page

    def run(self):
        while True:
            self.peak = max(self.peak, self.rss())
            time.sleep(self.period)

    def mark(self, stage: str) -> None:
        self.stages[stage] = max(self.peak, self.rss())
        print(f"{time.strftime('%X')} {stage} done", file=sys.stderr, flush=True)
        self.peak = self.rss()


def run_case(name: str, data: Path, multiscale: bool | None = None, spectral: bool = True) -> dict:
    """One case, in this process: build, match stage by stage, score on original vertices.
    ``multiscale``: as in ``match`` (None: chosen by size). On the coarse-to-fine path the
    "descriptors" stage is the whole coarse match and its lift, and "init" is empty.
    ``spectral``: as in ``match``."""
    import hope_rs
    from hope_rs.pipeline.runner import run_match

    folder, a, b, target = CASES[name]
    ma = hope_rs.load_mesh(data / folder / f"{a}.off")
    mb = hope_rs.load_mesh(data / folder / f"{b}.off")
    n0 = ma.n_vertices
    if folder == "faust_r":
        ai = hope_rs.load_vts(data / folder / "corres" / f"{a}.vts")
        bi = hope_rs.load_vts(data / folder / "corres" / f"{b}.vts")
    else:
        ai = bi = np.arange(min(n0, mb.n_vertices))
    if target is not None:
        va, vb, f = subdivide_to(ma.vertices, mb.vertices, ma.faces, target)
        ma, mb = hope_rs.Mesh(va, f), hope_rs.Mesh(vb, f)
    sampler = PeakSampler()
    sampler.start()
    sampler.mark("before")
    t0 = time.perf_counter()
    sa, sb = hope_rs.Shape(ma), hope_rs.Shape(mb)
    t = {"shapes": time.perf_counter() - t0}
    sampler.mark("shapes")
    config = hope_rs.MatchConfig().with_options(multiscale=multiscale, spectral=spectral)

    def on_stage(state, stage: str) -> None:
        # The multiscale stage (coarse match and lift) fills the "descriptors" column.
        if stage == "coarse":
            if state.coarse is not None:
                sampler.mark("descriptors")
            return
        sampler.mark(stage)

    # The stages of match, with a memory mark after each.
    res = run_match(sa, sb, "shot", config, on_stage=on_stage, timings=t)
    if "coarse" in t:
        t["descriptors"], t["init"] = t.pop("coarse"), 0.0
    for stage in ("descriptors", "init", "spectral", "faces"):
        t.setdefault(stage, 0.0)
    for stage in ("refine", "faces"):
        for part in ("cost", "assign"):
            t.setdefault(f"{stage}.{part}", 0.0)
    t["total"] = time.perf_counter() - t0
    f0, f = res.init_map, res.map
    res.map = res.hope_map
    init = hope_rs.score(hope_rs.geodesic_errors(sb, f0, a_idx=ai, b_idx=bi))
    hope = hope_rs.score(hope_rs.geodesic_errors(sb, res.map, a_idx=ai, b_idx=bi))
    final = hope_rs.score(hope_rs.geodesic_errors(sb, f, a_idx=ai, b_idx=bi))
    return {
        "case": name
        + {None: "", True: " (multiscale)", False: " (full)"}[multiscale]
        + (" (coarse-to-fine)" if res.coarse is not None and multiscale is None else "")
        + ("" if spectral else " (no spectral)"),
        "n": f"{ma.n_vertices}/{mb.n_vertices}",
        "steps": len(res.history),
        "seconds": t,
        "peak_gib": {k: v / 2**30 for k, v in sampler.stages.items()},
        "maxrss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
        "init": [init.exact, init.mean],
        "hope": [hope.exact, hope.mean, hope.auc],
        "final": [final.exact, final.mean, final.auc],
    }


def table(rows: list[dict]) -> str:
    head = (
        "| case | n | shapes (s) | descr (s) | init (s) | refine (s) | steps | spectral (s) "
        "| faces (s) | total (s) | peak descr / init / refine / spectral / faces (GiB) "
        "| max RSS (GiB) | init exact / mean | HOPE exact / mean | final exact / mean |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['case']} |" + " |" * 13 + f" {r['error']} |")
            continue
        s, p = r["seconds"], r["peak_gib"]
        lines.append(
            f"| {r['case']} | {r['n']} | {s['shapes']:.2f} | {s['descriptors']:.2f} "
            f"| {s['init']:.2f} | {s['refine']:.2f} | {r['steps']} | {s['spectral']:.2f} "
            f"| {s['faces']:.2f} | {s['total']:.1f} "
            f"| {p['descriptors']:.2f} / {p['init']:.2f} / {p['refine']:.2f} / {p['spectral']:.2f} "
            f"/ {p['faces']:.2f} "
            f"| {r['maxrss_gib']:.2f} | {100 * r['init'][0]:.1f}% / {r['init'][1]:.4f} "
            f"| {100 * r['hope'][0]:.1f}% / {r['hope'][1]:.4f} "
            f"| {100 * r['final'][0]:.1f}% / {r['final'][1]:.4f} |"
        )
    return head + "\n".join(lines) + "\n"


def steps_table(rows: list[dict]) -> str:
    """Where the HOPE steps' time goes: building overlap costs (parallel) against solving the
    assignments (the exact auction, sequential), and the rest of the refinement (LMD, the
    global repair, the polish, the map bookkeeping, and what the spectral pass's background
    eigensolve takes from them)."""
    head = (
        "| case | refine (s) | steps | overlap cost (s) | assignment (s) | rest (s) "
        "| faces (s) | faces' steps: cost / assignment (s) | assignment share of all steps |\n"
        "|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in rows:
        if "error" in r:
            continue
        s = r["seconds"]
        cost = s["refine.cost"] + s["faces.cost"]
        assign = s["refine.assign"] + s["faces.assign"]
        rest = s["refine"] - s["refine.cost"] - s["refine.assign"]
        share = assign / (cost + assign) if cost + assign > 0 else float("nan")
        lines.append(
            f"| {r['case']} | {s['refine']:.2f} | {r['steps']} | {s['refine.cost']:.2f} "
            f"| {s['refine.assign']:.2f} | {rest:.2f} | {s['faces']:.2f} "
            f"| {s['faces.cost']:.2f} / {s['faces.assign']:.2f} | {share:.0%} |"
        )
    return head + "\n".join(lines) + "\n"


def ratio_table(rows: list[dict]) -> str:
    """Each default-path row against the full-path row after it (``--compare``): time, peak
    memory and final mean error as ratios default / full, and both exact shares."""
    head = (
        "| case | time default / full | max RSS default / full | mean error default / full "
        "| exact default, full |\n|---|---|---|---|---|\n"
    )
    lines = []
    for new, old in zip(rows[::2], rows[1::2]):
        if "error" in new or "error" in old:
            lines.append(f"| {new['case']} | {new.get('error', old.get('error'))} | | | |")
            continue
        t = new["seconds"]["total"] / old["seconds"]["total"]
        m = new["maxrss_gib"] / old["maxrss_gib"]
        e = new["final"][1] / old["final"][1] if old["final"][1] > 0 else float("nan")
        lines.append(
            f"| {new['case']} | {t:.2f} ({new['seconds']['total']:.1f} / "
            f"{old['seconds']['total']:.1f} s) | {m:.2f} | {e:.2f} | "
            f"{100 * new['final'][0]:.1f}%, {100 * old['final'][0]:.1f}% |"
        )
    return head + "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", type=Path, default=Path(os.environ.get("HOPE_DATA", DEFAULT_DATA)))
    p.add_argument("--cases", default="faust_r5k,tosca28k,faust100k,faust250k")
    p.add_argument("--timeout", type=float, default=1200, help="seconds per case")
    p.add_argument("--out", type=Path, help="also write the Markdown table here")
    p.add_argument(
        "--multiscale",
        action="store_true",
        help="match(..., multiscale=True): the descr column is then the coarse match and lift",
    )
    p.add_argument(
        "--full", action="store_true", help="match(..., multiscale=False): the full path"
    )
    p.add_argument(
        "--compare",
        action="store_true",
        help="each case on the default path and with multiscale=False; prints the ratios",
    )
    p.add_argument(
        "--no-spectral", action="store_true", help="match(..., spectral=False): HOPE's map only"
    )
    p.add_argument("--child", help=argparse.SUPPRESS)
    args = p.parse_args()
    path = True if args.multiscale else (False if args.full else None)
    if args.child:
        print(json.dumps(run_case(args.child, args.data, path, not args.no_spectral)))
        return
    print(f"load average: {os.getloadavg()}", flush=True)
    rows = []
    runs = [
        (name, flag)
        for name in args.cases.split(",")
        for flag in (
            ([], ["--full"])
            if args.compare
            else (["--multiscale"] if args.multiscale else ["--full"] if args.full else [],)
        )
    ]
    for name, flag in runs:
        cmd = [sys.executable, __file__, "--child", name, "--data", str(args.data), *flag]
        cmd += ["--no-spectral"] if args.no_spectral else []
        try:
            # stdout carries the result; the child's stderr (stage progress, errors) passes through
            out = subprocess.run(
                cmd, check=False, stdout=subprocess.PIPE, text=True, timeout=args.timeout
            )
            if out.returncode != 0:
                row = {"case": name, "error": f"exit status {out.returncode}"}
            else:
                row = json.loads(out.stdout.strip().splitlines()[-1])
        except subprocess.TimeoutExpired:
            row = {"case": name, "error": f"over {args.timeout:.0f} s"}
        rows.append(row)
        print(json.dumps(row), flush=True)
    md = table(rows) + "\n" + steps_table(rows)
    if args.compare:
        md += "\n" + ratio_table(rows)
    print(md)
    if args.out:
        args.out.write_text(md)


if __name__ == "__main__":
    main()
