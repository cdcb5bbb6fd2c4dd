"""Compiled kernel of :mod:`engines.graph.candidates`: descent from a seed entry of the cost matrix
to the local minimum of its basin (numba, ``cache=True``: the first call in a fresh environment
compiles, a few seconds; later processes load the machine code from ``__pycache__``)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _cost(rows: np.ndarray, a: int, b: int) -> np.float32:
    """``||rows[a] - rows[b]||^2`` (float32 rows, float32 sum as numpy's einsum does)."""
    s = np.float32(0.0)
    for j in range(rows.shape[1]):
        d = rows[a, j] - rows[b, j]
        s += d * d
    return s


@njit(cache=True, nogil=True)
def descend(
    rows: np.ndarray,
    clip: np.ndarray,
    xs: np.ndarray,
    ys: np.ndarray,
    max_steps: int,
    out_x: np.ndarray,
    out_y: np.ndarray,
    out_v: np.ndarray,
    out_ok: np.ndarray,
) -> None:
    """For every seed ``(xs[i], ys[i])``: steepest descent over the 3x3 neighbourhood of the matrix
    ``M[x, y] = ||rows[x] - rows[y]||^2`` within the seed's clip-pair block (``clip (N,)`` each row's
    clip), at most ``max_steps`` moves. Writes the end entry ordered ``x <= y``, its value, and
    ``out_ok[i]``: whether it is a local minimum by the all-pairs scan's rule (no neighbour lower;
    neighbours earlier in raster order not equal) reached within ``max_steps``."""
    n = rows.shape[0]
    for i in range(xs.size):
        x = xs[i]
        y = ys[i]
        v = _cost(rows, x, y)
        converged = False
        for _ in range(max_steps):
            bx, by, bv = x, y, v
            for dx in range(-1, 2):
                nx = x + dx
                if nx < 0 or nx >= n or clip[nx] != clip[x]:
                    continue
                for dy in range(-1, 2):
                    if dx == 0 and dy == 0:
                        continue
                    ny = y + dy
                    if ny < 0 or ny >= n or clip[ny] != clip[y]:
                        continue
                    w = _cost(rows, nx, ny)
                    if w < bv:
                        bx, by, bv = nx, ny, w
            if bx == x and by == y:
                converged = True
                break
            x, y, v = bx, by, bv
        if x > y:
            x, y = y, x
        ok = converged
        if ok:  # ties: a neighbour earlier in raster order with the same value wins
            for dx in range(-1, 1):
                nx = x + dx
                if nx < 0 or clip[nx] != clip[x]:
                    continue
                for dy in range(-1, 2):
                    if dx == 0 and dy >= 0:
                        continue
                    ny = y + dy
                    if ny < 0 or ny >= n or clip[ny] != clip[y]:
                        continue
                    if _cost(rows, nx, ny) == v:
                        ok = False
        out_x[i] = x
        out_y[i] = y
        out_v[i] = v
        out_ok[i] = ok
