#!/usr/bin/env bash
# The quality gate: run it before committing; CI runs it first, before the test suite.
# Python lint and format (ruff), types (mypy), the docstring examples, the hand-written stub of
# the native module against the built one (stubtest), the API reference (warnings are errors),
# then Rust format and lints (clippy, warnings are errors) with and without the python feature.
# Needs the test extra in the venv (pip install -e '.[test]', as scripts/test_all.sh does) and
# Python >= 3.10 for the tools (the package's 3.9 syntax is held by ruff's target-version).
# Fails on the first failing check.
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${HOPE_PYTHON:-${HOPE_VENV:-.venv-test}/bin/python}"
t0=$SECONDS
step() { echo "== check: $*"; }

step ruff check
"$PY" -m ruff check .
step ruff format --check
"$PY" -m ruff format --check .
step mypy
"$PY" -m mypy
step "stubtest (python/hope_rs/_core.pyi against the built module)"
MYPYPATH=python "$PY" -m mypy.stubtest hope_rs._core
step "docstring examples"
"$PY" -m pytest -q -p no:cacheprovider --doctest-modules python/hope_rs
step "API reference"
DOCS="$(mktemp -d)"
trap 'rm -rf "$DOCS"' EXIT
HOPE_PYTHON="$PY" bash scripts/api_docs.sh "$DOCS" >/dev/null

if command -v rustup >/dev/null; then
    installed="$(rustup component list --installed)"
    for c in rustfmt clippy; do
        grep -q "^$c" <<<"$installed" || rustup component add "$c"
    done
fi
step cargo fmt --check
cargo fmt --check
step "cargo clippy (pure core)"
cargo clippy --quiet --all-targets -- -D warnings
step "cargo clippy (python feature)"
cargo clippy --quiet --all-targets --features python -- -D warnings
echo "check: all passed in $((SECONDS - t0)) s"
