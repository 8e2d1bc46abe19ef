"""The option checks of :func:`hope_rs.match`, run before any expensive work.

Each bad value gets a one-line message naming the option, what it allows and what it got.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from ..features.descriptors import check_kind
from .config import INIT_KINDS, declared
from .config_checks import check_config, checked_integer

__all__ = ["INIT_KINDS", "K_MAX_RANGE", "TOP_K_LIMIT", "check_config", "check_options"]

#: Hop radii a :class:`~hope_rs.Shape` supports (declared on ``MatchConfig.k_max``).
K_MAX_RANGE = declared("k_max")["range"]
#: Largest ``top_k`` (declared on ``RefineConfig.top_k``).
TOP_K_LIMIT = declared("top_k")["range"][1]


def check_options(
    *,
    init,
    k_max,
    schedule,
    max_passes,
    min_consistent,
    top_k,
    polish_k,
    global_step,
    multiscale,
    spectral,
    shared_faces,
    callback,
    progress=None,
    confidence=True,
) -> None:
    """Raise ``TypeError`` (wrong kind of value) or ``ValueError`` (out of range) for the first
    bad option of :func:`hope_rs.match`; the values themselves are left as given. An ``init``
    array is checked against the vertex counts later, by the caller."""
    lo, hi = K_MAX_RANGE
    k_max = checked_integer(
        "k_max", k_max, lo, hi, f"an integer in [{lo}, {hi}] (LMD reads 2-rings)"
    )
    if isinstance(init, str):
        check_kind(init)
    elif init is None or isinstance(init, (numbers.Number, dict, set)):
        raise TypeError(
            f"init must be one of {', '.join(map(repr, INIT_KINDS))} or an (n_a,) array of "
            f"vertices of B, got {type(init).__name__}"
        )
    if schedule is not None:
        _check_schedule(schedule, k_max)
    passes_lo, passes_hi = declared("max_passes")["range"]
    checked_integer("max_passes", max_passes, passes_lo, passes_hi, "an integer >= 1")
    _unit_number("min_consistent", min_consistent)
    allowed = f"an integer in [1, {TOP_K_LIMIT}] (candidates kept per vertex)"
    checked_integer("top_k", top_k, 1, TOP_K_LIMIT, allowed)
    if polish_k is not None:
        # It runs at min(polish_k, k_max): the default 3 serves k_max = 2 too.
        p_lo, p_hi = declared("polish_k")["range"]
        checked_integer("polish_k", polish_k, p_lo, p_hi, f"None or an integer in [{p_lo}, {p_hi}]")
    if not (multiscale is None or isinstance(multiscale, (bool, np.bool_))):
        raise TypeError(
            "multiscale must be None (chosen by size; a settings file leaves [multiscale] "
            f"enabled out for it), True or False, got {multiscale!r}"
        )
    for name, value in [
        ("global_step", global_step),
        ("spectral", spectral),
        ("shared_faces", shared_faces),
        ("confidence", confidence),
    ]:
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{name} must be True or False, got {value!r}")
    if callback is not None and not callable(callback):
        raise TypeError(
            "callback must be None or callable (it is called with each refinement Iteration), "
            f"got {type(callback).__name__}"
        )
    if not (progress is None or isinstance(progress, (bool, np.bool_)) or callable(progress)):
        raise TypeError(
            "progress must be None, True, False or callable (it is called with each "
            f"ProgressEvent), got {type(progress).__name__}"
        )


def _unit_number(name: str, value) -> None:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number in [0, 1], got {type(value).__name__}")
    if not (math.isfinite(value) and 0 <= float(value) <= 1):
        raise ValueError(f"{name} must be a number in [0, 1], got {value}")


def _check_schedule(schedule, k_max: int) -> None:
    allowed = f"a non-empty list of integer hop radii in [1, k_max={k_max}]"
    if isinstance(schedule, (str, bytes)):
        raise TypeError(f"schedule must be {allowed}, got the string {schedule!r}")
    if isinstance(schedule, np.ndarray) and schedule.ndim != 1:
        raise ValueError(f"schedule must be {allowed}, got an array of shape {schedule.shape}")
    try:
        entries = list(schedule)
    except TypeError:
        raise TypeError(f"schedule must be {allowed}, got {type(schedule).__name__}") from None
    if not entries:
        raise ValueError(f"schedule must be {allowed}, got an empty one")
    for k in entries:
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)):
            raise TypeError(f"schedule must be {allowed}, got the entry {k!r}")
        if not 1 <= k <= k_max:
            raise ValueError(f"schedule must be {allowed}, got the entry {k}")
