"""``motion.numparse.parse_decimals`` (both implementations) against Python's ``float``.

Inside the plain grammar ``-?[0-9]{0,8}(\\.[0-9]{0,8})?`` (at least one digit) the values must be
bit-identical to ``float(token)``; anything else must give ``None``. The one documented escape:
a mantissa (all digits of a token) above 2**53 may also give ``None`` (the general parser then
takes over), since the fast path divides an exact integer mantissa by a power of ten.
"""

from __future__ import annotations

import re
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motion.numparse import parse_decimals
from tests.thoroughness import examples


def parse(
    data: bytes, start: int = 0, row_length: int | None = None, max_values: int | None = None
) -> np.ndarray | None:
    """``parse_decimals`` by both implementations (compiled, numpy passes), which must agree bit for
    bit (or both give ``None``); their common answer."""
    compiled = parse_decimals(data, start, row_length, max_values, compiled=True)
    vectorized = parse_decimals(data, start, row_length, max_values, compiled=False)
    assert (compiled is None) == (vectorized is None), (compiled, vectorized)
    if compiled is not None and vectorized is not None:
        assert compiled.dtype == vectorized.dtype and compiled.shape == vectorized.shape
        assert np.array_equal(compiled.view(np.uint64), vectorized.view(np.uint64))
    return compiled


PLAIN = re.compile(rb"-?[0-9]{0,8}(\.[0-9]{0,8})?")
SEPARATORS = [" ", "\t", "\n", "\r\n", "  ", " \t", "\t\r\n", "\n\n"]
PIECE = 1 << 19  # parse_decimals works in ~512 KiB pieces


def is_plain(tok: bytes) -> bool:
    return PLAIN.fullmatch(tok) is not None and any(c in b"0123456789" for c in tok)


def mantissa_fits(tok: bytes) -> bool:
    digits = tok.replace(b"-", b"").replace(b".", b"")
    return int(digits or b"0") <= 2**53


def reference(tokens: list[bytes]) -> np.ndarray:
    return np.array([float(t) for t in tokens], dtype=np.float64)


def assert_bit_identical(got: np.ndarray | None, tokens: list[bytes]) -> None:
    expected = reference(tokens)
    assert got is not None, f"plain decimals rejected: {tokens[:8]!r}..."
    assert got.dtype == np.float64 and got.shape == expected.shape, f"shape {got.shape} vs {expected.shape}"
    bad = np.flatnonzero(got.view(np.uint64) != expected.view(np.uint64))
    if bad.size:
        i = int(bad[0])
        pytest.fail(f"{bad.size} values differ, first {tokens[i]!r}: got {got[i]!r}, float() {expected[i]!r}")


def check_plain(data: bytes, tokens: list[bytes]) -> None:
    """``data`` holds exactly ``tokens`` (all plain): bit-identical, or None only for huge mantissas."""
    got = parse(data)
    if got is None and not all(mantissa_fits(t) for t in tokens):
        return
    assert_bit_identical(got, tokens)


# --------------------------------------------------------------------------------------------
# strategies
# --------------------------------------------------------------------------------------------

finite = st.floats(min_value=-9.9e7, max_value=9.9e7, allow_nan=False, allow_infinity=False)


@st.composite
def plain_tokens(draw: st.DrawFn) -> bytes:
    """A random float formatted with ``%.{k}f``, sometimes as ``.5``/``-.5`` or ``12.``."""
    x = draw(st.one_of(finite, st.sampled_from([0.0, -0.0, 1e-9, -1e-9, 0.5, -0.5])))
    k = draw(st.integers(0, 8))
    s = f"%.{k}f" % x
    style = draw(st.sampled_from(["as-is", "no-leading-zero", "trailing-dot"]))
    if style == "no-leading-zero" and re.match(r"-?0\.", s):
        s = s.replace("0.", ".", 1)
    elif style == "trailing-dot" and "." not in s:
        s += "."
    return s.encode()


@st.composite
def joined(draw: st.DrawFn, tokens: st.SearchStrategy[list[bytes]]) -> tuple[bytes, list[bytes]]:
    """Tokens joined by random whitespace, with optional leading and trailing whitespace."""
    toks = draw(tokens)
    seps = draw(st.lists(st.sampled_from(SEPARATORS), min_size=len(toks) + 1, max_size=len(toks) + 1))
    lead = draw(st.sampled_from(["", " ", "\n", "\t \r\n"]))
    out = lead.encode()
    for tok, sep in zip(toks, seps, strict=False):
        out += tok + sep.encode()
    strip: bool = draw(st.booleans())
    if toks and strip:
        out = out.rstrip()  # no trailing separator at all
    return out, toks


