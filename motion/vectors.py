"""Small vector helpers for the per-frame arrays of motions."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


def norms(x: Array) -> Array:
    """``(...,)`` Euclidean lengths of the vectors ``x (..., n)``: ``np.linalg.norm(x, axis=-1)``.

    For ``n <= 4`` (points, quaternions) the squares are summed in order, as numpy's reduction
    does for so short an axis, so the values are the same bit for bit; numpy reduces a short last
    axis element by element, several times slower than these few whole-array operations. Longer
    vectors use ``np.linalg.norm``.
    """
    v = np.asarray(x, dtype=np.float64)
    n = v.shape[-1]
    if not 1 <= n <= 4:
        return np.asarray(np.linalg.norm(v, axis=-1))
    s = v[..., 0] * v[..., 0]
    for k in range(1, n):
        s = s + v[..., k] * v[..., k]
    return np.asarray(np.sqrt(s))


def cross(a: Array, b: Array) -> Array:
    """``np.cross(a, b)`` of 3-vectors ``(..., 3)`` (broadcasting): the same products and
    differences, so the same bits, without ``np.cross``'s axis bookkeeping (which costs more than
    the arithmetic for a few thousand vectors)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = ay * bz - az * by
    out[..., 1] = az * bx - ax * bz
    out[..., 2] = ax * by - ay * bx
    return out
