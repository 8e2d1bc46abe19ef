#!/usr/bin/env bash
# Release artefacts into OUT_DIR: a manylinux wheel (abi3, one wheel for CPython >= 3.9) and an
# sdist. The wheel is linked by zig against glibc 2.17 symbols (manylinux2014), whatever the
# host's glibc; `auditwheel show` must then report a manylinux tag. The sdist must hold what a
# build needs and no results or CI files, and must itself build into a wheel with plain pip.
#
# Needs only python3 and cargo: the build tools go into their own venv (HOPE_BUILD_VENV,
# default .venv-build, reused on later runs). The Rust target dir is shared with the other
# builds (CARGO_TARGET_DIR, default ./target), so dependencies compile once.
set -euo pipefail

if [[ $# -ne 1 ]]; then
    echo "usage: scripts/build_wheel.sh OUT_DIR" >&2
    exit 2
fi
REPO="$(cd "$(dirname "$0")/.." && pwd)"
mkdir -p "$1"
OUT="$(cd "$1" && pwd)"
cd "$REPO"

BUILD_VENV="${HOPE_BUILD_VENV:-$REPO/.venv-build}"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$REPO/target}"
# Pinned so a release build is reproducible; ziglang is zig itself, shipped as a PyPI wheel.
TOOLS=("maturin==1.16.0" "ziglang==0.17.1" "auditwheel==6.8.2")

if [[ ! -x "$BUILD_VENV/bin/python" ]]; then
    python3 -m venv "$BUILD_VENV"
fi
"$BUILD_VENV/bin/python" -m pip install -q --disable-pip-version-check "${TOOLS[@]}"
# maturin finds zig as `python3 -m ziglang`, so the venv's python3 must come first on PATH.
export PATH="$BUILD_VENV/bin:$PATH"

STAGE="$(mktemp -d)"
trap 'rm -rf "$STAGE"' EXIT

echo "== wheel (manylinux2014 via zig)"
maturin build --release --zig --compatibility manylinux2014 --out "$STAGE/wheel"
wheels=("$STAGE"/wheel/*.whl)
if [[ ${#wheels[@]} -ne 1 ]]; then
    echo "build_wheel: expected one wheel, got: ${wheels[*]}" >&2
    exit 1
fi
WHEEL="${wheels[0]}"
auditwheel show "$WHEEL" | tee "$STAGE/auditwheel.txt"
# auditwheel prints the most compatible tag the symbols allow; anything but manylinux fails.
if ! tr '\n' ' ' <"$STAGE/auditwheel.txt" | grep -Eq 'consistent with the following platform tag: +"manylinux_[0-9]+_[0-9]+_x86_64"'; then
    echo "build_wheel: auditwheel does not report a manylinux tag for $(basename "$WHEEL")" >&2
    exit 1
fi
python scripts/check_dist.py wheel "$WHEEL"

echo "== sdist"
maturin sdist --out "$STAGE/sdist"
sdists=("$STAGE"/sdist/*.tar.gz)
SDIST="${sdists[0]}"
python scripts/check_dist.py sdist "$SDIST"

echo "== wheel from the sdist (pip, isolated build, outside the source tree)"
mkdir "$STAGE/from-sdist"
(cd "$STAGE/from-sdist" && python -m pip wheel -q --disable-pip-version-check --no-deps \
    -w "$STAGE/from-sdist" "$SDIST")
python scripts/check_dist.py wheel-any "$STAGE"/from-sdist/hope_rs-*.whl

cp "$WHEEL" "$SDIST" "$OUT"/
echo "build_wheel: wrote $OUT/$(basename "$WHEEL") and $OUT/$(basename "$SDIST")"
