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
