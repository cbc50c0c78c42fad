"""World vectors in a rotated frame, in float32 with a fixed rounding: fused multiply-adds.

The tracker keeps positions in float32. Rotating them with a matrix product would leave each
result's last bit to the BLAS kernel that runs (whether it fuses multiply-adds, in which order it
adds), and the penetration sums compare such results against each other. Here every coordinate
is computed as fma(r2, v2, fma(r1, v1, r0 * v0)), each step rounded once to float32: the same
bits on every machine, and the same as OpenBLAS's fused sgemm kernels give for a 3x3 product.
"""

from __future__ import annotations

import numpy as np


def fused_multiply_add_float32(a, b, c) -> np.ndarray:
    """a * b + c for float32 arrays, rounded once to float32 (as a hardware fma).

    The product of two float32 values is exact in float64; the sum is formed in float64 with its
    rounding error (two-sum), and rounded to odd (the last bit set whenever the sum is inexact).
    A float64 value rounded to odd rounds to float32 exactly as the exact sum would, since float64
    carries more than 2 * 24 + 1 bits.
    """
    product = np.asarray(a, dtype=np.float64) * np.asarray(b, dtype=np.float64)
    addend = np.asarray(c, dtype=np.float64)
    total = product + addend
    # Two-sum: the exact rounding error of the float64 addition.
    back = total - product
    error = (product - (total - back)) + (addend - back)
    even = (total.view(np.int64) & 1) == 0
    inexact_even = (error != 0.0) & even
    if inexact_even.any():
        toward = np.where(error > 0.0, np.inf, -np.inf)
        total = np.where(inexact_even, np.nextafter(total, toward), total)
    return total.astype(np.float32)


def in_frame_float32(frame_t: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Coordinates ``frame_t @ vectors`` (3, k) float32, each with the fixed fused rounding.

    Args:
        frame_t: (3, 3) or (k, 3, 3) float32 matrices (R^T of the frame's orientation R, so the
            result is the vectors' coordinates along the frame's axes), one per column or shared.
        vectors: (3, k) float32 world vectors (m).
    """
    frame_t = np.asarray(frame_t, dtype=np.float32)
    rows = []
    for i in range(3):
        r = frame_t[..., i, :]
        acc = r[..., 0] * vectors[0]
        acc = fused_multiply_add_float32(r[..., 1], vectors[1], acc)
        rows.append(fused_multiply_add_float32(r[..., 2], vectors[2], acc))
    return np.stack(rows)
