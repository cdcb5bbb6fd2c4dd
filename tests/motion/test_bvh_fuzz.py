"""Property-based fuzzing of the BVH reader: mangled files give a valid Motion or a BvhError.

A valid small BVH text is mangled (lines deleted, duplicated or swapped; tokens replaced by random
strings or numbers; truncated; random bytes inserted, including NUL and non-UTF-8; braces
flipped; optionally gzip-compressed). ``parse_bvh`` must then either return a motion whose arrays
are all finite, or raise :class:`motion.BvhError` with a line number inside the file -- never
another exception (IndexError, ValueError, UnicodeDecodeError, zlib.error, RuntimeWarning, ...).

Replacement numbers cover the whole float64 range (1e308 must not overflow the kinematics).
"""

from __future__ import annotations

import gzip
import re
import zlib
from collections.abc import Callable

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from motion import BvhError, BvhLimits, Motion, parse_bvh
from tests.thoroughness import examples

from .bvh_helpers import POSITION_XYZ, JointSpec, bvh_text_from_spec, random_channel_rows, rot_channels

FUZZ = settings(max_examples=examples(300), deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _bases() -> list[bytes]:
    rng = np.random.default_rng(0)
    cmu = [
        JointSpec("Hips", -1, (0.0, 35.0, 0.0), POSITION_XYZ + rot_channels("ZYX")),
        JointSpec("LeftUpLeg", 0, (3.9, -1.2, 0.0), rot_channels("ZXY")),
        JointSpec("LeftLeg", 1, (0.0, -16.9, 0.0), rot_channels("ZXY"), end_sites=((0.0, -15.0, 2.0),)),
        JointSpec("Spine", 0, (0.0, 6.0, 0.0), rot_channels("ZXY"), end_sites=((0.0, 10.0, 0.0),)),
    ]
    bandai = [
        JointSpec("joint_Root", -1, (0.0, 0.0, 0.0), POSITION_XYZ + rot_channels("ZXY")),
        JointSpec("Hips", 0, (-0.7, 93.3, -2.0), POSITION_XYZ + rot_channels("ZXY")),
        JointSpec(
            "Head", 1, (15.7, 0.0, 0.0), POSITION_XYZ + rot_channels("ZXY"), end_sites=((0.0, 0.0, 0.0),)
        ),
    ]
    three = [
        JointSpec("root", -1, (0.0, 1.0, 0.0), rot_channels("YXZ")),
        JointSpec(
            "arm", 0, (0.3, 0.0, 0.0), ("Yposition", *rot_channels("XZY")), end_sites=((0.2, 0.0, 0.0),)
        ),
    ]
    return [
        bvh_text_from_spec(cmu, random_channel_rows(cmu, 4, rng), frame_time="0.008333").encode(),
        bvh_text_from_spec(
            bandai,
            random_channel_rows(bandai, 3, rng) * 1e-6,
            number_format="%.6g",
            newline="\r\n",
            indent="  ",
        ).encode(),
        bvh_text_from_spec(three, random_channel_rows(three, 3, rng), sep="\t", frame_time="0.1").encode(),
    ]


BASES = _bases()

KEYWORDS = [
    "{", "}", "ROOT", "JOINT", "End", "Site", "OFFSET", "CHANNELS", "HIERARCHY", "MOTION", "Frames:",
    "Frame", "Time:", "Xrotation", "Yrotation", "Zrotation", "Xposition", "Yposition", "Zposition",
    "Wrotation", "0", "3", "6", "7", "-1", "nan", "inf", "-inf", "1e999", "-0", "+5", "1e-320", "0x10",
    "1_0", ".", "-", "", " ", "\t", "\r\n", "\n", "\x00", "\ufeff", "é",
]  # fmt: skip

numbers = st.one_of(
    st.integers(min_value=-(10**12), max_value=10**12).map(str),
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.floats(min_value=-1e12, max_value=1e12, allow_nan=False).map(repr),
    st.floats(min_value=-1e12, max_value=1e12, allow_nan=False).map(lambda x: f"{x:.6f}"),
    st.floats(min_value=-1e12, max_value=1e12, allow_nan=False).map(lambda x: f"{x:e}"),
)
replacement_text = st.one_of(st.sampled_from(KEYWORDS), numbers, st.text(max_size=12))


# --------------------------------------------------------------------------------------------
# mutations: each draws its parameters and returns the mangled bytes
# --------------------------------------------------------------------------------------------

Mutation = Callable[[st.DataObject, bytes], bytes]


def _lines(data: bytes) -> list[bytes]:
    return data.split(b"\n")


def delete_line(d: st.DataObject, data: bytes) -> bytes:
    lines = _lines(data)
    i = d.draw(st.integers(0, len(lines) - 1), label="delete line")
    return b"\n".join(lines[:i] + lines[i + 1 :])


def duplicate_line(d: st.DataObject, data: bytes) -> bytes:
    lines = _lines(data)
    i = d.draw(st.integers(0, len(lines) - 1), label="duplicate line")
    return b"\n".join(lines[: i + 1] + lines[i:])


def swap_lines(d: st.DataObject, data: bytes) -> bytes:
    lines = _lines(data)
    i = d.draw(st.integers(0, len(lines) - 1), label="swap i")
    j = d.draw(st.integers(0, len(lines) - 1), label="swap j")
    lines[i], lines[j] = lines[j], lines[i]
    return b"\n".join(lines)


def replace_token(d: st.DataObject, data: bytes) -> bytes:
    spans = [m.span() for m in re.finditer(rb"\S+", data)]
    if not spans:
        return data
    a, b = spans[d.draw(st.integers(0, len(spans) - 1), label="token")]
    new = d.draw(replacement_text, label="replacement").encode("utf-8")
    return data[:a] + new + data[b:]


def replace_number(d: st.DataObject, data: bytes) -> bytes:
    spans = [m.span() for m in re.finditer(rb"-?[0-9][0-9.e+-]*", data)]
    if not spans:
        return data
    a, b = spans[d.draw(st.integers(0, len(spans) - 1), label="number")]
    return data[:a] + d.draw(numbers, label="new number").encode() + data[b:]


def truncate(d: st.DataObject, data: bytes) -> bytes:
    return data[: d.draw(st.integers(0, len(data)), label="truncate at")]


def insert_bytes(d: st.DataObject, data: bytes) -> bytes:
    at = d.draw(st.integers(0, len(data)), label="insert at")
    junk = d.draw(
        st.one_of(
            st.binary(min_size=1, max_size=8),
            st.sampled_from([b"\x00", b"\xff\xfe", b"\xc3", b"\x80", b"\r", b"\n", b"\x0b", b"\x1f\x8b"]),
        ),
        label="bytes",
    )
    return data[:at] + junk + data[at:]


def flip_brace(d: st.DataObject, data: bytes) -> bytes:
    where = [i for i, c in enumerate(data) if c in b"{}"]
    if not where:
        return data
    i = where[d.draw(st.integers(0, len(where) - 1), label="brace")]
    return data[:i] + (b"}" if data[i : i + 1] == b"{" else b"{") + data[i + 1 :]


MUTATIONS: list[Mutation] = [
    delete_line,
    duplicate_line,
    swap_lines,
    replace_token,
    replace_number,
    truncate,
    insert_bytes,
    flip_brace,
]


# --------------------------------------------------------------------------------------------
# the property
# --------------------------------------------------------------------------------------------


def _plain(data: bytes) -> bytes | None:
    """The text the reader sees (gunzipped when it is gzip), or None when it is not valid gzip."""
    if not data.startswith(b"\x1f\x8b"):
        return data
    try:
        return gzip.decompress(data)
    except (OSError, EOFError, zlib.error):
        return None


def assert_valid_motion(m: Motion) -> None:
    sk = m.skeleton
    assert m.num_frames >= 1 and sk.num_joints >= 1
    assert np.isfinite(m.fps) and m.fps > 0
    for name, arr in [
        ("root_positions", m.root_positions),
        ("rotations", m.rotations),
        ("joint_translations", m.joint_translations),
        ("offsets", sk.offsets),
        ("end_site_offsets", sk.end_site_offsets),
    ]:
        assert np.isfinite(arr).all(), f"non-finite {name}"
    assert m.rotations.shape == (m.num_frames, sk.num_joints, 4)
    assert np.abs(np.linalg.norm(m.rotations, axis=-1) - 1.0).max() < 1e-9, "non-unit quaternions"
    assert np.isfinite(m.global_positions()).all(), "non-finite global positions"


def check_error(err: BvhError, data: bytes) -> None:
    """The error has a message and, when it names a line, that line is in the file.

    ``last`` counts the empty line after a final newline (where "the file ends too early" is
    reported); one more is tolerated for the known off-by-one of a file ending right after
    ``Frame Time`` without a newline (see ``test_bvh.py``).
    """
    assert err.problem, "empty error message"
    text = _plain(data)
    if err.line is not None and text is not None:
        last = text.count(b"\n") + 1
        assert 1 <= err.line <= last + 1, f"line {err.line} beyond a {last}-line file: {err}"


def check_reader(data: bytes, limits: BvhLimits | None = None) -> None:
    try:
        m = parse_bvh(data, limits=limits)
    except BvhError as err:
        check_error(err, data)
        return
    assert_valid_motion(m)


def test_bases_are_valid() -> None:
    for base in BASES:
        assert_valid_motion(parse_bvh(base))


def _single(mutation: Mutation) -> Callable[[], None]:
    @FUZZ
    @given(base=st.sampled_from(BASES), d=st.data())
    def run(base: bytes, d: st.DataObject) -> None:
        check_reader(mutation(d, base))

    run.__name__ = run.__qualname__ = f"test_{mutation.__name__}"
    return run


test_delete_line = _single(delete_line)
test_duplicate_line = _single(duplicate_line)
test_swap_lines = _single(swap_lines)
test_replace_token = _single(replace_token)
test_replace_number = _single(replace_number)
test_truncate = _single(truncate)
test_insert_bytes = _single(insert_bytes)
test_flip_brace = _single(flip_brace)


@FUZZ
@given(base=st.sampled_from(BASES), d=st.data())
def test_several_mutations_and_gzip(base: bytes, d: st.DataObject) -> None:
    data = base
    for mutation in d.draw(st.lists(st.sampled_from(MUTATIONS), min_size=1, max_size=5), label="mutations"):
        data = mutation(d, data)
    packing = d.draw(st.sampled_from(["plain", "gzip", "truncated-gzip"]), label="packing")
    if packing != "plain":
        data = gzip.compress(data)
        if packing == "truncated-gzip":
            data = data[: d.draw(st.integers(0, len(data) - 1), label="gzip cut")]
    limits = d.draw(
        st.sampled_from([None, BvhLimits(max_joints=2, max_frames=2), BvhLimits(max_bytes=200)]),
        label="limits",
    )
    check_reader(data, limits)


@FUZZ
@given(data=st.binary(max_size=300))
def test_random_bytes(data: bytes) -> None:
    check_reader(data)
    check_reader(b"HIERARCHY\nROOT a\n{\n" + data)
    check_reader(BASES[0].split(b"MOTION")[0] + b"MOTION\n" + data)
