"""Benchmark the three Rust kernels of hope_rs against the Python route a user would write.

What is compared (for each mesh pair and each hop radius k):

* ``khop_neighbourhoods`` vs SciPy boolean sparse powers ``(A + I)^k`` (A: edge adjacency
  built from the faces with SciPy); both patterns are checked equal.
* ``overlap_cost`` vs the SciPy sparse product ``Na @ diag(w) @ P @ Nb.T`` (P: the n_a x n_b
  matrix of the map f, w: witness indicator); checked equal for ``keep=None``. Ours is timed
  with ``keep=None`` and with ``keep=f`` (the form the assignment needs), ``top_k=None`` both.
* ``auction_assignment`` on the integer cost ``4*K + (col == f[row])`` (K from
  ``overlap_cost(..., keep=f)``) vs ``lap.lapmod`` (sparse Jonker-Volgenant, on ``max - cost``)
  and ``scipy.sparse.csgraph.min_weight_full_bipartite_matching`` (on ``max + 1 - cost``; only
  for n <= 10000 unless ``--slow-peers``). The totals of ours and lapmod must agree.

Inputs follow the project's protocol: f is the identity with a random 20% of its entries
shuffled among themselves (seeded), the witnesses are the other 80%.

Times are the best of a few repeats (``time.perf_counter``). Peak memory is the peak RSS
(``VmHWM``) of a fresh ``python -c`` subprocess that imports hope_rs, loads the meshes and the
precomputed inputs, and calls one kernel; the baseline is the same process without the call.
(``ru_maxrss`` of such a child is useless: Linux carries the parent's peak over the exec.)
This runs on the largest pair of the run at its largest k (TOSCA at k = 8 by default, FAUST
with ``--quick``), followed by the "every vertex is a witness" case: ``overlap_cost`` with
``top_k=64, keep=f`` and without top_k (killed past 60 s or 6 GiB RSS, then "skipped").

Run from the repository root::

    python benches/bench_kernels.py                  # full run (TOSCA 28k + FAUST 7k, k = 1..8)
    python benches/bench_kernels.py --quick          # CI smoke run: FAUST, k in {1, 4, 8}
    python benches/bench_kernels.py --k 1,4 --out bench.md --data /path/to/data

Needs ``lap`` (``pip install lap``) besides numpy and scipy. The Rust kernels use every core
(rayon; set ``RAYON_NUM_THREADS`` to change it), the SciPy and lap peers run on one core.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy
import scipy.sparse as sp

import hope_rs
from hope_rs.geometry.mesh import load_mesh

BENCH_DIR = Path(__file__).resolve().parent
DEFAULT_DATA = BENCH_DIR.parent.parent / "shared" / "data"
PAIRS = {
    "TOSCA cat0-cat6": ("tosca/cat0.off", "tosca/cat6.off"),
    "FAUST 012-018": ("faust_reg/tr_reg_012.off", "faust_reg/tr_reg_018.off"),
}
QUICK_PAIRS = ("FAUST 012-018",)
QUICK_KS = (1, 4, 8)
SHUFFLED_FRACTION = 0.2
SCIPY_MATCHING_MAX_N = 10_000  # scipy's matching was once measured at 245 s on the 28k pair
ALL_WITNESS_TOP_K = 64
CHILD_TIME_LIMIT_S = 60
CHILD_RSS_LIMIT_MIB = 6 * 1024


# ----------------------------------------------------------------------------- inputs


@dataclass
class Pair:
    name: str
    paths: tuple[Path, Path]
    faces_a: np.ndarray
    faces_b: np.ndarray
    n: int


def load_pair(name: str, data_dir: Path) -> Pair:
    paths = tuple(data_dir / p for p in PAIRS[name])
    a, b = (load_mesh(p) for p in paths)
    if a.n_vertices != b.n_vertices:
        raise ValueError(f"{name}: the pair must have equal vertex counts for an identity map")
    return Pair(name, paths, a.faces, b.faces, a.n_vertices)


def perturbed_identity(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Identity map with a random 20% of entries shuffled among themselves; witnesses = rest."""
    f = np.arange(n, dtype=np.int64)
    moved = rng.choice(n, size=round(SHUFFLED_FRACTION * n), replace=False)
    f[moved] = f[rng.permutation(moved)]
    witnesses = np.ones(n, dtype=bool)
    witnesses[moved] = False
    return f, witnesses