ODD_BYTES = sorted(set(range(33, 127)) | {0x80, 0xA0, 0xC3, 0xFF})  # printable ASCII and non-ASCII
odd_tokens = st.one_of(
    st.binary(min_size=1, max_size=12).map(lambda b: bytes(ODD_BYTES[x % len(ODD_BYTES)] for x in b)),
    st.text(alphabet="0123456789.-+eE", min_size=1, max_size=20).map(str.encode),
)


# --------------------------------------------------------------------------------------------
# plain decimals: bit-identical to float()
# --------------------------------------------------------------------------------------------


@settings(max_examples=examples(400), deadline=None)
@given(joined(st.lists(plain_tokens(), min_size=1, max_size=60)))
def test_plain_decimals_are_bit_identical_to_float(case: tuple[bytes, list[bytes]]) -> None:
    data, tokens = case
    check_plain(data, tokens)


@settings(max_examples=examples(200), deadline=None)
@given(
    k=st.integers(0, 8),
    xs=st.lists(finite, min_size=1, max_size=40),
    sep=st.sampled_from(SEPARATORS),
)
def test_fixed_width_columns_as_in_mocap_files(k: int, xs: list[float], sep: str) -> None:
    # The usual case: every token with the same number of decimals, one decimal point each.
    tokens = [(f"%.{k}f" % x).encode() for x in xs]
    check_plain(sep.encode().join(tokens) + b"\n", tokens)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (b"-0.0", [-0.0]),
        (b"-0", [-0.0]),
        (b"-.0 0. .0", [-0.0, 0.0, 0.0]),
        (b".5 -.25 7. -7.", [0.5, -0.25, 7.0, -7.0]),
        (b"00000012.50000000", [12.5]),
        (b"12345678.12345678", [12345678.12345678]),
        (b"0.1 0.2 0.3", [0.1, 0.2, 0.3]),
        (b"\t1\r\n2\n\n3 \r\n", [1.0, 2.0, 3.0]),
    ],
)
def test_edge_cases(text: bytes, expected: list[float]) -> None:
    got = parse(text)
    assert got is not None
    exp = np.array(expected)
    assert np.array_equal(got.view(np.uint64), exp.view(np.uint64)), f"{text!r}: {got} vs {exp}"


@pytest.mark.parametrize("text", [b"", b" ", b"\n\r\n\t  \n"], ids=["empty", "space", "blank-lines"])
def test_no_numbers_gives_an_empty_array(text: bytes) -> None:
    got = parse(text)
    assert got is not None and got.shape == (0,) and got.dtype == np.float64


def _long_text(
    rng: np.random.Generator, n_lines: int, per_line: int, decimals: int, newline: str
) -> tuple[bytes, list[bytes]]:
    values = rng.uniform(-2000.0, 2000.0, (n_lines, per_line))
    values[rng.random(values.shape) < 0.01] = -0.0
    fmt = f"%.{decimals}f"
    lines = [" ".join(fmt % v for v in row) for row in values]
    text = (newline.join(lines) + newline).encode()
    return text, text.split()


@pytest.mark.parametrize(
    ("n_lines", "per_line", "decimals", "newline"),
    [(5000, 60, 6, "\n"), (3100, 93, 4, "\r\n"), (20000, 11, 8, "\n"), (7, 40000, 5, "\n")],
    ids=["cmu-like", "crlf", "short-lines", "very-long-lines"],
)
def test_long_files_spanning_several_pieces(n_lines: int, per_line: int, decimals: int, newline: str) -> None:
    rng = np.random.default_rng(n_lines)
    text, tokens = _long_text(rng, n_lines, per_line, decimals, newline)
    assert len(text) > 2.5 * PIECE, "the input should span several pieces"
    assert_bit_identical(parse(text), tokens)


