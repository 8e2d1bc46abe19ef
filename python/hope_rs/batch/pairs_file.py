"""Pairs files: one pair of mesh paths a line (and optionally the pair's landmark file)."""

from __future__ import annotations

import os
import shlex
from pathlib import Path
from typing import Literal, overload

import numpy as np

from ..geometry.map_io import read_landmarks
from ..geometry.readers import READERS
from ..pipeline.landmarks import check_landmarks

__all__ = ["all_pairs", "landmark_files", "read_pairs", "strip_comment"]


def strip_comment(line: str) -> str:
    """``line`` without its comment: a ``#`` starts one only at the start of the line or after
    white space, and not inside quotes (``scan#2.off`` and ``"a #b.off"`` are paths)."""
    quote = None
    escaped = False
    for i, c in enumerate(line):
        if escaped:
            escaped = False
        elif c == "\\" and quote != "'":
            escaped = True
        elif quote is not None:
            if c == quote:
                quote = None
        elif c in "'\"":
            quote = c
        elif c == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i]
    return line


def _pair_fields(line: str) -> list[str]:
    """The fields of one pairs-file line: tab-separated when the line has a tab (paths may then
    hold spaces), else shell-like words (quote paths with spaces); see :func:`strip_comment`."""
    if "\t" in line:
        cut = (i for i, c in enumerate(line) if c == "#" and (i == 0 or line[i - 1].isspace()))
        body = line[: next(cut, len(line))]
        if "\t" in body.strip():
            return [_unquoted(f.strip()) for f in body.split("\t") if f.strip()]
    return shlex.split(strip_comment(line), comments=False)


def _unquoted(field: str) -> str:
    """A tab-separated field without the quotes around it, when it is one quoted word."""
    if len(field) >= 2 and field[0] == field[-1] and field[0] in "'\"":
        try:
            words = shlex.split(field)
        except ValueError:
            return field
        if len(words) == 1:
            return words[0]
    return field


@overload
def read_pairs(
    path: str | os.PathLike, *, ext: str = "", with_landmarks: Literal[False] = False
) -> list[tuple[Path, Path]]: ...
@overload
def read_pairs(
    path: str | os.PathLike, *, ext: str = "", with_landmarks: Literal[True]
) -> tuple[list[tuple[Path, Path]], list[np.ndarray | None]]: ...
def read_pairs(path: str | os.PathLike, *, ext: str = "", with_landmarks: bool = False):
    """Read a pairs file: one pair per line, two mesh paths.

    The two paths are separated by white space (quote a path holding spaces, as in a shell:
    ``"my meshes/a.off" b.off``) or by a tab (then each field is taken as it is, spaces
    included, without quotes around it). Relative paths are resolved against the file's
    folder; ``ext`` (e.g. ``".off"``) is appended to bare names, those without a mesh suffix
    (``.off``, ``.obj``, ``.ply``, ``.stl``, ``.glb``), so the ``pairs.txt`` of the shared benchmark sets
    (``tr_reg_002 tr_reg_007``) work as they are, beside ``scan.ply``. Blank lines are ignored, and
    so is a comment: a ``#`` at the start of a line or after white space (outside quotes) and
    the rest of the line; a ``#`` inside a name (``scan#2``) is part of the path. A malformed
    line, or a pair listed twice (its map would go to one file twice), raises ValueError
    naming the file and line.

    With ``with_landmarks``, a line may name a third file: the pair's landmarks (read with
    :func:`hope_rs.read_landmarks`, relative paths against the pairs file's folder, no ``ext``
    added), and the result is ``(pairs, landmarks)`` with one (m, 2) array or ``None`` per pair.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (folder / "scan.lm").write_text("0 5\\n17 3\\n")
    >>> _ = (folder / "pairs.txt").write_text("template scan scan.lm\\ntemplate scan#2 # 2nd\\n")
    >>> pairs, landmarks = read_pairs(folder / "pairs.txt", ext=".off", with_landmarks=True)
    >>> [(a.name, b.name) for a, b in pairs], landmarks[0].tolist(), landmarks[1]
    ([('template.off', 'scan.off'), ('template.off', 'scan#2.off')], [[0, 5], [17, 3]], None)
    """
    pairs, files, lines = _parse(path, ext, with_landmarks)
    if not with_landmarks:
        return pairs
    marks = []
    for lm, no in zip(files, lines):
        try:
            marks.append(None if lm is None else check_landmarks(read_landmarks(lm), None, None))
        except (OSError, TypeError, ValueError) as e:
            raise ValueError(
                f"{path}:{no}: a third field names the pair's landmark file: {e}"
            ) from None
    return pairs, marks


def landmark_files(path: str | os.PathLike, *, ext: str = "") -> list[Path | None]:
    """The landmark file a pairs file names for each of its pairs (its third field, resolved
    against the file's folder), or ``None``: what :func:`hope_rs.match_many` takes as
    ``landmarks`` to name the file in a pair's error. Checked as :func:`read_pairs` checks it,
    without reading the landmark files."""
    return _parse(path, ext, True)[1]


def _parse(path, ext: str, with_landmarks: bool) -> tuple[list, list, list[int]]:
    """The pairs of a pairs file, each one's landmark file (or ``None``) and line number."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{str(path)!r} is a folder; give the pairs file (one 'A B' per line)")
    if not path.is_file():
        raise FileNotFoundError(f"no such pairs file: {str(path)!r}")
    if ext and not ext.startswith("."):
        ext = "." + ext
    folder = path.resolve().parent
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"{path} is not a text file of mesh paths") from None
    out, files, lines = [], [], []
    listed: dict[tuple[str, str], int] = {}  # each pair's first line, by its files
    for no, line in enumerate(text.splitlines(), 1):
        try:
            tokens = _pair_fields(line)
        except ValueError as e:  # shlex: an unclosed quote
            raise ValueError(f"{path}:{no}: {e}: {line.strip()!r}") from None
        if not tokens:
            continue
        if len(tokens) != 2 and not (with_landmarks and len(tokens) == 3):
            want = "two mesh paths (and a landmark file)" if with_landmarks else "two mesh paths"
            raise ValueError(
                f"{path}:{no}: expected {want} separated by white space or a tab, got "
                f"{len(tokens)} field(s) (quote paths holding spaces): {line.strip()!r}"
            )
        lm = Path(tokens[2]) if len(tokens) == 3 else None
        files.append(lm if lm is None or lm.is_absolute() else folder / lm)
        lines.append(no)
        pair = []
        for t in tokens[:2]:
            if ext and Path(t).suffix.lower() not in READERS:  # a bare name
                t += ext
            p = Path(t)
            pair.append(p if p.is_absolute() else folder / p)
        first = listed.setdefault((os.path.abspath(pair[0]), os.path.abspath(pair[1])), no)
        if first != no:  # its map would be written twice, to one file
            raise ValueError(
                f"{path}:{no}: the pair {tokens[0]} -> {tokens[1]} is listed on line {first} "
                "already; list each pair once"
            )
        out.append((pair[0], pair[1]))
    if not out:
        raise ValueError(f"{path} lists no pairs (expected lines of two mesh paths)")
    return out, files, lines


def all_pairs(n: int) -> list[tuple[int, int]]:
    """Every unordered pair (i, j), i < j, of n shapes."""
    return [(i, j) for i in range(n) for j in range(i + 1, n)]