def assignment_cost(k_keep: sp.csr_matrix, f: np.ndarray) -> sp.csr_matrix:
    """Integer cost ``4*K + (col == f[row])``: the current match gets a tiny bonus."""
    rows = np.repeat(np.arange(k_keep.shape[0]), np.diff(k_keep.indptr))
    data = 4 * k_keep.data.astype(np.int64) + (k_keep.indices == f[rows])
    return sp.csr_matrix((data, k_keep.indices.copy(), k_keep.indptr.copy()), shape=k_keep.shape)


# ----------------------------------------------------------------------------- peers


def scipy_khop(faces: np.ndarray, n: int, k: int) -> sp.csr_matrix:
    """Boolean ``(A + I)^k`` with SciPy, A the symmetric edge adjacency of the faces."""
    i, j = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    a = sp.csr_matrix((np.ones(i.size, dtype=bool), (i, j)), shape=(n, n))
    step = (a + a.T + sp.identity(n, dtype=bool, format="csr")).tocsr()
    out = sp.identity(n, dtype=bool, format="csr")
    for _ in range(k):
        out = out @ step  # bool @ bool stays bool: the threshold is built in
    return out


def scipy_overlap(nbrs_a, nbrs_b, f: np.ndarray, witnesses: np.ndarray) -> sp.csr_matrix:
    """``Na @ diag(w) @ P @ Nb.T`` in int32 (uint8 would overflow)."""
    n_a, n_b = nbrs_a.shape[0], nbrs_b.shape[0]
    w = sp.diags(witnesses, dtype=np.int32)
    p = sp.csr_matrix((np.ones(n_a, dtype=np.int32), (np.arange(n_a), f)), shape=(n_a, n_b))
    return (nbrs_a @ w @ p @ nbrs_b.T).tocsr()


def lapmod_assignment(cost: sp.csr_matrix) -> np.ndarray:
    """``lap.lapmod`` on the nonnegative minimisation cost ``max - cost``."""
    import lap

    cc = (cost.data.max() - cost.data).astype(np.float64)
    ii = cost.indptr.astype(np.int32)
    kk = cost.indices.astype(np.int32)
    x, _ = lap.lapmod(cost.shape[0], cc, ii, kk, return_cost=False)
    return x


def scipy_matching(cost: sp.csr_matrix) -> np.ndarray:
    """``min_weight_full_bipartite_matching`` on the positive cost ``max + 1 - cost``."""
    from scipy.sparse.csgraph import min_weight_full_bipartite_matching

    shifted = sp.csr_matrix(
        (cost.data.max() + 1 - cost.data, cost.indices, cost.indptr), shape=cost.shape
    )
    rows, cols = min_weight_full_bipartite_matching(shifted)
    out = np.full(cost.shape[0], -1, dtype=np.int64)
    out[rows] = cols
    return out


# ----------------------------------------------------------------------------- checks


def same_pattern(ours: sp.csr_matrix, peer: sp.csr_matrix) -> bool:
    return ours.shape == peer.shape and (ours.astype(bool) != peer.astype(bool)).nnz == 0


def same_values(ours: sp.csr_matrix, peer: sp.csr_matrix) -> bool:
    peer = peer.copy()
    peer.eliminate_zeros()
    return ours.shape == peer.shape and (ours.astype(np.int64) != peer.astype(np.int64)).nnz == 0


def assignment_total(cost: sp.csr_matrix, cols) -> int | None:
    """Total of a full assignment within the pattern of ``cost``, None if it is not one."""
    n = cost.shape[0]
    cols = np.asarray(cols, dtype=np.int64)
    if cols.shape != (n,) or cols.min() < 0 or np.unique(cols).size != n:
        return None
    rows = np.repeat(np.arange(n), np.diff(cost.indptr))
    hit = cost.indices == cols[rows]
    if np.count_nonzero(hit) != n:
        return None
    return int(cost.data[hit].sum())


# ----------------------------------------------------------------------------- timing


def best_time(fn, repeats: int, budget_s: float = 30.0):
    """Best wall time of up to ``repeats`` calls (fewer once ``budget_s`` is spent)."""
    best, spent, result = float("inf"), 0.0, None
    for _ in range(repeats):
        result = None
        t0 = time.perf_counter()
        result = fn()
        dt = time.perf_counter() - t0
        best, spent = min(best, dt), spent + dt
        if spent > budget_s:
            break
    return best, result


