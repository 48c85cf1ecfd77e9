"""Checks for the numpy arguments of the Python API (the bindings' ``check_array`` lives in
cpp/bindings/bindings.hpp): a TypeError or ValueError naming the argument, never a silent
conversion of objects, complex numbers, strings or booleans into numbers, and a ValueError
naming the argument for more than MAX_ENTRIES entries (e.g. a broadcast view of 2**31 rows,
which takes no memory until copied)."""
from __future__ import annotations

from typing import Any, Optional, Tuple

import numpy as np

__all__ = ["MAX_ENTRIES", "as_array", "real_array", "index_array"]

#: The most entries an array argument may have (the C++ core indexes rows with 32-bit ints).
MAX_ENTRIES = 2**31 - 1


def as_array(value: Any, name: str) -> np.ndarray:
    """``np.asarray(value)``; ragged nested lists raise a TypeError naming ``name``."""
    try:
        return np.asarray(value)
    except (ValueError, TypeError) as e:  # ragged nested lists
        raise TypeError(f"{name}: expected an array of numbers ({e})") from None


def _check_shape(a: np.ndarray, name: str, shape: Tuple) -> None:
    """``shape``: sizes, None for any size; a leading Ellipsis allows any leading dimensions."""
    if shape and shape[0] is Ellipsis:
        tail = shape[1:]
        ok = a.ndim >= len(tail) and all(s is None or a.shape[a.ndim - len(tail) + i] == s for i, s in enumerate(tail))
        want = "(..., " + ", ".join("N" if s is None else str(s) for s in tail) + ")"
    else:
        ok = a.ndim == len(shape) and all(s is None or a.shape[i] == s for i, s in enumerate(shape))
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
    if not ok:
        raise ValueError(f"{name}: expected shape {want}, got {a.shape}")


def _contiguous(a: np.ndarray, name: str, dtype) -> np.ndarray:
    if a.size > MAX_ENTRIES:  # refused before any copy: a copy that big could meet the OOM killer
        raise ValueError(f"{name}: {a.size} entries (shape {a.shape}) is over the limit of {MAX_ENTRIES}")
    try:
        return np.ascontiguousarray(a, dtype=dtype)
    except MemoryError as e:
        raise MemoryError(f"{name}: an array of shape {a.shape} is too large to copy ({e})") from None


def real_array(value: Any, name: str, shape: Tuple, *, dtype=np.float32, finite: bool = False) -> np.ndarray:
    """``value`` (an array or nested lists of real numbers, float or integer) as a C-contiguous
    ``dtype`` array of ``shape``; NaN and inf refused when ``finite``."""
    a = as_array(value, name)
    if a.dtype.kind not in "fiu":
        raise TypeError(f"{name}: expected real numbers, got dtype {a.dtype}")
    _check_shape(a, name, shape)
    out = _contiguous(a, name, dtype)
    if finite and not np.isfinite(out).all():
        raise ValueError(f"{name}: contains NaN or inf")
    return out


def index_array(value: Any, name: str, shape: Tuple, *, high: int, low: int = 0,
                what: Optional[str] = None) -> np.ndarray:
    """``value`` (integers) as a C-contiguous int64 array of ``shape`` with every entry in
    [low, high); ``what`` names the range in the error (e.g. "the database's frames")."""
    a = as_array(value, name)
    if a.dtype.kind not in "iu":
        raise TypeError(f"{name}: expected integers, got dtype {a.dtype}")
    _check_shape(a, name, shape)
    if a.size > MAX_ENTRIES:
        raise ValueError(f"{name}: {a.size} entries (shape {a.shape}) is over the limit of {MAX_ENTRIES}")
    if a.size and (a.min() < low or a.max() >= high):  # before the cast: uint64 could wrap
        bad = a[(a < low) | (a >= high)].flat[0]
        raise ValueError(f"{name}: {bad} is outside [{low}, {high})" + (f" ({what})" if what else ""))
    return _contiguous(a, name, np.int64)
