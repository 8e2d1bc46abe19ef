"""The batch manifest: what each map file of an output folder was computed from.

``OUT/hope-rs-manifest.json`` holds, per map file, the two shapes' names and content digests,
the landmarks' digest, the settings key (:meth:`~hope_rs.MatchConfig.key` and both shapes'
:class:`~hope_rs.ShapeConfig`) and the code version. It is rewritten atomically after each pair.
A rerun skips a pair only when its map file is whole and its entry matches the pair in every
field; :meth:`Manifest.why_redo` says what differs.
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

__all__ = ["MANIFEST", "Manifest", "landmarks_digest", "settings_key"]

#: The manifest's file name in an output folder.
MANIFEST = "hope-rs-manifest.json"
#: Layout version of the manifest.
FORMAT = 1

#: Entry fields and how a difference in each is reported.
FIELDS = {
    "a_digest": "mesh {a} changed",
    "b_digest": "mesh {b} changed",
    "landmarks": "its landmarks changed",
    "settings": "the settings changed",
    "code": "it was computed by another version of hope_rs",
}


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def settings_key(match_key: str, config_a, config_b) -> str:
    """The settings of one pair: the MatchConfig key and the ShapeConfig of each shape."""
    parts = [match_key] + [
        json.dumps(dataclasses.asdict(c), sort_keys=True, default=list)
        for c in (config_a, config_b)
    ]
    return _sha("\n".join(parts))


def landmarks_digest(landmarks) -> str | None:
    """SHA-256 of a pair's (m, 2) landmarks as int64, or None without any."""
    if landmarks is None or len(landmarks) == 0:
        return None
    arr = np.ascontiguousarray(np.asarray(landmarks, dtype=np.int64))
    return hashlib.sha256(repr(arr.shape).encode() + arr.tobytes()).hexdigest()


class Manifest:
    """The manifest of the output folder ``folder`` (read when it exists)."""

    def __init__(self, folder: str | os.PathLike):
        self.path = Path(folder) / MANIFEST
        self.entries: dict[str, dict] = {}
        if not self.path.exists():
            return
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
            if data.get("format") != FORMAT or not isinstance(data.get("maps"), dict):
                raise ValueError("unknown layout")
            self.entries = data["maps"]
        except (OSError, ValueError, AttributeError) as e:
            warnings.warn(
                f"batch manifest {str(self.path)!r} is unreadable ({e}); the maps it listed "
                "are computed again",
                RuntimeWarning,
                stacklevel=2,
            )

    def why_redo(self, name: str, entry: dict) -> str | None:
        """None when map file ``name`` was computed from exactly ``entry``, else why not."""
        old = self.entries.get(name)
        if old is None:
            return "the manifest has no entry for it"
        for key, why in FIELDS.items():
            if old.get(key) != entry.get(key):
                return why.format(a=entry.get("a"), b=entry.get("b"))
        return None

    def forget(self, name: str) -> None:
        """Drop the entry of map file ``name`` (before its map is rewritten: a run cut short
        between the two must not leave a new map under an old entry)."""
        if self.entries.pop(name, None) is not None:
            self._save()

    def record(self, name: str, entry: dict) -> None:
        """Store ``entry`` for map file ``name`` and rewrite the manifest atomically."""
        self.entries[name] = entry
        self._save()

    def _save(self) -> None:
        text = json.dumps({"format": FORMAT, "maps": self.entries}, indent=1, sort_keys=True)
        atomic_write(self.path, lambda fh: fh.write(text.encode("utf-8")))
