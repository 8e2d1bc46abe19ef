#!/usr/bin/env bash
# The API reference, HTML generated from the docstrings by pdoc, into the folder given
# (default docs/api, not committed): the public package and every layer's modules.
# Warnings are errors, so a docstring or annotation pdoc cannot read fails the build.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-docs/api}"
PY="${HOPE_PYTHON:-python3}"
"$PY" -W error -W ignore::DeprecationWarning -m pdoc --docformat numpy --output-directory "$OUT" \
    hope_rs hope_rs.geometry hope_rs.kernels hope_rs.features hope_rs.shape hope_rs.pipeline \
    hope_rs.matching hope_rs.batch hope_rs.evaluation hope_rs.cli
echo "API reference: $OUT/index.html"
