"""End-to-end ``hope_rs.match`` of one tree against another, alternately in one run.

Each round runs every pair in a fresh process per tree (``PYTHONPATH=<tree>/python``), the two
trees in alternating order; each process matches once to warm up and then ``--repeats`` times.
Prints per pair the median seconds of each tree, the ratio new / old, the same for the CPU
seconds of all the process's threads (steadier than wall time on a busy machine, though blind to
work that idles a core), and whether the two trees' maps are bit-identical (SHA-256 of
``res.map``)::

    python benches/bench_against.py --old /work/main --pairs faust_r/tr_reg_000:faust_r/tr_reg_001
    python benches/bench_against.py --old /work/main --rounds 5   # the default pairs

``--new`` defaults to the tree this file is in.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data"
DEFAULT_PAIRS = ("faust_r/tr_reg_000:faust_r/tr_reg_001", "tosca_r/cat0:tosca_r/cat1")

CHILD = """
import hashlib, json, sys, time
import numpy as np
import hope_rs
a, b, repeats = hope_rs.load_mesh(sys.argv[1]), hope_rs.load_mesh(sys.argv[2]), int(sys.argv[3])
res = hope_rs.match(a, b)
times, cpu = [], []
for _ in range(repeats):
    t, c = time.perf_counter(), time.process_time()
    res = hope_rs.match(a, b)
    times.append(time.perf_counter() - t)
    cpu.append(time.process_time() - c)
m = np.ascontiguousarray(res.map, dtype=np.int64)
stages = {k: v for k, v in res.timings.items()}
print(json.dumps({"times": times, "cpu": cpu, "sha": hashlib.sha256(m.tobytes()).hexdigest(),
                  "file": hope_rs.__file__, "timings": stages}))
"""


def run(tree: Path, a: Path, b: Path, repeats: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree / "python"))
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(a), str(b), str(repeats)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    r = json.loads(out.stdout.strip().splitlines()[-1])
    if not r["file"].startswith(str(tree)):
        raise RuntimeError(f"{tree}: imported hope_rs from {r['file']}")
    return r


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--old", type=Path, required=True, help="the tree to compare against")
    p.add_argument("--new", type=Path, default=ROOT)
    p.add_argument("--data", type=Path, default=DEFAULT_DATA)
    p.add_argument("--pairs", nargs="*", default=list(DEFAULT_PAIRS), help="A:B paths, no .off")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--repeats", type=int, default=2, help="timed matches per process")
    args = p.parse_args(argv)
    print(f"load average at the start: {os.getloadavg()}")
    for spec in args.pairs:
        a, b = (args.data / f"{x}.off" for x in spec.split(":"))
        times: dict[str, list[float]] = {"old": [], "new": []}
        cpu: dict[str, list[float]] = {"old": [], "new": []}
        stages: dict[str, list[dict]] = {"old": [], "new": []}
        shas: dict[str, set[str]] = {"old": set(), "new": set()}
        for rnd in range(args.rounds):
            order = ("old", "new") if rnd % 2 == 0 else ("new", "old")
            for side in order:
                r = run(args.old if side == "old" else args.new, a, b, args.repeats)
                times[side] += r["times"]
                cpu[side] += r["cpu"]
                stages[side].append(r["timings"])
                shas[side].add(r["sha"])
        mo, mn = statistics.median(times["old"]), statistics.median(times["new"])
        same = shas["old"] == shas["new"] and len(shas["old"]) == 1
        print(
            f"{spec}: old median {mo:.2f} s, new median {mn:.2f} s, new / old {mn / mo:.2f} "
            f"({len(times['old'])} timings each); maps {'identical' if same else 'DIFFER'}"
        )
        co, cn = statistics.median(cpu["old"]), statistics.median(cpu["new"])
        print(
            f"    CPU seconds (all threads): old median {co:.2f}, new median {cn:.2f}, "
            f"new / old {cn / co:.2f}"
        )
        for key in sorted(stages["new"][0]):
            so = statistics.median(s.get(key, 0.0) for s in stages["old"])
            sn = statistics.median(s.get(key, 0.0) for s in stages["new"])
            print(f"    {key:>16}: old {so:.3f} s, new {sn:.3f} s")
    print(f"load average at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
