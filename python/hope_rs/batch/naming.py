"""Map file names of a batch: unique and inside the output folder by construction.

A pair's file is ``<a>__<b>.txt`` (or ``.npy``) from the two shapes' names, each made safe:
characters other than letters, digits, ``_ . + -`` become ``_``, a leading dot becomes ``_``
(no hidden files, no ``..``), and a name is cut to :data:`STEM_BYTES` bytes. A name that had
to be changed, or that another pair's name equals (letter case ignored, as some file systems
do), gets ``-`` and the first 8 hex digits of a SHA-256 of the pair's identity (the shapes'
absolute paths, dict keys or positions). Names that are still not unique (the same pair listed
twice) are refused before any work.
"""

from __future__ import annotations

import hashlib
import re
import unicodedata
from collections import Counter

__all__ = ["MAP_FORMATS", "STEM_BYTES", "map_name", "map_names", "safe_stem"]

#: Map file formats of a batch and their suffixes.
MAP_FORMATS = {"txt": ".txt", "npy": ".npy"}
#: Longest shape name in a file name, in UTF-8 bytes: two of them, the separator, the digest
#: suffix and the file suffix stay well below the 255 bytes file systems allow.
STEM_BYTES = 100
_UNSAFE = re.compile(r"[^\w.+-]")


def safe_stem(name: str) -> tuple[str, bool]:
    """``name`` made safe as part of a file name, and whether that changed it."""
    s = _UNSAFE.sub("_", unicodedata.normalize("NFC", str(name)))
    s = re.sub(r"^\.+", lambda m: "_" * len(m.group()), s) or "_"
    raw = s.encode("utf-8")
    if len(raw) > STEM_BYTES:
        s = raw[:STEM_BYTES].decode("utf-8", errors="ignore")
    return s, s != name


def map_name(a: str, b: str, map_format: str = "txt") -> str:
    """File name of the map of pair (a, b) when no other pair's name collides with it (see
    :func:`map_names` for the names of a whole batch)."""
    return map_names([(a, b)], [(a, b)], map_format)[0]


def map_names(names: list[tuple[str, str]], identities: list[tuple[str, str]], map_format: str):
    """One file name per pair: ``names`` are the pairs' shape names, ``identities`` what tells
    their shapes apart (absolute paths, dict keys as ``repr``, positions). ValueError when two
    pairs would still share a file."""
    suffix = MAP_FORMATS[map_format]
    plain, changed = [], []
    for a, b in names:
        (sa, ca), (sb, cb) = safe_stem(a), safe_stem(b)
        plain.append(f"{sa}__{sb}")
        changed.append(ca or cb)
    seen = Counter(p.casefold() for p in plain)
    out = []
    for p, c, ident in zip(plain, changed, identities):
        if c or seen[p.casefold()] > 1:
            digest = hashlib.sha256(
                "\0".join(map(str, ident)).encode("utf-8", "surrogatepass")
            ).hexdigest()
            p = f"{p}-{digest[:8]}"
        out.append(p + suffix)
    first: dict[str, int] = {}
    for n, name in enumerate(out):
        other = first.setdefault(name.casefold(), n)
        if other != n:
            raise ValueError(
                f"pairs {other} and {n} ({names[n][0]} -> {names[n][1]}) would both write the "
                f"map file {name!r}; list each pair once"
            )
    return out
