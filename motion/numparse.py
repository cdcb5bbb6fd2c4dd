"""Fast, exact parsing of whitespace-separated decimal numbers (the BVH MOTION block).

``numpy.fromstring``/``loadtxt`` spend ~230 ns per number on this machine, and mocap files hold
hundreds of thousands of plain decimals such as ``-103.167999``. :func:`parse_decimals` reads them
in one compiled pass over the bytes (numba; ~2 ns per byte, 4 ms for a 2.7 MB salsa clip against
~15 ms for the vectorised numpy version it replaces, which needed some 30 whole-array passes):
each token's sign, (up to 8) integer digits and (up to 8) fractional digits are read into an
exact integer mantissa ``int * 10**k + frac``, and one division by ``10**k`` (exact in float64 for
k <= 22) gives the correctly rounded value, identical to ``strtod``.

Anything outside the plain grammar ``-?[0-9]{0,8}(\\.[0-9]{0,8})?`` (exponents, ``nan``, ``+``,
long mantissas, stray characters) makes it return ``None``; the caller then uses a general parser,
which also locates the offending line.

The kernel is compiled with ``cache=True`` (the first call in a fresh environment compiles it in
about a second; later processes load it from ``__pycache__``); numba is imported on the first call.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt

_POW10 = 10.0 ** np.arange(9)
_EXACT_LIMIT = 2**53


@lru_cache(maxsize=1)
def _kernel() -> Callable[..., int]:
    """The compiled scanner (numba is imported and the kernel loaded on first use)."""
    from numba import njit

    @njit(cache=True, nogil=True)
    def scan(b: Any, start: int, row_length: int, out: Any, pow10: Any, limit: int) -> int:
        """Write the values of ``b[start:]`` into ``out``; their count, -1 for a token outside
        the grammar (or a non-blank line with another count than ``row_length``, when that is
        ``>= 0``), -2 when ``out`` is full."""
        n = b.size
        i = start
        k = 0
        per_line = 0
        while i < n:
            c = b[i]
            if c == 10:
                if per_line != 0 and row_length >= 0 and per_line != row_length:
                    return -1
                per_line = 0
                i += 1
                continue
            if c == 32 or (c >= 9 and c <= 13):
                i += 1
                continue
            negative = c == 45
            if negative:
                i += 1
            mantissa = 0
            n_int = 0
            while i < n and b[i] >= 48 and b[i] <= 57:
                mantissa = mantissa * 10 + (b[i] - 48)
                n_int += 1
                i += 1
            n_frac = 0
            if i < n and b[i] == 46:
                i += 1
                while i < n and b[i] >= 48 and b[i] <= 57:
                    mantissa = mantissa * 10 + (b[i] - 48)
                    n_frac += 1
                    i += 1
            if i < n and not (b[i] == 32 or (b[i] >= 9 and b[i] <= 13)):
                return -1  # another character inside the token
            if n_int > 8 or n_frac > 8 or n_int + n_frac == 0 or mantissa > limit:
                return -1
            if k >= out.size:
                return -2
            value = mantissa / pow10[n_frac]
            out[k] = -value if negative else value
            k += 1
            per_line += 1
        if per_line != 0 and row_length >= 0 and per_line != row_length:
            return -1
        return k

    return scan


def parse_decimals(
    data: bytes, start: int = 0, row_length: int | None = None, max_values: int | None = None
) -> npt.NDArray[np.float64] | None:
    """Parse plain decimal numbers separated by ASCII whitespace.

    Parameters
    ----------
    data:
        Bytes such as ``b"-0.5 12.25\\n3 4\\n"``.
    start:
        Offset in ``data`` where the numbers begin (a whole file can be passed without copying its
        tail; the bytes before ``start`` are ignored).
    row_length:
        When given, every non-blank line must hold exactly this many numbers (else ``None``).
    max_values:
        When given, more numbers than this give ``None`` (a caller that knows how many to expect
        saves a buffer half the size of the text).

    Returns
    -------
    The values in order, float64, or ``None`` when some token is outside the plain grammar, a
    mantissa exceeds 2**53, a line has the wrong count or there are more than ``max_values``
    numbers (the caller then uses a general parser). Separators are ASCII whitespace (tab, LF, VT,
    FF, CR, space); other control bytes make a token invalid, as in ``float()``.

    Examples
    --------
    >>> parse_decimals(b"-0.5 12.25\\n3 4\\n").tolist()
    [-0.5, 12.25, 3.0, 4.0]
    >>> parse_decimals(b"1e3") is None
    True
    """
    b = np.frombuffer(data, dtype=np.uint8)
    start = min(max(int(start), 0), b.size)
    capacity = (b.size - start) // 2 + 1  # a number and a separator take two bytes at least
    if max_values is not None:
        capacity = min(capacity, max(int(max_values), 0))
    out = np.empty(capacity)
    rows = -1 if row_length is None else int(row_length)
    count = _kernel()(b, start, rows, out, _POW10, _EXACT_LIMIT)
    if count < 0:
        return None
    return out[:count] if count == capacity else out[:count].copy()
