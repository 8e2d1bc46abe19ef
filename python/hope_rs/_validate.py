"""Input checks shared by the public API: fail early, and say how to fix the input."""

from __future__ import annotations

import numpy as np


def _array(x, name: str, shape: str) -> np.ndarray:
    try:
        return np.asarray(x)
    except (ValueError, TypeError):
        raise ValueError(
            f"{name} must be an {shape} array; its rows have different lengths"
        ) from None


def as_faces(
    faces, n_vertices: int | None = None, *, name: str = "faces", copy: bool = False
) -> np.ndarray:
    """Return ``faces`` as a C-contiguous (M, 3) int64 array with indices checked (a new array
    when ``copy``). Integer-valued floats are accepted; the range is checked on the values as
    given, before any conversion could wrap them (a uint64 2**64-1 is reported as itself)."""
    arr = _array(faces, name, "(M, 3) integer")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must be an (M, 3) integer array, got shape {arr.shape}")
    if arr.dtype == bool or not (
        np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)
    ):
        raise TypeError(f"{name} must hold integer vertex indices, got dtype {arr.dtype}")
    if arr.size:
        if np.issubdtype(arr.dtype, np.floating):
            whole = np.isfinite(arr) & (arr == np.round(arr))
            if not whole.all():
                bad = float(arr[~whole].flat[0])
                raise TypeError(f"{name} must hold integer vertex indices, got {bad!r}")
        lo, hi = arr.min(), arr.max()
        lo = int(lo) if np.issubdtype(arr.dtype, np.integer) else float(lo)
        hi = int(hi) if np.issubdtype(arr.dtype, np.integer) else float(hi)
        if lo < 0:
            small = np.issubdtype(arr.dtype, np.signedinteger) and arr.dtype.itemsize < 4
            raise ValueError(
                f"{name} hold a negative vertex index ({lo:.0f}); indices are 0-based"
                if isinstance(lo, float)
                else f"{name} hold a negative vertex index ({lo}); indices are 0-based"
                + (
                    f" (they are {arr.dtype}, which wraps indices above "
                    f"{np.iinfo(arr.dtype).max}: give int32 or int64)"
                    if small
                    else ""
                )
            )
        limit = n_vertices if n_vertices is not None else 2**63 - 1
        if hi >= limit:
            shown = f"{hi:.0f}" if isinstance(hi, float) else str(hi)
            raise ValueError(
                f"{name} refer to vertex {shown} but there are only {n_vertices} vertices "
                "(indices must be 0-based and below the vertex count)"
                if n_vertices is not None
                else f"{name} hold vertex index {shown}, beyond any mesh"
            )
    if copy:
        return np.array(arr, dtype=np.int64, order="C", copy=True)
    return np.ascontiguousarray(arr, dtype=np.int64)


def as_vertices(vertices, *, name: str = "vertices", copy: bool = False) -> np.ndarray:
    """Return ``vertices`` as a C-contiguous finite (N, 3) float64 array (a new array when
    ``copy``)."""
    arr = _array(vertices, name, "(N, 3) float")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must be an (N, 3) float array, got shape {arr.shape}")
    if arr.dtype == bool or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
    ):
        raise TypeError(f"{name} must be numeric, got dtype {arr.dtype}")
    if copy:
        arr = np.array(arr, dtype=np.float64, order="C", copy=True)
    else:
        arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(arr), axis=1))[0])
        raise ValueError(f"{name} contain NaN or infinite coordinates (first at row {bad})")
    return arr


def as_index_map(f, length: int, upper: int, *, name: str = "f") -> np.ndarray:
    """Return a map as an int64 array of ``length`` entries in ``[0, upper)``."""
    arr = np.asarray(f)
    if arr.ndim != 1 or arr.shape[0] != length:
        raise ValueError(f"{name} must be a 1-D array of length {length}, got shape {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"{name} must be an integer array, got dtype {arr.dtype}")
    if arr.size and (arr.min() < 0 or arr.max() >= upper):
        # Checked before the cast to int64, which wraps unsigned values past 2**63 around.
        raise ValueError(f"{name} must hold values in [0, {upper}), got [{arr.min()}, {arr.max()}]")
    return np.ascontiguousarray(arr, dtype=np.int64)


def as_mask(mask, length: int, *, name: str = "witnesses") -> np.ndarray:
    """Return a boolean mask of ``length`` entries (accepts bool arrays or index lists)."""
    arr = np.asarray(mask)
    if arr.dtype == bool:
        if arr.shape != (length,):
            raise ValueError(f"{name} must be a boolean array of length {length}, got {arr.shape}")
        return np.ascontiguousarray(arr)
    if arr.ndim == 1 and (arr.size == 0 or np.issubdtype(arr.dtype, np.integer)):
        idx = as_index_map(arr, arr.shape[0], length, name=name)
        out = np.zeros(length, dtype=bool)
        out[idx] = True
        return out
    raise TypeError(f"{name} must be a boolean mask or an array of vertex indices")
