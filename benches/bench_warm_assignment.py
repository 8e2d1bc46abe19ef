"""Warm-started exact assignment against today's auction on the replayed steps of real matches.

Each HOPE step of ``hope_rs.match`` is recorded (its inputs at the Rust step call), its cost is
rebuilt (``_core.overlap_step_cost_graphs``) and solved, in one run and alternately:

* **cold**: today's path, the auction with the step's hint (``_core.auction_assignment_int``);
* **warm**: ``_core.warm_assignment_int`` from the previous step's optimal assignment and
  optimal column prices: rows whose entry is no longer tight are re-inserted by shortest
  augmenting paths;
* **dual**: the same solver from zero prices (every row that is not on its row's best column
  breaks): what a step costs when no prices are carried over, e.g. after a fallback.

Per step: the median of ``--repeats`` alternated timings, the rows repaired, whether the optimum
is unique (then every exact solver returns the same assignment, so the warm start reproduces
the auction's map bit for bit), and the totals of cold and warm (must agree: both exact).
The summary prints warm / cold per pair, and the cost of an exact-reproduction policy: warm,
plus the auction whenever the warm optimum is not unique or the warm start does not apply.

Also counts the HOPE steps whose map moved no vertex (``Iteration.changed == 0``) and those
the refinement did not solve because their inputs repeated (``Iteration.reused``).

Run from the repository root::

    python benches/bench_warm_assignment.py                 # faust_r 000-001 (5k) and the cat (28k)
    python benches/bench_warm_assignment.py --quick         # the 5k pair only
    python benches/bench_warm_assignment.py --large         # also a FAUST pair subdivided twice (110k)
    python benches/bench_warm_assignment.py --pair "TOSCA cat0-cat6"

Every step's cost is kept in memory for the replay: about 1 GB for the cat, several GB and an
hour on 2 cores with ``--large``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import hope_rs
from hope_rs import _core
from hope_rs.geometry.mesh import load_mesh

BENCH_DIR = Path(__file__).resolve().parent
DEFAULT_DATA = BENCH_DIR.parent.parent / "shared" / "data"
PAIRS = {
    "faust_r 000-001": ("faust_r/tr_reg_000.off", "faust_r/tr_reg_001.off", 0),
    "TOSCA cat0-cat6": ("tosca/cat0.off", "tosca/cat6.off", 0),
    "FAUST 012-018 subdivided twice": ("faust_reg/tr_reg_012.off", "faust_reg/tr_reg_018.off", 2),
}
QUICK = ("faust_r 000-001",)
DEFAULT = ("faust_r 000-001", "TOSCA cat0-cat6")


@dataclass
class Step:
    k: int
    cost: tuple  # indptr, indices, data, n_rows, n_cols
    hint: np.ndarray
    floor_div: int
    f: np.ndarray  # the map the step starts from
    out: np.ndarray  # the auction's assignment in the recorded run


def subdivided(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each face split into four at its edges' midpoints (the original vertices keep their
    numbers)."""
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, inv = np.unique(edges, axis=0, return_inverse=True)
    mid = v.shape[0] + inv.reshape(3, -1).T
    corners = [np.stack([f[:, i], mid[:, i], mid[:, (i + 2) % 3]], 1) for i in range(3)]
    return np.vstack([v, v[uniq].mean(axis=1)]), np.concatenate([*corners, mid])


def load(path: Path, times: int) -> hope_rs.Mesh:
    m = load_mesh(path)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    for _ in range(times):
        v, f = subdivided(v, f)
    return hope_rs.Mesh(v, f)


def record(a: hope_rs.Mesh, b: hope_rs.Mesh) -> tuple[list[Step], list]:
    """The steps of ``hope_rs.match(a, b)`` with their costs, and the match's history."""
    calls = []
    original = _core.overlap_assignment_graphs

    def spy(ga, gb, k, f, w, top_k, keep, hint, floor_div, stay):
        g, tc, ta = original(ga, gb, k, f, w, top_k, keep, hint, floor_div, stay)
        cost = _core.overlap_step_cost_graphs(ga, gb, k, f, w, top_k, keep, stay)
        calls.append(Step(k, (*cost, ga.n_vertices, gb.n_vertices), hint, floor_div, f.copy(), g))
        return g, tc, ta

    _core.overlap_assignment_graphs = spy
    try:
        res = hope_rs.match(a, b)
    finally:
        _core.overlap_assignment_graphs = original
    return calls, res.history


def total(cost: tuple, assign: np.ndarray) -> int:
    indptr, indices, data, n_rows, _ = cost
    rows = np.repeat(np.arange(n_rows), np.diff(indptr))
    hit = indices == assign[rows]
    return int(data[hit].sum())


def cold(step: Step) -> np.ndarray:
    return _core.auction_assignment_int(*step.cost, True, step.floor_div, step.hint)


def warm(step: Step, prev: np.ndarray, prices: np.ndarray):
    return _core.warm_assignment_int(*step.cost, prev, prices, step.cost[3])


def timed(fn, *args) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn(*args)
    return time.perf_counter() - t0, out


def duals(step: Step) -> tuple[float, np.ndarray]:
    """Seconds and optimal column prices of a step, from zero prices."""
    t, out = timed(warm, step, step.out, np.zeros(step.cost[4], dtype=np.int64))
    return t, out[1]


