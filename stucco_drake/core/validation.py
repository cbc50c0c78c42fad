"""Input checks shared by the core: one-line errors that name the offending argument."""

from __future__ import annotations

import numpy as np


def as_finite_array(value, name: str, shape: tuple, dtype=np.float64) -> np.ndarray:
    """Return ``value`` as a finite array of ``shape``; ``None`` in ``shape`` matches any size.

    Raises ValueError naming ``name`` when the shape is wrong or an entry is NaN or infinite.
    """
    try:
        array = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: not a numeric array ({error})") from None
    if array.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(array.shape, shape, strict=True)
    ):
        expected = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {expected}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return array


_IDENTITY = np.eye(3)
_ORTHONORMAL_TOLERANCE = 1e-6 + 1e-5 * _IDENTITY


def as_rotation(value, name: str) -> np.ndarray:
    """Return ``value`` as a 3x3 rotation matrix, rejecting non-orthonormal input."""
    rotation = as_finite_array(value, name, (3, 3))
    # np.allclose(R R^T, I, atol=1e-6) and det(R) >= 0, written out: this runs on every
    # tracker update, and the general routines cost more than the update's own bookkeeping.
    error = np.abs(rotation @ rotation.T - _IDENTITY)
    determinant = np.linalg.det(rotation)
    if not (error <= _ORTHONORMAL_TOLERANCE).all() or determinant < 0:
        raise ValueError(f"{name}: not a rotation matrix (R R^T != I or det(R) < 0)")
    return rotation
