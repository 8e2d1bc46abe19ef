"""Check a built sdist or wheel of hope-rs: the files a build or an install needs are inside,
benchmark results and CI files are not, and the wheel's metadata carries the licence.

Usage: ``python scripts/check_dist.py sdist DIST.tar.gz``, ``... wheel DIST.whl`` (a release
wheel: abi3 and manylinux) or ``... wheel-any DIST.whl`` (any platform tag, e.g. a local build).
Prints one line per problem and exits 1 if there is any. Standard library only, so it runs
under any Python 3.9+.
"""

from __future__ import annotations

import re
import sys
import tarfile
import zipfile
from pathlib import Path, PurePosixPath

__all__ = ["main", "sdist_problems", "wheel_problems"]

# Relative to the sdist's top folder: what `pip wheel` from the sdist needs.
SDIST_REQUIRED = (
    "Cargo.toml",
    "Cargo.lock",
    "pyproject.toml",
    "README.md",
    "LICENSE",
    "PKG-INFO",
    "src/lib.rs",
    "src/python/mod.rs",
    "python/hope_rs/__init__.py",
    "python/hope_rs/_core.pyi",
    "python/hope_rs/py.typed",
)
# Top-level folders that are results or tooling, not source.
SDIST_FORBIDDEN_DIRS = (".ci", "benches", "docs", "target", "bench-results", ".github")
# File suffixes that never belong in a source release: plots and compiled objects.
FORBIDDEN_SUFFIXES = (".png", ".jpg", ".so", ".pyc")

# Besides every module of the source tree (see ``source_modules``).
WHEEL_REQUIRED = (
    "hope_rs/__init__.py",
    "hope_rs/cli/__main__.py",
    "hope_rs/_core.pyi",
    "hope_rs/py.typed",
    "hope_rs/data/faust_012_018.npz",
    "hope_rs/data/faust_r_000_001.npz",
)


def source_modules() -> tuple[str, ...]:
    """Every module of the package in this checkout, as wheel member paths."""
    root = Path(__file__).resolve().parents[1] / "python"
    return tuple(sorted(p.relative_to(root).as_posix() for p in (root / "hope_rs").rglob("*.py")))


def sdist_problems(names: list[str]) -> list[str]:
    """Problems with an sdist, given its member names.

    Parameters
    ----------
    names : list of str
        Member paths as ``tarfile.getnames()`` lists them (``hope_rs-X.Y.Z/...``).

    Returns
    -------
    list of str
        One message per missing required file or unwanted member; empty when fine.
    """
    tops = {n.split("/", 1)[0] for n in names}
    if len(tops) != 1:
        return [f"sdist must have exactly one top folder, found {sorted(tops)}"]
    rel = {n.split("/", 1)[1] for n in names if "/" in n}
    problems = [f"sdist lacks {r}" for r in SDIST_REQUIRED if r not in rel]
    for r in sorted(rel):
        parts = PurePosixPath(r).parts
        if (
            parts
            and parts[0] in SDIST_FORBIDDEN_DIRS
            or r.endswith(FORBIDDEN_SUFFIXES)
            or "__pycache__" in parts
        ):
            problems.append(f"sdist should not contain {r}")
    return problems


def wheel_problems(
    names: list[str], metadata: str, wheel_file: str, *, manylinux: bool = True
) -> list[str]:
    """Problems with a wheel, given its member names and its METADATA and WHEEL texts.

    Parameters
    ----------
    names : list of str
        Member paths as ``zipfile.namelist()`` lists them.
    metadata : str
        Text of ``*.dist-info/METADATA``.
    wheel_file : str
        Text of ``*.dist-info/WHEEL`` (holds the platform tags).
    manylinux : bool
        Require every tag to be abi3 + manylinux (a release wheel); otherwise only abi3.

    Returns
    -------
    list of str
        One message per problem; empty when fine.
    """
    required = dict.fromkeys((*WHEEL_REQUIRED, *source_modules()))
    problems = [f"wheel lacks {r}" for r in required if r not in names]
    if not any(re.fullmatch(r"hope_rs/_core\.abi3\.so", n) for n in names):
        problems.append("wheel lacks the compiled extension hope_rs/_core.abi3.so")
    if not any(re.fullmatch(r"[^/]+\.dist-info/licenses/LICENSE", n) for n in names):
        problems.append("wheel lacks .dist-info/licenses/LICENSE")
    if "License-Expression: MIT" not in metadata.splitlines():
        problems.append("METADATA lacks 'License-Expression: MIT'")
    if "License-File: LICENSE" not in metadata.splitlines():
        problems.append("METADATA lacks 'License-File: LICENSE'")
    tags = [ln.split(":", 1)[1].strip() for ln in wheel_file.splitlines() if ln.startswith("Tag:")]
    platform = r"manylinux(_\d+_\d+|1|2010|2014)_\w+" if manylinux else r"\w+"
    tag = re.compile(rf"cp3\d+-abi3-{platform}")
    if not tags or not all(tag.fullmatch(t) for t in tags):
        kind = "abi3 manylinux" if manylinux else "abi3"
        problems.append(f"wheel tags {tags} are not all {kind} tags")
    for n in names:
        if n.endswith((".pyc", ".png")) or "__pycache__" in n:
            problems.append(f"wheel should not contain {n}")
    return problems


def main(argv: list[str] | None = None) -> int:
    """Check one sdist or wheel; print the problems and return 1 if there are any."""
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2 or argv[0] not in ("sdist", "wheel", "wheel-any"):
        print("usage: check_dist.py sdist|wheel|wheel-any PATH", file=sys.stderr)
        return 2
    kind, path = argv
    if kind == "sdist":
        with tarfile.open(path) as tf:
            names = tf.getnames()
        problems = sdist_problems(names)
    else:
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
            meta = [n for n in names if re.fullmatch(r"[^/]+\.dist-info/METADATA", n)]
            if len(meta) != 1:
                print(f"check_dist: {path}: expected one .dist-info/METADATA, found {meta}")
                return 1
            dist_info = meta[0].rsplit("/", 1)[0]
            metadata = zf.read(f"{dist_info}/METADATA").decode()
            wheel_file = zf.read(f"{dist_info}/WHEEL").decode()
        problems = wheel_problems(names, metadata, wheel_file, manylinux=kind == "wheel")
    for p in problems:
        print(f"check_dist: {path}: {p}")
    if not problems:
        print(f"check_dist: {path}: ok ({len(names)} members)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