@pytest.mark.parametrize("where", ["first", "middle", "last"])
def test_a_bad_token_in_any_piece_gives_none(where: str) -> None:
    text, tokens = _long_text(np.random.default_rng(2), 4000, 60, 6, "\n")
    assert len(text) > 2.5 * PIECE
    pos = {"first": 100, "middle": len(text) // 2, "last": len(text) - 20}[where]
    cut = text.index(b" ", pos)
    assert parse(text) is not None
    assert parse(text[:cut] + b" 1e-5" + text[cut:]) is None


@settings(max_examples=examples(200), deadline=None)
@given(
    prefix=st.binary(max_size=20).filter(lambda b: not b.endswith(b".")),
    case=joined(st.lists(plain_tokens(), min_size=1, max_size=10)),
)
def test_bytes_before_start_are_ignored(prefix: bytes, case: tuple[bytes, list[bytes]]) -> None:
    # Whatever precedes `start` (digits, '-', letters, non-ASCII) is context only; a '.' right
    # before `start` is tested below.
    data, tokens = case
    got = parse(prefix + data, start=len(prefix))
    if got is None and not all(mantissa_fits(t) for t in tokens):
        return
    assert_bit_identical(got, tokens)


def test_a_dot_just_before_start_is_ignored() -> None:
    data = b"Frame Time: 1." + b"5 2"
    got = parse(data, start=len(b"Frame Time: 1."))
    assert got is not None and got.tolist() == [5.0, 2.0]


# --------------------------------------------------------------------------------------------
# outside the grammar: None
# --------------------------------------------------------------------------------------------

REJECTED = [
    b"1e5",
    b"1E5",
    b"5.1072e-06",
    b"+1",
    b"+1.5",
    b"nan",
    b"NaN",
    b"inf",
    b"-inf",
    b"1.2.3",
    b"1..2",
    b"..5",
    b".",
    b"-",
    b"-.",
    b"--1",
    b"1-",
    b"1-2",
    b"1a",
    b"a",
    b"0x10",
    b"1,5",
    b"1_000",
    b"123456789",
    b"123456789.5",
    b"0.123456789",
    b"-000000001",
    b"1.5\xff",
    "１".encode(),
    "½".encode(),
    b"\xa0",
]


@pytest.mark.parametrize("bad", REJECTED, ids=[repr(b)[2:-1] for b in REJECTED])
@pytest.mark.parametrize("position", ["alone", "first", "middle", "last"])
def test_tokens_outside_the_grammar_give_none(bad: bytes, position: str) -> None:
    context = {
        "alone": bad,
        "first": bad + b" 1.5 2.5\n",
        "middle": b"1.5 " + bad + b"\t2.5\n",
        "last": b"1.5 2.5\n" + bad,
    }[position]
    assert parse(context) is None, f"{context!r} should be rejected"


@settings(max_examples=examples(500), deadline=None)
@given(joined(st.lists(st.one_of(plain_tokens(), odd_tokens), min_size=1, max_size=20)))
def test_grammar_decides_between_values_and_none(case: tuple[bytes, list[bytes]]) -> None:
    data, tokens = case
    got = parse(data)
    if all(is_plain(t) for t in tokens):
        if got is None and not all(mantissa_fits(t) for t in tokens):
            return
        assert_bit_identical(got, tokens)
    else:
        odd = next(t for t in tokens if not is_plain(t))
        assert got is None, f"{odd!r} is outside the grammar but {data!r} parsed to {got}"


@pytest.mark.parametrize("ctrl", [b"\x00", b"\x01", b"\x1b", b"\x1f"])
def test_control_characters_are_not_separators(ctrl: bytes) -> None:
    assert parse(b"1.0" + ctrl + b"2.0\n") is None


def test_max_values_bounds_the_count() -> None:
    data = b"1 2 3\n4 5 6\n"
    assert parse(data, max_values=6).tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]  # type: ignore[union-attr]
    assert parse(data, max_values=5) is None
    assert parse(data, max_values=0) is None
    assert parse(b" \n", max_values=0).tolist() == []  # type: ignore[union-attr]


def test_row_length_zero_allows_only_blank_lines() -> None:
    assert parse(b"\n \n", row_length=0).tolist() == []  # type: ignore[union-attr]
    assert parse(b"\n1\n", row_length=0) is None
    assert parse(b"1 2\n3 4", row_length=2).tolist() == [1.0, 2.0, 3.0, 4.0]  # type: ignore[union-attr]
    assert parse(b"1 2\n3", row_length=2) is None


def test_the_default_is_compiled_only_once_kernels_are_ready(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A process that was not warmed parses with the numpy passes (no compile); once
    :func:`motion.jitcache.mark_compiled_ready` was called, with the compiled pass."""
    from motion import jitcache, numparse

    used: list[str] = []
    kernel = numparse._kernel

    def spy() -> Callable[..., int]:
        used.append("compiled")
        return kernel()

    monkeypatch.setattr(numparse, "_kernel", spy)
    monkeypatch.setitem(jitcache._ready, "compiled", False)
    values = parse_decimals(b"1.5 2\n")
    assert values is not None and values.tolist() == [1.5, 2.0]
    assert used == []
    jitcache.mark_compiled_ready()
    values = parse_decimals(b"1.5 2\n")
    assert values is not None and values.tolist() == [1.5, 2.0]
    assert used == ["compiled"]
