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

Two implementations give the same values bit for bit (tested on random text and real files): the
compiled pass, used once the process runs compiled kernels (:func:`motion.jitcache.compiled_ready`:
``segue warm`` compiled them into numba's cache, as ``segue serve`` and ``segue worker`` do at
start), and the vectorised numpy passes it replaced (~15 ms for that clip, 3-7 ms for a bundled
salsa sample: whole tokens found with a few array passes, digits read as 8-byte words with the
SWAR trick), used otherwise -- importing numba and loading the kernel cost ~0.75 s, and compiling
it ~0.5 CPU-s, which a command-line call that reads a few files should not pay for ~10 ms.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt

from .jitcache import compiled_ready

_POW10 = 10.0 ** np.arange(9)


@lru_cache(maxsize=1)
def _kernel() -> Callable[..., int]:
    """The compiled scanner (numba is imported and the kernel loaded on first use)."""
    from .jitcache import configure

    configure()
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
    data: bytes,
    start: int = 0,
    row_length: int | None = None,
    max_values: int | None = None,
    compiled: bool | None = None,
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
    compiled:
        Use the compiled pass (``True``) or the numpy passes (``False``); default: the compiled
        one once the process runs compiled kernels (module docstring).

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
    start = min(max(int(start), 0), len(data))
    capacity = (len(data) - start) // 2 + 1  # a number and a separator take two bytes at least
    if max_values is not None:
        capacity = min(capacity, max(int(max_values), 0))
    out = np.empty(capacity)
    count = parse_decimals_into(data, out, start, row_length, compiled)
    if count is None:
        return None
    return out[:count] if count == capacity else out[:count].copy()


def parse_decimals_into(
    data: bytes,
    out: npt.NDArray[np.float64],
    start: int = 0,
    row_length: int | None = None,
    compiled: bool | None = None,
) -> int | None:
    """:func:`parse_decimals` into a preallocated buffer: the values of ``data[start:]`` are
    written to ``out[:count]`` (``out``: 1-D float64, C-contiguous) and ``count`` is returned;
    ``None`` as for :func:`parse_decimals`, or when ``out`` cannot hold them all (what was
    written is then undefined). No other array of the values' size is made: a caller that knows
    a bound on the count (a BVH reader: rows x channels) holds the numbers once.

    >>> buf = np.empty(4)
    >>> parse_decimals_into(b"1 2.5\\n-3 4\\n", buf), buf.tolist()
    (4, [1.0, 2.5, -3.0, 4.0])
    """
    if out.ndim != 1 or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError("out must be a 1-D C-contiguous float64 array")
    start = min(max(int(start), 0), len(data))
    if not (compiled_ready() if compiled is None else compiled):
        return _vectorized(data, start, row_length, out)
    b = np.frombuffer(data, dtype=np.uint8)
    rows = -1 if row_length is None else int(row_length)
    count = _kernel()(b, start, rows, out, _POW10, _EXACT_LIMIT)
    return None if count < 0 else int(count)


# ------------------------------------------------------------------ the numpy passes

_U64 = np.uint64
_ASCII_ZERO_X8 = _U64(0x3030303030303030)
_LOW7_X8 = _U64(0x7F7F7F7F7F7F7F7F)
_HIGH1_X8 = _U64(0x8080808080808080)
_DIGIT_GUARD_X8 = _U64(0x7676767676767676)  # byte + 0x76 sets the high bit iff byte >= 10
# Keep the top n bytes of a little-endian word (n = 0..8): the last n characters before its end.
_KEEP_TOP = np.array([((1 << 64) - 1) ^ ((1 << (8 * (8 - n))) - 1) for n in range(9)], dtype=np.uint64)
_SIGNED_POW10 = np.concatenate((10.0 ** np.arange(9), -(10.0 ** np.arange(9))))  # index k + 9*negative
_POW10_INT = np.array([10**n for n in range(9)], dtype=np.uint64)
_EXACT_LIMIT = 2**53
_PAD = 8
_MINUS, _DOT, _NEWLINE = 45, 46, 10


def _byte_words(data: bytes) -> npt.NDArray[np.uint64]:
    """``data`` seen as overlapping little-endian uint64 words, one starting at every byte
    (a zero-copy strided view); ``words[p - 8]`` holds the 8 bytes before position ``p``."""
    return np.ndarray(shape=(len(data) - 7,), dtype="<u8", buffer=data, strides=(1,))


