"""Input checks shared by the public API: fail early, and say how to fix the input."""

from __future__ import annotations

import numpy as np


def as_faces(faces, n_vertices: int | None = None, *, name: str = "faces") -> np.ndarray:
    """Return ``faces`` as a C-contiguous (M, 3) int64 array with indices checked."""
    arr = np.asarray(faces)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must be an (M, 3) integer array, got shape {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        if (
            np.issubdtype(arr.dtype, np.floating)
            and np.all(np.isfinite(arr))
            and np.all(arr == np.round(arr))
        ):
            arr = arr.astype(np.int64)
        else:
            raise TypeError(f"{name} must hold integer vertex indices, got dtype {arr.dtype}")
    arr = np.ascontiguousarray(arr, dtype=np.int64)
    if arr.size:
        lo, hi = int(arr.min()), int(arr.max())
        if lo < 0:
            raise ValueError(f"{name} hold a negative vertex index ({lo}); indices are 0-based")
        if n_vertices is not None and hi >= n_vertices:
            raise ValueError(
                f"{name} refer to vertex {hi} but there are only {n_vertices} vertices "
                "(indices must be 0-based and below the vertex count)"
            )
    return arr


def as_vertices(vertices, *, name: str = "vertices") -> np.ndarray:
    """Return ``vertices`` as a C-contiguous finite (N, 3) float64 array."""
    arr = np.asarray(vertices)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must be an (N, 3) float array, got shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise TypeError(f"{name} must be numeric, got dtype {arr.dtype}")
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
    arr = np.ascontiguousarray(arr, dtype=np.int64)
    if arr.size and (arr.min() < 0 or arr.max() >= upper):
        raise ValueError(f"{name} must hold values in [0, {upper}), got [{arr.min()}, {arr.max()}]")
    return arr


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