def fmt_s(t: float | None) -> str:
    if t is None:
        return "skipped"
    return f"{t:.4f}" if t < 1 else f"{t:.2f}"


def fmt_ratio(peer: float | None, ours: float) -> str:
    return "-" if peer is None else f"{peer / ours:.2f}x"


# ----------------------------------------------------------------------------- benchmarks


@dataclass
class Tables:
    khop: list[list[str]] = field(default_factory=list)
    cost: list[list[str]] = field(default_factory=list)
    assign: list[list[str]] = field(default_factory=list)


def table_row(pair: Pair, k: int, matrix, *cells: str) -> list[str]:
    """mesh, n, k, nnz/row of ``matrix``, then ``cells``."""
    return [pair.name, str(pair.n), str(k), f"{matrix.nnz / pair.n:.1f}", *cells]


def bench_khop(pair: Pair, k: int, repeats: int, tables: Tables):
    t_ours, (na, nb) = best_time(
        lambda: (
            hope_rs.khop_neighbourhoods(pair.faces_a, k, n_vertices=pair.n),
            hope_rs.khop_neighbourhoods(pair.faces_b, k, n_vertices=pair.n),
        ),
        repeats,
    )
    t_peer, (pa, pb) = best_time(
        lambda: (scipy_khop(pair.faces_a, pair.n, k), scipy_khop(pair.faces_b, pair.n, k)),
        repeats,
    )
    ok = same_pattern(na, pa) and same_pattern(nb, pb)
    check = "ok" if ok else "**DIFFERENT**"
    tables.khop.append(
        table_row(pair, k, na, fmt_s(t_ours), fmt_s(t_peer), fmt_ratio(t_peer, t_ours), check)
    )
    return na, nb


def bench_cost(pair: Pair, k: int, na, nb, f, w, repeats: int, tables: Tables):
    t_ours, k_ours = best_time(lambda: hope_rs.overlap_cost(na, nb, f, w), repeats)
    t_keep, k_keep = best_time(lambda: hope_rs.overlap_cost(na, nb, f, w, keep=f), repeats)
    t_peer, k_peer = best_time(lambda: scipy_overlap(na, nb, f, w), repeats)
    ok = same_values(k_ours, k_peer)
    times = (fmt_s(t_ours), fmt_s(t_keep), fmt_s(t_peer), fmt_ratio(t_peer, t_ours))
    tables.cost.append(table_row(pair, k, k_ours, *times, "ok" if ok else "**DIFFERENT**"))
    return k_keep


def bench_assignment(pair: Pair, k: int, cost, repeats: int, slow_peers: bool, tables: Tables):
    t_ours, x_ours = best_time(lambda: hope_rs.auction_assignment(cost), repeats)
    t_lap, x_lap = best_time(lambda: lapmod_assignment(cost), repeats)
    t_sci, x_sci = None, None
    if slow_peers or pair.n <= SCIPY_MATCHING_MAX_N:
        t_sci, x_sci = best_time(lambda: scipy_matching(cost), repeats)
    totals = {
        "ours": assignment_total(cost, x_ours),
        "lapmod": assignment_total(cost, x_lap),
        "scipy": None if x_sci is None else assignment_total(cost, x_sci),
    }
    times = (fmt_s(t_ours), fmt_s(t_lap), fmt_ratio(t_lap, t_ours))
    times += (fmt_s(t_sci), fmt_ratio(t_sci, t_ours))
    tables.assign.append(table_row(pair, k, cost, *times, check_totals(totals, x_sci is not None)))


def check_totals(totals: dict, with_scipy: bool) -> str:
    ours, lap_total = totals["ours"], totals["lapmod"]
    if ours is None:
        return "**ours: not a full assignment**"
    if lap_total is None:
        return f"**{ours}, lapmod invalid**"
    if with_scipy and totals["scipy"] != ours:
        return f"**ours {ours} vs scipy {totals['scipy']}**"
    if ours != lap_total:
        return f"**ours {ours} vs lapmod {lap_total}**"
    return f"{ours} = optimum"


