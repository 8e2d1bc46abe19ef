"""Commit, date, machine and load lines for the headers of generated documents."""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def git(*args: str) -> str:
    try:
        return subprocess.check_output(["git", *args], cwd=ROOT, text=True).strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"{cpu}, {cores} cores, Python {platform.python_version()}, {platform.system()}"


def load() -> str:
    try:
        return "load average " + ", ".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:
        return "load average unknown"


#: What the generators write: a change there is not a change to the code that ran.
GENERATED = (
    "docs/benchmarks.md",
    "docs/confidence.md",
    "docs/speed.md",
    "docs/results",
    "README.md",
)


def header() -> str:
    """The commit (marked when the tree has uncommitted changes outside the generated
    documents), the UTC date, the machine and the load average, one line each."""
    dirty = git(
        "status", "--porcelain", "--untracked-files=no", "--", ".",
        *(f":(exclude){p}" for p in GENERATED),
    )  # fmt: skip
    return (
        f"commit {git('rev-parse', '--short', 'HEAD')}{' (uncommitted changes)' if dirty else ''}\n"
        f"date {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC\n"
        f"machine {machine()}\n"
        f"{load()} at the start\n"
    )
