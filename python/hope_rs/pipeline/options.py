"""The option checks of :func:`hope_rs.match`, run before any expensive work.

Each bad value gets a one-line message naming the option, what it allows and what it got.
"""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np

from ..features.descriptors import check_kind
from .config import INIT_KINDS, declared

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
    k_max = _integer("k_max", k_max, lo, hi, f"an integer in [{lo}, {hi}] (LMD reads 2-rings)")
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
    _integer("max_passes", max_passes, passes_lo, passes_hi, "an integer >= 1")
    _unit_number("min_consistent", min_consistent)
    allowed = f"an integer in [1, {TOP_K_LIMIT}] (candidates kept per vertex)"
    _integer("top_k", top_k, 1, TOP_K_LIMIT, allowed)
    if polish_k is not None:
        # It runs at min(polish_k, k_max): the default 3 serves k_max = 2 too.
        p_lo, p_hi = declared("polish_k")["range"]
        _integer("polish_k", polish_k, p_lo, p_hi, f"None or an integer in [{p_lo}, {p_hi}]")
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


def _integer(name: str, value, lo: int, hi: int | None, allowed: str) -> int:
    """``value`` as an int when it is an integer (not a bool) in [lo, hi]; ``allowed`` says
    so in the message."""
    if isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be {allowed}, not a bool (got {value!r})")
    if not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be {allowed}, got {type(value).__name__} {value!r}")
    if value < lo or (hi is not None and value > hi):
        raise ValueError(f"{name} must be {allowed}, got {value}")
    return int(value)


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


def check_config(config, path: str = "MatchConfig") -> None:
    """Raise ``TypeError`` or ``ValueError`` (one line, naming the field) for a setting of a
    config dataclass that cannot be right: a number of another kind than its default, not
    NaN, or negative where the default is not (pass indices, counts, sizes, tolerances), nor
    infinite where the field's metadata says ``finite``, nor outside its declared ``range``
    (bounds included, or excluded with ``exclusive``) or ``choices``: the constraints are
    declared once, on the field.
    Nested configs are checked too, and so is an optional integer (``int | None``) that is
    set; other fields whose default is ``None``, a string or a tuple are left to their own
    checks."""
    default = type(config)()
    for f in dataclasses.fields(config):
        value, ref = getattr(config, f.name), getattr(default, f.name)
        name = f"{path}.{f.name}"
        if value is None and "None" in str(f.type):
            continue
        choices = f.metadata.get("choices")
        if choices is not None and (not isinstance(value, type(ref)) or value not in choices):
            raise ValueError(
                f"{name} must be one of {', '.join(map(repr, choices))}, got {value!r}"
            )
        if dataclasses.is_dataclass(ref):
            if type(value) is not type(ref):
                raise TypeError(
                    f"{name} must be a {type(ref).__name__}, got {type(value).__name__}"
                )
            check_config(value, f"{path}.{f.name}")
        elif ref is None and str(f.type).replace(" ", "") == "int|None":
            # An optional count or size (None: no limit).
            lo, hi = f.metadata.get("range", (0, None))
            _integer(name, value, lo, hi, f"None or {_span(lo, hi)}")
        elif isinstance(ref, bool):
            if not isinstance(value, (bool, np.bool_)):
                raise TypeError(f"{name} must be True or False, got {value!r}")
        elif isinstance(ref, int):
            lo, hi = f.metadata.get("range", (0 if ref >= 0 else -(2**63), None))
            allowed = _sign(ref, "an integer") if "range" not in f.metadata else _span(lo, hi)
            _integer(name, value, lo, hi, allowed)
        elif isinstance(ref, float):
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
                raise TypeError(f"{name} must be a number, got {type(value).__name__} {value!r}")
            if math.isnan(value) or ("range" not in f.metadata and ref >= 0 and value < 0):
                raise ValueError(f"{name} must be {_float_allowed(f, ref)}, got {value}")
            if f.metadata.get("finite") and not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number (default {ref}), got {value}")
            if "range" in f.metadata:
                lo, hi = f.metadata["range"]
                if f.metadata.get("exclusive"):  # the bounds themselves excluded
                    if value <= lo or (hi is not None and value >= hi):
                        raise ValueError(f"{name} must be {_float_allowed(f, ref)}, got {value}")
                elif value < lo or (hi is not None and value > hi):
                    raise ValueError(f"{name} must be {_span(lo, hi, 'a number')}, got {value}")


def _float_allowed(f: dataclasses.Field, ref: float) -> str:
    """What a float field takes, as its errors say it: its declared range, or its sign."""
    if "range" not in f.metadata:
        return _sign(ref, "a number")
    lo, hi = f.metadata["range"]
    if f.metadata.get("exclusive"):
        return f"a number > {lo}" if hi is None else f"a number in ({lo}, {hi})"
    return _span(lo, hi, "a number")


def _span(lo, hi, what: str = "an integer") -> str:
    return f"{what} >= {lo}" if hi is None else f"{what} in [{lo}, {hi}]"


def _sign(ref, what: str) -> str:
    return f"{what} >= 0 (default {ref})" if ref >= 0 else f"{what} (default {ref})"