def _swar_digits(
    words: npt.NDArray[np.uint64], n_digits: npt.NDArray[np.intp]
) -> tuple[npt.NDArray[np.uint64], bool]:
    """Value of the last ``n_digits`` ASCII digits of each word, and whether they all are digits."""
    v = (words ^ _ASCII_ZERO_X8) & _KEEP_TOP[n_digits]
    ok = not np.any((((v & _LOW7_X8) + _DIGIT_GUARD_X8) | v) & _HIGH1_X8)
    v = ((v & _U64(0x0F0F0F0F0F0F0F0F)) * _U64(2561)) >> _U64(8)
    v = ((v & _U64(0x00FF00FF00FF00FF)) * _U64(6553601)) >> _U64(16)
    v = ((v & _U64(0x0000FFFF0000FFFF)) * _U64(42949672960001)) >> _U64(32)
    return v, ok


_CHUNK_BYTES = 1 << 19


def _vectorized(data: bytes, start: int, row_length: int | None, out: npt.NDArray[np.float64]) -> int | None:
    """:func:`parse_decimals_into` by vectorised numpy passes over ~512 KiB pieces cut at line
    ends (temporaries small enough to be reused from the allocator's heap), each piece's values
    written into ``out`` in turn."""
    if start < _PAD:  # words are read up to 8 bytes before a token: make room
        data, start = b" " * _PAD + bytes(data[start:]), _PAD
    whole = np.frombuffer(data, dtype=np.uint8)
    words = _byte_words(data)
    count = 0
    pos, end = start, len(data)
    while pos < end:
        stop = data.find(b"\n", min(pos + _CHUNK_BYTES, end))
        stop = end if stop < 0 else stop + 1
        piece = _parse_piece(whole, words, pos, stop, row_length)
        if piece is None or count + piece.size > out.size:
            return None
        out[count : count + piece.size] = piece
        count += piece.size
        pos = stop
    return count


def _parse_piece(
    whole: npt.NDArray[np.uint8],
    words: npt.NDArray[np.uint64],
    start: int,
    stop: int,
    row_length: int | None,
) -> npt.NDArray[np.float64] | None:
    """Parse ``whole[start:stop]`` (``start >= 8``; ``stop`` just after a line end or at the end)."""
    b = whole[start - 1 : stop]
    token = (b != 32) & ((b < 9) | (b > 13))  # not ASCII whitespace
    token[0] = False  # the byte before `start` is context only
    edges = np.flatnonzero(token[1:] != token[:-1])
    if token[-1]:
        edges = np.append(edges, token.size - 1)
    starts = edges[0::2] + 1
    ends = edges[1::2] + 1  # exclusive, relative to b
    n = starts.size
    if n == 0:
        return np.zeros(0)

    if row_length is not None:
        line_ends = np.flatnonzero(b == _NEWLINE)
        per_line = np.diff(np.searchsorted(starts, line_ends), prepend=0, append=n)
        if np.any((per_line != 0) & (per_line != row_length)):
            return None
    negative = b[starts] == _MINUS  # a '-' anywhere else fails the digit checks below
    dots = np.flatnonzero(b[1:] == _DOT) + 1  # b[0] is context before `start`
    if dots.size == n and np.all(dots > starts) and np.all(dots < ends):
        point = dots  # the usual case: every token has exactly one decimal point
        n_frac = ends - point - 1
    else:
        point = ends.copy()
        if dots.size:
            owner = np.searchsorted(starts, dots, side="right") - 1
            if np.any(np.diff(owner) == 0) or np.any(dots >= ends[owner]):
                return None  # two points in a token
            point[owner] = dots
        n_frac = np.where(point < ends, ends - point - 1, 0)
    n_int = point - starts - negative
    if n_int.max() > 8 or n_frac.max() > 8 or np.any(n_int + n_frac == 0) or n_int.min() < 0:
        return None

    base = start - 1
    int_part, ok_int = _swar_digits(words[point + (base - 8)], n_int)
    frac_part, ok_frac = _swar_digits(words[ends + (base - 8)], n_frac)
    if not (ok_int and ok_frac):
        return None  # some other character inside a token
    mantissa = int_part * _POW10_INT[n_frac] + frac_part
    if int(mantissa.max()) > _EXACT_LIMIT:
        return None
    values: npt.NDArray[np.float64] = mantissa.astype(np.float64) / _SIGNED_POW10[n_frac + negative * 9]
    return values
