"""The module paths of hope_rs 0.1 (a flat package), kept importable for one release.

``import hope_rs.refine`` still works and gives the module at its new path
(:mod:`hope_rs.pipeline.refine`), with a :class:`DeprecationWarning` naming that path.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

#: Old module (under ``hope_rs.``) → its path since the package was split into layers.
MOVED = {
    "_options": "pipeline.options",
    "anchors": "pipeline.anchors",
    "assignment": "kernels.assignment",
    "batch_cli": "cli.batch_cli",
    "bench": "evaluation.bench",
    "cache": "batch.cache",
    "datasets": "evaluation.datasets",
    "demo": "evaluation.demo",
    "descriptors": "features.descriptors",
    "evaluate": "evaluation.evaluate",
    "growth": "pipeline.growth",
    "handles": "pipeline.handles",
    "initial": "pipeline.initial",
    "lmd": "pipeline.lmd",
    "map_io": "geometry.map_io",
    "mesh": "geometry.mesh",
    "methods": "evaluation.methods",
    "multiscale": "pipeline.multiscale",
    "numbering": "geometry.numbering",
    "orientation": "geometry.orientation",
    "progress": "pipeline.progress",
    "ray_backend": "batch.ray_backend",
    "refine": "pipeline.refine",
    "shared_faces": "pipeline.shared_faces",
    "show": "evaluation.show",
    "sites": "geometry.sites",
    "spectral": "pipeline.spectral",
}


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds ``hope_rs.<old>`` and loads it as the module at its new path."""

    def find_spec(self, fullname, path=None, target=None):
        package, _, name = fullname.partition(".")
        if package != "hope_rs" or name not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        new = f"hope_rs.{MOVED[spec.name.partition('.')[2]]}"
        warnings.warn(
            f"{spec.name} moved to {new}; the old path goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )
        return importlib.import_module(new)

    def exec_module(self, module):
        pass  # the module at the new path is executed already


def install() -> None:
    """Adds the finder once (importing the package calls it)."""
    if not any(isinstance(f, _Alias) for f in sys.meta_path):
        sys.meta_path.append(_Alias())
