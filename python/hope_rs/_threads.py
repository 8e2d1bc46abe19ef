"""The Rust kernels' thread count: ``RAYON_NUM_THREADS`` capped at the cores available.

Rayon starts as many threads as ``RAYON_NUM_THREADS`` asks for at the first parallel call;
far more threads than cores make the kernels' many short parallel loops several times
slower. The variable is capped when the package is imported, before any Rust call.
"""

from __future__ import annotations

import os
import warnings

__all__ = ["available_cores", "cap_rayon_threads"]


def available_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def cap_rayon_threads() -> None:
    """Lower ``RAYON_NUM_THREADS`` to :func:`available_cores`, with a warning, when it asks
    for more; other values (unset, 0 for rayon's default, not a number) are left alone."""
    text = os.environ.get("RAYON_NUM_THREADS", "")
    try:
        asked = int(text)
    except ValueError:
        return
    cores = available_cores()
    if asked > cores:
        os.environ["RAYON_NUM_THREADS"] = str(cores)
        warnings.warn(
            f"RAYON_NUM_THREADS={asked} is more than the {cores} cores available; the Rust "
            f"kernels use {cores} threads",
            RuntimeWarning,
            stacklevel=2,
        )
