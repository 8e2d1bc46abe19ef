#!/usr/bin/env bash
# The whole test suite from a clean clone: fresh venv, release build of the extension, the
# quality gate (scripts/check.sh, first so that it fails fast), Rust unit tests, then pytest
# (the slowest tests listed at the end).
# Fails on the first failing step.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${HOPE_VENV:-.venv-test}"
python3 -m venv "$VENV"
"$VENV/bin/python" -m pip install -q --upgrade pip
"$VENV/bin/python" -m pip install -q -e '.[test]'
HOPE_VENV="$VENV" bash scripts/check.sh
cargo test --release
# Two workers (pytest-xdist): most of a test's time is single-threaded Python, so the two
# cores of a small machine run two tests at once; HOPE_TEST_WORKERS=0 runs them in one process.
"$VENV/bin/python" -m pytest -q -n "${HOPE_TEST_WORKERS:-2}" --durations=15 "$@"