def start_map(step: Step) -> np.ndarray:
    """The warm start's assignment: the step's own map where it is one-to-one."""
    f = step.f
    return f if np.unique(f).size == f.size and step.cost[3] <= step.cost[4] else step.hint


def bench_pair(name: str, data: Path, repeats: int) -> list[str]:
    pa, pb, sub = PAIRS[name]
    a, b = load(data / pa, sub), load(data / pb, sub)
    if a.n_vertices > b.n_vertices:  # the warm solver takes rows <= columns
        a, b = b, a
    t0 = time.perf_counter()
    steps, history = record(a, b)
    t_match = time.perf_counter() - t0
    t_dual, prices = zip(*(duals(s) for s in steps))
    rows = []
    for i, s in enumerate(steps[1:], 1):
        same_k = [j for j in range(i) if steps[j].k == s.k]
        sources = {"previous": i - 1, "same k": same_k[-1] if same_k else None}
        tc, tw, outs = [], {n: [] for n in sources}, {}
        for _ in range(repeats):  # alternated, medians
            t, g = timed(cold, s)
            tc.append(t)
            for n, j in sources.items():
                if j is not None:
                    t, outs[n] = timed(warm, s, start_map(s), prices[j])
                    tw[n].append(t)
        assert np.array_equal(g, s.out), f"step {i}: the auction is deterministic"
        cells = [str(i), str(s.k), f"{statistics.median(tc):.4f}", f"{t_dual[i]:.4f}"]
        row = {"cold": statistics.median(tc)}
        for n, j in sources.items():
            w = outs.get(n)
            if j is None or w is None:
                cells += ["-", "-", "-"]
                row[n] = None
                continue
            assert total(s.cost, w[0]) == total(s.cost, g), f"step {i}: warm is exact"
            if w[3]:
                assert np.array_equal(w[0], g), f"step {i}: a unique optimum is the auction's"
            t = statistics.median(tw[n])
            row[n] = (t, w[2], w[3], int(np.count_nonzero(w[0] != g)))
            cells += [f"{t:.4f} ({t / row['cold']:.2f})", str(w[2]), f"{w[3]} / {row[n][3]}"]
        rows.append((row, cells))
    lines = [
        (
            f"### {name} ({a.n_vertices} -> {b.n_vertices} vertices; match {t_match:.1f} s, "
            f"{len(steps)} assignment steps)"
        ),
        "",
        (
            "| step | k | cold (s) | from zero prices (s) | warm from the previous step (s, / cold) "
            "| rows repaired | unique / rows differing | warm from the last step at the same k "
            "(s, / cold) | rows repaired | unique / rows differing |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines += ["| " + " | ".join(c) + " |" for _, c in rows]
    lines.append("")
    cold_all = sum(r["cold"] for r, _ in rows)
    for src in ("previous", "same k"):
        got = [(r["cold"], r[src]) for r, _ in rows if r[src] is not None]
        if not got:
            continue
        c = sum(x for x, _ in got)
        w = sum(y[0] for _, y in got)
        exact = sum(y[0] + (0 if y[2] else x) for x, y in got)
        rep = statistics.median(y[1] for _, y in got)
        uniq = sum(y[2] for _, y in got)
        lines.append(
            f"- warm from the {src} step, {len(got)} steps: cold {c:.3f} s, warm {w:.3f} s "
            f"(warm / cold {w / c:.2f}); keeping the auction's map (auction wherever the optimum "
            f"is not unique) {exact:.3f} s ({exact / c:.2f}); rows repaired median {rep:.0f} of "
            f"{a.n_vertices}; unique optima {uniq} of {len(got)}"
        )
    lines.append(f"- all steps but the first, cold: {cold_all:.3f} s")
    still = [i for i, s in enumerate(steps) if np.array_equal(s.out, s.f)]
    refine = [it for it in history if it.k > 0 and not it.polish]
    lines += [
        (
            f"- assignment steps that moved no vertex: {len(still)} of {len(steps)} "
            f"(steps {still}); refinement k-hop steps (history): "
            f"{sum(it.changed == 0 for it in refine)} of {len(refine)}, of which "
            f"{sum(it.reused for it in refine)} took an earlier step's result unsolved "
            "(Iteration.reused: the same map at the same k)"
        ),
        "",
    ]
    return lines


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, default=DEFAULT_DATA)
    p.add_argument("--quick", action="store_true", help="the 5k pair only")
    p.add_argument("--large", action="store_true", help="also the 110k subdivided pair")
    p.add_argument("--pair", action="append", choices=list(PAIRS), help="only these pairs")
    p.add_argument("--repeats", type=int, default=5, help="alternated timings per step (median)")
    p.add_argument("--out", type=Path, default=None, help="also write the Markdown here")
    args = p.parse_args(argv)
    names = QUICK if args.quick else DEFAULT + (tuple(PAIRS)[2:] if args.large else ())
    names = tuple(args.pair) if args.pair else names
    lines = []
    for name in names:
        part = bench_pair(name, args.data, args.repeats)
        print("\n".join(part), flush=True)
        lines += part
    if args.out is not None:
        tmp = args.out.with_suffix(args.out.suffix + ".tmp")
        tmp.write_text("\n".join(lines) + "\n")
        tmp.replace(args.out)


if __name__ == "__main__":
    main()
