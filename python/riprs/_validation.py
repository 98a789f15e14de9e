"""Argument coercion shared by the public wrappers: array-likes in, float64 numpy out."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riprs._riprs import NonFiniteError, ShapeError

FloatArray = NDArray[np.float64]


def as_matrix(value: ArrayLike, name: str) -> FloatArray:
    """Return ``value`` as a C-contiguous 2-D float64 array.

    Scalars become 1x1 and 1-D inputs become a single row, as in python-control. Complex,
    non-numeric or >2-D inputs raise; the message names ``name``.
    """
    array = _as_real_array(value, name)
    if array.ndim > 2:
        raise ShapeError(f"{name}: expected a 2-D array, got {array.ndim} dimensions")
    return np.ascontiguousarray(np.atleast_2d(array))


def as_optional_matrix(value: ArrayLike | None, name: str) -> FloatArray | None:
    """:func:`as_matrix`, passing ``None`` through."""
    return None if value is None else as_matrix(value, name)


def as_vector(value: ArrayLike, name: str, length: int | None = None) -> FloatArray:
    """Return ``value`` as a 1-D float64 array (scalars become length 1), checked for finiteness
    and, when given, for ``length``."""
    array = np.atleast_1d(_as_real_array(value, name))
    if array.ndim != 1:
        raise ShapeError(f"{name}: expected a 1-D array, got shape {array.shape}")
    if length is not None and array.shape[0] != length:
        raise ShapeError(f"{name}: expected shape ({length},), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise NonFiniteError(f"{name} contains NaN or Inf")
    return np.ascontiguousarray(array)


def _as_real_array(value: Any, name: str) -> np.ndarray:
    if np.iscomplexobj(value):
        raise TypeError(f"{name} must be real, got a complex array")
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be an array of real numbers: {exc}") from exc
