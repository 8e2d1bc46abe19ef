"""The batch manifest: what each map file of an output folder was computed from.

``OUT/hope-rs-manifest.jsonl`` records, per map file, the two shapes' names and content
digests, the landmarks' digest, the settings key (:meth:`~hope_rs.MatchConfig.key` and both
shapes' :class:`~hope_rs.ShapeConfig`), the code version and the digest of the map written
(a map file edited or replaced afterwards is computed again), and the match's
:class:`~hope_rs.MatchQuality` (``quality``, not compared: a skipped pair reports it). A rerun
skips a pair only when its map file is whole and its entry matches the pair in every field;
:meth:`Manifest.why_redo` says what differs.

The file is a journal, one JSON object a line, appended to and flushed to disk as each pair
finishes (after its map is written): an entry costs one short write however many pairs the
folder holds, and a batch killed at any moment leaves at worst a cut last line, which is
ignored. An entry is dropped (a line saying so) before its map is rewritten, so that no entry
describes another map than the one on disk; the last line about a map wins. When the journal
has grown to several lines per map it is rewritten, atomically, with one line per map.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import warnings
from pathlib import Path

import numpy as np

from ..geometry.map_io import atomic_write
from ..pipeline.config import settings_json

__all__ = ["MANIFEST", "Manifest", "landmarks_digest", "map_digest", "settings_key"]

#: The manifest's file name in an output folder.
MANIFEST = "hope-rs-manifest.jsonl"
#: The first line of a manifest: its layout version.
HEADER = {"hope_rs_manifest": 1}

#: Entry fields and how a difference in each is reported.
FIELDS = {
    "a_digest": "mesh {a} changed",
    "b_digest": "mesh {b} changed",
    "landmarks": "its landmarks changed",
    "settings": "the settings changed",
    "code": "it was computed by another version of hope_rs",
    "map_digest": "the map file is not the one the batch wrote",
}
#: The fields of FIELDS that name a pair's inputs: a map recorded for others is wrong for it.
INPUT_FIELDS = ("a_digest", "b_digest", "landmarks")


def settings_key(match_key: str, config_a, config_b) -> str:
    """The settings of one pair: the MatchConfig key and the ShapeConfig of each shape."""
    parts = [match_key] + [settings_json(dataclasses.asdict(c)) for c in (config_a, config_b)]
    return hashlib.sha256("\n".join(parts).encode("utf-8")).hexdigest()


def landmarks_digest(landmarks) -> str | None:
    """SHA-256 of a pair's (m, 2) landmarks as int64, or None without any."""
    if landmarks is None or len(landmarks) == 0:
        return None
    arr = np.ascontiguousarray(np.asarray(landmarks, dtype=np.int64))
    return hashlib.sha256(repr(arr.shape).encode() + arr.tobytes()).hexdigest()


def map_digest(mapping) -> str:
    """SHA-256 of a map's indices as little-endian int64 (the same whatever its file format)."""
    arr = np.ascontiguousarray(np.asarray(mapping, dtype="<i8"))
    return hashlib.sha256(arr.tobytes()).hexdigest()


def _line(obj: dict) -> bytes:
    return (json.dumps(obj, sort_keys=True) + "\n").encode("utf-8")


class Manifest:
    """The manifest of the output folder ``folder`` (read when it exists)."""

    def __init__(self, folder: str | os.PathLike):
        self.path = Path(folder) / MANIFEST
        if self.path.is_dir():
            raise ValueError(
                f"the batch manifest {str(self.path)!r} is a folder; move it away (the manifest "
                "is a file the batch writes)"
            )
        self.entries: dict[str, dict] = {}
        lines = self._read()
        if lines is None or lines > 2 * len(self.entries) + 64:
            self._rewrite()  # new, unreadable or grown: one line per map

    def _read(self) -> int | None:
        """Read the entries; the number of lines, or None when there is no usable file."""
        try:
            text = self.path.read_bytes().decode("utf-8", errors="replace")
        except FileNotFoundError:
            return None
        except OSError as e:
            text, why = "", str(e)
        else:
            why = "it is not a hope_rs batch manifest"
        lines = text.splitlines()
        try:
            head = json.loads(lines[0])
        except (IndexError, ValueError):
            head = None
        ok = head == HEADER
        layout = head.get("hope_rs_manifest") if isinstance(head, dict) else None
        if (
            isinstance(layout, int)
            and not isinstance(layout, bool)
            and layout > HEADER["hope_rs_manifest"]
        ):
            # Replacing it would lose what a newer hope_rs recorded.
            raise ValueError(
                f"the batch manifest {str(self.path)!r} was written by a newer hope_rs (layout "
                f"{layout}); run that version, or give another output folder"
            )
        if not ok:
            warnings.warn(
                f"batch manifest {str(self.path)!r} is unreadable ({why}); the maps of this "
                "folder are computed again",
                RuntimeWarning,
                stacklevel=3,
            )
            return None
        for line in lines[1:]:
            try:
                item = json.loads(line)
                name = item["map"]
                if item.get("drop"):
                    self.entries.pop(name, None)
                else:
                    self.entries[name] = dict(item["entry"])
            except (ValueError, KeyError, TypeError, AttributeError):
                continue  # a line cut short by a crash
        if text and not text.endswith("\n"):
            self._append(b"\n")  # so that the next line starts on its own
        return len(lines)

    def _append(self, data: bytes) -> None:
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
        try:
            os.write(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)

    def _rewrite(self) -> None:
        text = _line(HEADER) + b"".join(
            _line({"map": name, "entry": e}) for name, e in sorted(self.entries.items())
        )
        atomic_write(self.path, lambda fh: fh.write(text))

    def why_redo(self, name: str, entry: dict) -> str | None:
        """None when map file ``name`` was computed from exactly ``entry``, else why not."""
        old = self.entries.get(name)
        if old is None:
            return "the manifest has no entry for it"
        if "map_digest" not in old:
            return "its manifest entry was written by an older hope_rs (no map digest)"
        for key, why in FIELDS.items():
            if old.get(key) != entry.get(key):
                return why.format(a=entry.get("a"), b=entry.get("b"))
        return None

    def inputs_changed(self, name: str, entry: dict) -> bool:
        """Whether map file ``name`` was recorded for other meshes or landmarks than
        ``entry``'s (its map is then wrong for them, not merely made another way)."""
        old = self.entries.get(name)
        return old is not None and any(old.get(k) != entry.get(k) for k in INPUT_FIELDS)

    def forget(self, name: str) -> None:
        """Drop the entry of map file ``name`` (before its map is rewritten: a run cut short
        between the two must not leave a new map under an old entry)."""
        if self.entries.pop(name, None) is not None:
            self._append(_line({"map": name, "drop": True}))

    def record(self, name: str, entry: dict) -> None:
        """Record ``entry`` for map file ``name`` (once its map is written)."""
        self.entries[name] = entry
        self._append(_line({"map": name, "entry": entry}))
