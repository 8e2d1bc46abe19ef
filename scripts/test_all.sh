#!/usr/bin/env bash
# The whole test suite from a clean clone: fresh venv, release build of the extension, the
# quality gate (scripts/check.sh, first so that it fails fast), Rust unit tests, then pytest.
# Fails on the first failing step.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${HOPE_VENV:-.venv-test}"
python3 -m venv "$VENV"
"$VENV/bin/python" -m pip install -q --upgrade pip
"$VENV/bin/python" -m pip install -q -e '.[test]'
HOPE_VENV="$VENV" bash scripts/check.sh
cargo test --release
"$VENV/bin/python" -m pytest -q "$@"
