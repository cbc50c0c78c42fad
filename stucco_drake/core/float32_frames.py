"""World vectors in a rotated frame, in float32 with a fixed rounding: fused multiply-adds.

The tracker keeps positions in float32. Rotating them with a matrix product would leave each
result's last bit to the BLAS kernel that runs (whether it fuses multiply-adds, in which order it
adds), and the penetration sums compare such results against each other. Here every coordinate
is computed as fma(r2, v2, fma(r1, v1, r0 * v0)), each step rounded once to float32: the same
bits on every machine, and the same as OpenBLAS's fused sgemm kernels give for a 3x3 product.
"""

from __future__ import annotations

import numpy as np

#: float64 carries 29 more fraction bits than float32: a float32 midpoint has these low bits.
_EXTRA_BITS = 29
_MIDPOINT = 1 << (_EXTRA_BITS - 1)
#: Below this magnitude float32 is subnormal and its spacing is not a fixed 29-bit step.
_FLOAT32_TINY = float(np.finfo(np.float32).tiny)


def fused_multiply_add_float32(a, b, c) -> np.ndarray:
    """a * b + c for float32 arrays, rounded once to float32 (as a hardware fma).

    The product of two float32 values is exact in float64, so the float64 sum is rounded once.
    Rounding that sum to float32 again gives the correctly rounded result unless the sum fell
    exactly on a float32 midpoint (rounding to nearest cannot cross one, every midpoint being a
    float64 value): there the exact sum's side is read from the two-sum error term.
    """
    product = np.asarray(a, dtype=np.float64) * np.asarray(b, dtype=np.float64)
    addend = np.asarray(c, dtype=np.float64)
    total = product + addend
    low = total.view(np.int64) & ((1 << _EXTRA_BITS) - 1)
    doubtful = (low == _MIDPOINT) | (np.abs(total) < _FLOAT32_TINY)
    if doubtful.any():
        at = np.flatnonzero(doubtful)
        p, q, t = (np.broadcast_to(v, total.shape).ravel()[at] for v in (product, addend, total))
        back = t - p
        error = (p - (t - back)) + (q - back)  # two-sum: t + error == p + q exactly
        # Round to odd: an inexact sum with its last bit clear moves one float64 step toward the
        # exact sum; float32 rounding of a float64 rounded to odd is the correct rounding.
        even = (t.view(np.int64) & 1) == 0
        toward = np.where(error > 0.0, np.inf, -np.inf)
        t = np.where((error != 0.0) & even, np.nextafter(t, toward), t)
        total.ravel()[at] = t  # total is a fresh contiguous array
    return total.astype(np.float32)


def in_frame_float32(frame_t: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Coordinates ``frame_t @ vectors`` (3, k) float32, each with the fixed fused rounding.

    Args:
        frame_t: (3, 3) or (k, 3, 3) float32 matrices (R^T of the frame's orientation R, so the
            result is the vectors' coordinates along the frame's axes), one per column or shared.
        vectors: (3, k) float32 world vectors (m).
    """
    frame_t = np.asarray(frame_t, dtype=np.float32)
    # Column j of each matrix as a (3, k) (or (3, 1)) array: all three rows in one call.
    column = [np.moveaxis(frame_t[..., :, j], -1, 0).reshape(3, -1) for j in range(3)]
    acc = column[0] * vectors[0]
    acc = fused_multiply_add_float32(column[1], vectors[1], acc)
    return fused_multiply_add_float32(column[2], vectors[2], acc)
