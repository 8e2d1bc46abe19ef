"""The checks of a config dataclass's fields, declared once on each field (``range``,
``choices``, ``finite``): run by :func:`hope_rs.match` and by
:meth:`~hope_rs.MatchConfig.with_options`, so that a bad value is refused where it is set.
"""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np

__all__ = ["check_config", "checked_integer"]


def checked_integer(name: str, value, lo: int, hi: int | None, allowed: str) -> int:
    """``value`` as an int when it is an integer (not a bool) in [lo, hi]; ``allowed`` says
    so in the message."""
    if isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be {allowed}, not a bool (got {value!r})")
    if not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be {allowed}, got {type(value).__name__} {value!r}")
    if value < lo or (hi is not None and value > hi):
        raise ValueError(f"{name} must be {allowed}, got {value}")
    return int(value)


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
            checked_integer(name, value, lo, hi, f"None or {_span(lo, hi)}")
        elif isinstance(ref, bool):
            if not isinstance(value, (bool, np.bool_)):
                raise TypeError(f"{name} must be True or False, got {value!r}")
        elif isinstance(ref, int):
            lo, hi = f.metadata.get("range", (0 if ref >= 0 else -(2**63), None))
            allowed = _sign(ref, "an integer") if "range" not in f.metadata else _span(lo, hi)
            checked_integer(name, value, lo, hi, allowed)
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
