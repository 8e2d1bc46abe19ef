"""A 5k match on a quiet machine and beside busy processes, in one run: the contention ratio.

Users run ``hope_rs.match`` next to other work (a notebook beside a build, a ``joblib`` loop, a
shared server, CI). This bench times the default ``match`` of a remeshed FAUST pair in a fresh
process, alternating quiet runs with runs while ``--busy`` other processes (default: one per
core) spin on the CPU, and prints the medians and their ratio. A fair share of the machine
gives a ratio near (busy + 1) / 1 only when our process could use every core alone; on 2
cores with 2 busy processes, about 2.

    python benches/bench_contention.py                 # 3 rounds, spectral pass on
    python benches/bench_contention.py --rounds 5 --no-spectral
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"

CHILD = """
import sys, time
import hope_rs
a, b = hope_rs.load_mesh(sys.argv[1]), hope_rs.load_mesh(sys.argv[2])
t = time.perf_counter()
hope_rs.match(a, b, spectral=sys.argv[3] == "1")
print(time.perf_counter() - t)
"""


def timed_match(a: Path, b: Path, spectral: bool) -> float:
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(a), str(b), "1" if spectral else "0"],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    return float(out.stdout.strip().splitlines()[-1])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=os.environ.get("HOPE_DATA", DEFAULT_DATA), type=Path)
    p.add_argument("--pair", default="tr_reg_000,tr_reg_001", help="two faust_r shapes")
    p.add_argument("--rounds", type=int, default=3, help="quiet/busy runs each (median)")
    p.add_argument("--busy", type=int, default=os.cpu_count() or 2, help="busy processes")
    p.add_argument("--no-spectral", action="store_true", help="match(..., spectral=False)")
    args = p.parse_args()
    a, b = (args.data / "faust_r" / f"{n}.off" for n in args.pair.split(","))
    spectral = not args.no_spectral
    timed_match(a, b, spectral)  # warm the file cache and the extension
    quiet, busy = [], []
    for r in range(args.rounds):
        quiet.append(timed_match(a, b, spectral))
        spinners = [
            subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)
        ]
        try:
            busy.append(timed_match(a, b, spectral))
        finally:
            for s in spinners:
                s.kill()
                s.wait()
        print(f"round {r + 1}: quiet {quiet[-1]:.2f} s, beside {args.busy} busy {busy[-1]:.2f} s")
    q, loaded = statistics.median(quiet), statistics.median(busy)
    print(
        f"match {a.stem} -> {b.stem} (spectral={spectral}): quiet median {q:.2f} s, "
        f"beside {args.busy} busy processes median {loaded:.2f} s, ratio {loaded / q:.1f}x"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