def bench_pair(pair: Pair, ks, args, tables: Tables) -> dict:
    """Time all kernels of one pair for each k; return the inputs at the largest k."""
    rng = np.random.default_rng(args.seed)
    f, w = perturbed_identity(pair.n, rng)
    inputs = {}
    for k in ks:
        na, nb = bench_khop(pair, k, args.repeats, tables)
        k_keep = bench_cost(pair, k, na, nb, f, w, args.repeats, tables)
        cost = assignment_cost(k_keep, f)
        bench_assignment(pair, k, cost, args.repeats, args.slow_peers, tables)
        print(f"  {pair.name} k={k} done (load {os.getloadavg()[0]:.2f})", file=sys.stderr)
        if k == max(ks):
            inputs = {"k": k, "na": na, "nb": nb, "f": f, "w": w, "cost": cost}
    return inputs


# ----------------------------------------------------------------------------- peak memory


def _status_mib(key: str, pid: int | str = "self") -> float:
    """``VmRSS`` (current) or ``VmHWM`` (peak) of a process from /proc, in MiB."""
    with open(f"/proc/{pid}/status") as fh:
        for line in fh:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024
    return 0.0


def _reset_peak_rss() -> bool:
    """Restart ``VmHWM`` from the current RSS (Linux >= 4.0); False if not allowed."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
    except OSError:
        return False
    return True


def save_inputs(path: Path, inputs: dict) -> None:
    arrays = {"f": inputs["f"], "w": inputs["w"]}
    for name in ("na", "nb", "cost"):
        m = inputs[name]
        arrays.update({f"{name}_indptr": m.indptr, f"{name}_indices": m.indices})
        arrays.update({f"{name}_data": m.data, f"{name}_shape": np.array(m.shape)})
    np.savez(path, **arrays)


def _load_csr(z, name: str) -> sp.csr_matrix:
    parts = (z[f"{name}_data"], z[f"{name}_indices"], z[f"{name}_indptr"])
    return sp.csr_matrix(parts, shape=tuple(z[f"{name}_shape"]))


def _child_job(spec: dict, mesh_a):
    """The call to measure in the child, with its inputs already loaded."""
    job, k = spec["job"], spec["k"]
    if job == "baseline":
        return lambda: None
    if job in ("khop", "khop_scipy"):
        faces_a, n = mesh_a.faces, mesh_a.n_vertices
        if job == "khop":
            return lambda: hope_rs.khop_neighbourhoods(faces_a, k, n_vertices=n)
        return lambda: scipy_khop(faces_a, n, k)
    z = np.load(spec["inputs"])
    f, w = z["f"], z["w"]
    if job in ("auction", "lapmod"):
        cost = _load_csr(z, "cost")
        return (
            (lambda: hope_rs.auction_assignment(cost))
            if job == "auction"
            else (lambda: lapmod_assignment(cost))
        )
    na, nb = _load_csr(z, "na"), _load_csr(z, "nb")
    if job == "overlap_scipy":
        return lambda: scipy_overlap(na, nb, f, w)
    if spec.get("all_witnesses"):
        w = np.ones_like(w)
    return lambda: hope_rs.overlap_cost(na, nb, f, w, top_k=spec.get("top_k"), keep=f)


def child_main(spec_json: str) -> None:
    """Entry point of the measuring subprocess: load, call one kernel, print JSON."""
    spec = json.loads(spec_json)
    meshes = [load_mesh(p) for p in spec["meshes"]]
    run = _child_job(spec, meshes[0])
    load_peak, before = _status_mib("VmHWM"), _status_mib("VmRSS")
    reset = _reset_peak_rss()
    if spec.get("time_limit"):
        signal.alarm(spec["time_limit"])  # default action of SIGALRM ends the process
    t0 = time.perf_counter()
    result = run()
    seconds = time.perf_counter() - t0
    signal.alarm(0)
    call_peak = _status_mib("VmHWM")
    out = {
        "seconds": seconds,
        "peak_mib": max(load_peak, call_peak),
        "rss_before_mib": before,
        "call_peak_mib": call_peak if reset else None,
        "nnz_per_row": result.nnz / result.shape[0] if sp.issparse(result) else None,
    }
    print(json.dumps(out))


@dataclass
class ChildResult:
    out: dict | None
    note: str = ""
    seen_peak_mib: float = 0.0


def run_child(spec: dict, rss_limit_mib: float | None = None) -> ChildResult:
    """Run one job in a fresh interpreter, killing it once its RSS exceeds ``rss_limit_mib``.

    The peak is the child's own ``VmHWM``: ``ru_maxrss`` of a fork+exec child (from
    ``os.wait4`` or ``RUSAGE_CHILDREN``) would include the parent's peak, which Linux carries
    over the exec.
    """
    code = (
        f"import sys; sys.path.insert(0, {str(BENCH_DIR)!r}); "
        "import bench_kernels; bench_kernels.child_main(sys.argv[1])"
    )
    proc = subprocess.Popen(
        [sys.executable, "-B", "-c", code, json.dumps(spec)], stdout=subprocess.PIPE
    )
    note, seen = "", 0.0
    while proc.poll() is None:
        try:
            seen = max(seen, _status_mib("VmHWM", proc.pid))
        except OSError:  # exited between poll() and the read
            continue
        if rss_limit_mib and not note and seen > rss_limit_mib:
            proc.kill()
            note = f"skipped (RSS > {rss_limit_mib / 1024:.0f} GiB)"
        time.sleep(0.02)
    text = proc.stdout.read().decode()
    proc.stdout.close()
    if proc.returncode == -signal.SIGALRM:
        note = f"skipped (> {spec['time_limit']} s)"
    elif proc.returncode != 0 and not note:
        note = f"failed (exit {proc.returncode})"
    out = json.loads(text.strip().splitlines()[-1]) if proc.returncode == 0 else None
    return ChildResult(out, note, seen)


def memory_tables(pair: Pair, inputs: dict) -> list[str]:
    """Peak RSS of each kernel (and peer) at the largest k, plus the all-witness case."""
    k = inputs["k"]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "inputs.npz"
        save_inputs(path, inputs)
        base = {"meshes": [str(p) for p in pair.paths], "inputs": str(path), "k": k}
        jobs = [
            ("baseline: import hope_rs + load meshes", "baseline", {}),
            ("khop_neighbourhoods (one mesh)", "khop", {}),
            ("peer: scipy (A+I)^k (one mesh)", "khop_scipy", {}),
            ("overlap_cost keep=f", "overlap", {}),
            ("peer: scipy Na diag(w) P Nb^T", "overlap_scipy", {}),
            ("auction_assignment", "auction", {}),
            ("peer: lap.lapmod", "lapmod", {}),
        ]
        mem_rows = [
            _memory_row(label, run_child({**base, "job": job, **extra}))
            for label, job, extra in jobs
        ]
        witness_rows = [
            _witness_row(
                f"top_k={ALL_WITNESS_TOP_K}, keep=f", {**base, "top_k": ALL_WITNESS_TOP_K}
            ),
            _witness_row("no top_k, keep=f", {**base, "time_limit": CHILD_TIME_LIMIT_S}),
        ]
    title = f"{pair.name} (n = {pair.n}), k = {k}"
    mem = markdown_table(
        ["case", "peak RSS", "RSS before call", "peak during call", "call (s)"], mem_rows
    )
    wit = markdown_table(
        ["overlap_cost, all witnesses", "time (s)", "nnz/row", "peak RSS (MiB)"], witness_rows
    )
    return [
        f"### Peak memory, {title}",
        (
            "Each row is a fresh `python -c` process: import, load meshes and precomputed "
            "inputs, one call. Peak RSS = `VmHWM` of that process over its whole life; "
            "peak during call = `VmHWM` reset (`/proc/self/clear_refs`) just before the call. "
            "All in MiB."
        ),
        mem,
        f"### Every vertex a witness, {title}",
        (
            f"Limits for the run without top_k: {CHILD_TIME_LIMIT_S} s, "
            f"{CHILD_RSS_LIMIT_MIB // 1024} GiB RSS; single run in a fresh process."
        ),
        wit,
    ]


def _memory_row(label: str, res: ChildResult) -> list[str]:
    if res.out is None:
        return [label, res.note, "-", "-", "-"]
    o = res.out
    if label.startswith("baseline"):
        return [label, f"{o['peak_mib']:.0f}", f"{o['rss_before_mib']:.0f}", "-", "-"]
    call_peak = "n/a" if o["call_peak_mib"] is None else f"{o['call_peak_mib']:.0f}"
    cells = (f"{o['peak_mib']:.0f}", f"{o['rss_before_mib']:.0f}", call_peak)
    return [label, *cells, fmt_s(o["seconds"])]


def _witness_row(label: str, spec: dict) -> list[str]:
    res = run_child({**spec, "job": "overlap", "all_witnesses": True}, CHILD_RSS_LIMIT_MIB)
    if res.out is None:
        return [label, res.note, "-", f"(reached {res.seen_peak_mib:.0f})"]
    o = res.out
    return [label, fmt_s(o["seconds"]), f"{o['nnz_per_row']:.1f}", f"{o['peak_mib']:.0f}"]


# ----------------------------------------------------------------------------- output


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = [header, ["-" * w for w in widths], *rows]
    return "\n".join(
        "| " + " | ".join(c.ljust(w) for c, w in zip(line, widths)) + " |" for line in lines
    )


def environment_lines(args, argv: list[str]) -> list[str]:
    import lap

    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    threads = os.environ.get("RAYON_NUM_THREADS", f"all {os.cpu_count()} cores")
    versions = (
        f"python {platform.python_version()}, hope_rs {hope_rs.__version__}, "
        f"numpy {np.__version__}, scipy {scipy.__version__}, lap {lap.__version__}"
    )
    timing = (
        f"best of up to {args.repeats} runs (fewer when a case takes > 30 s); f = identity with "
        f"{SHUFFLED_FRACTION:.0%} shuffled (seed {args.seed}); k-hop times cover both meshes"
    )
    return [
        f"- command: `python {' '.join(argv)}`",
        f"- load average at start (1, 5, 15 min): {load}; {os.cpu_count()} CPUs",
        f"- {versions}",
        f"- Rust kernels: rayon threads = {threads}; peers are single-threaded",
        f"- times: {timing}",
    ]


def result_tables(tables: Tables) -> list[str]:
    return [
        "### k-hop neighbourhoods (both meshes)",
        markdown_table(
            ["mesh", "n", "k", "nnz/row", "ours (s)", "scipy (A+I)^k (s)", "peer/ours", "equal"],
            tables.khop,
        ),
        "### Overlap cost (witnesses = 80%)",
        markdown_table(
            [
                "mesh",
                "n",
                "k",
                "nnz/row",
                "ours (s)",
                "ours keep=f (s)",
                "scipy Na W P Nb^T (s)",
                "peer/ours",
                "equal",
            ],
            tables.cost,
        ),
        "### Assignment on 4K + bonus (maximise)",
        markdown_table(
            [
                "mesh",
                "n",
                "k",
                "nnz/row",
                "ours (s)",
                "lapmod (s)",
                "lapmod/ours",
                "scipy matching (s)",
                "scipy/ours",
                "total",
            ],
            tables.assign,
        ),
    ]


# ----------------------------------------------------------------------------- main


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, default=DEFAULT_DATA, help="data directory")
    p.add_argument("--quick", action="store_true", help="FAUST only, k in {1, 4, 8} (CI smoke)")
    p.add_argument("--k", type=_parse_ks, default=None, help="comma-separated k (default 1..8)")
    p.add_argument("--out", type=Path, default=None, help="also write the Markdown here")
    p.add_argument("--repeats", type=int, default=3, help="timing repeats (best is kept)")
    p.add_argument("--seed", type=int, default=0, help="seed of the shuffled 20%%")
    p.add_argument(
        "--slow-peers",
        action="store_true",
        help=f"run scipy's matching also for n > {SCIPY_MATCHING_MAX_N}",
    )
    p.add_argument("--no-memory", action="store_true", help="skip the peak-memory tables")
    return p.parse_args(argv)


def _parse_ks(text: str) -> tuple[int, ...]:
    try:
        ks = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers, got {text!r}"
        ) from None
    if not ks or min(ks) < 0 or max(ks) > 255:
        raise argparse.ArgumentTypeError("k must be in [0, 255]")
    return ks


def main(argv=None) -> None:
    args = parse_args(argv)
    ks = args.k or (QUICK_KS if args.quick else tuple(range(1, 9)))
    names = QUICK_PAIRS if args.quick else tuple(PAIRS)
    header = "\n".join(environment_lines(args, sys.argv))
    print(header, file=sys.stderr, flush=True)
    tables, largest = Tables(), None
    for name in names:
        pair = load_pair(name, args.data)
        inputs = bench_pair(pair, ks, args, tables)
        if largest is None or pair.n > largest[0].n:
            largest = (pair, inputs)
    sections = ["## hope_rs kernel benchmark", header, *result_tables(tables)]
    if not args.no_memory:
        sections += memory_tables(*largest)
    sections.append(f"- load average at end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    text = "\n\n".join(sections) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
