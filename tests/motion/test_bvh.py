"""BVH reader and writer on small synthetic files written by the tests.

Expected values come from hand computations (the golden chain) or from the independent matrix
FK of :mod:`bvh_helpers`, never from :mod:`motion.rotations` or scipy's ``Rotation``.
"""

from __future__ import annotations

import gzip
import io
import re
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest

import motion
from motion import BvhError, BvhLimits, parse_bvh, read_bvh, write_bvh
from motion.bvh import bvh_text
from motion.errors import ReadWarning

from .bvh_helpers import (
    POSITION_XYZ,
    TAIT_BRYAN_ORDERS,
    JointSpec,
    bvh_text_from_spec,
    euler_matrix,
    quat_to_matrix,
    random_channel_rows,
    read_raw_bvh,
    reference_fk,
    rot_channels,
    rotation_angle,
)

ROOT6 = POSITION_XYZ + rot_channels("ZXY")


def parse_text(text: str, **kwargs: object) -> motion.Motion:
    return parse_bvh(text.encode("utf-8"), **kwargs)  # type: ignore[arg-type]


def assert_matches_reference(m: motion.Motion, text: str, tol: float = 1e-9) -> None:
    """Global rotations, joint and End Site positions agree with the independent FK."""
    raw = read_raw_bvh(text.encode())
    ref = reference_fk(raw)
    pos, grot = m.fk()
    np.testing.assert_allclose(pos, ref.positions, atol=tol, rtol=0, err_msg="global joint positions")
    np.testing.assert_allclose(
        quat_to_matrix(grot), ref.rotations, atol=tol, rtol=0, err_msg="global rotations"
    )
    np.testing.assert_allclose(
        m.end_site_positions(pos, grot), ref.end_sites, atol=tol, rtol=0, err_msg="End Sites"
    )


# A chain used by many tests: root (6 channels) -> thigh -> shin -> End Site.
def chain(
    root_channels: tuple[str, ...] = ROOT6,
    thigh_channels: tuple[str, ...] = rot_channels("ZXY"),
    shin_channels: tuple[str, ...] = rot_channels("ZXY"),
) -> list[JointSpec]:
    return [
        JointSpec("Hips", -1, (1.0, 90.0, -2.0), root_channels),
        JointSpec("Thigh", 0, (10.0, -5.0, 0.5), thigh_channels),
        JointSpec("Shin", 1, (0.0, -40.0, 3.0), shin_channels, end_sites=((0.0, -8.0, 12.0),)),
    ]


# --------------------------------------------------------------------------------------------
# channel layouts
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("order", TAIT_BRYAN_ORDERS)
def test_every_tait_bryan_order_is_intrinsic_in_file_order(order: str) -> None:
    joints = chain(POSITION_XYZ + rot_channels(order), rot_channels(order), rot_channels(order[::-1]))
    rows = random_channel_rows(joints, 7, np.random.default_rng(len(order) + ord(order[0])))
    text = bvh_text_from_spec(joints, rows)
    m = parse_text(text)
    assert m.skeleton.channels[0][3:] == rot_channels(order)
    assert m.skeleton.rotation_order(0) == order and m.skeleton.rotation_order(2) == order[::-1]
    expected_root = euler_matrix(order, rows[:, 3:6])
    np.testing.assert_allclose(quat_to_matrix(m.rotations[:, 0]), expected_root, atol=1e-12, rtol=0)
    # The same numbers read in the reverse order (extrinsic) give another rotation: the test
    # above would notice an order mix-up.
    assert rotation_angle(euler_matrix(order[::-1], rows[:, 3:6][:, ::-1]), expected_root).max() > 1e-3
    assert_matches_reference(m, text)


def test_position_channels_on_a_non_root_joint_replace_the_offset() -> None:
    joints = [
        JointSpec("Root", -1, (0.0, 0.0, 0.0), ROOT6),
        JointSpec("Slider", 0, (9.0, 9.0, 9.0), POSITION_XYZ + rot_channels("ZYX")),
        JointSpec("YOnly", 1, (4.0, 5.0, 6.0), ("Yposition", *rot_channels("XYZ"))),
        JointSpec("Tip", 2, (1.0, 0.0, 0.0), rot_channels("YZX"), end_sites=((0.0, 1.0, 0.0),)),
    ]
    rows = np.zeros((2, 19))
    # frame 0: Slider at local (1, 2, 3), rotated 90 deg about Z; everything else zero.
    rows[0, 6:12] = [1.0, 2.0, 3.0, 90.0, 0.0, 0.0]
    rows[0, 12] = 7.0  # YOnly's Y position; its X and Z stay 4 and 6
    rows[1] = random_channel_rows(joints, 1, np.random.default_rng(3))[0]
    text = bvh_text_from_spec(joints, rows)
    m = parse_text(text)
    assert m.skeleton.translated_joints.tolist() == [1, 2]
    np.testing.assert_allclose(m.joint_translations[0], [[1.0, 2.0, 3.0], [4.0, 7.0, 6.0]])
    pos = m.global_positions()
    # Slider = (1, 2, 3) (the channels replace OFFSET 9 9 9, they are not added to it).
    # YOnly = Slider + Rz(90) (4, 7, 6) = (1, 2, 3) + (-7, 4, 6) = (-6, 6, 9)
    # Tip = YOnly + Rz(90) (1, 0, 0) = (-6, 6, 9) + (0, 1, 0) = (-6, 7, 9)
    np.testing.assert_allclose(
        pos[0, 1:], [[1.0, 2.0, 3.0], [-6.0, 6.0, 9.0], [-6.0, 7.0, 9.0]], atol=1e-12, rtol=0
    )
    assert_matches_reference(m, text)


def test_three_channel_root_keeps_its_offset_as_position() -> None:
    joints = chain(root_channels=rot_channels("ZYX"))
    rows = random_channel_rows(joints, 5, np.random.default_rng(5))
    text = bvh_text_from_spec(joints, rows)
    m = parse_text(text)
    assert m.skeleton.num_channels == 9
    np.testing.assert_array_equal(m.root_positions, np.tile([1.0, 90.0, -2.0], (5, 1)))
    assert_matches_reference(m, text)


def test_six_channels_on_every_joint() -> None:
    # Bandai-Namco layout: Xposition Yposition Zposition Zrotation Xrotation Yrotation everywhere.
    joints = chain(ROOT6, ROOT6, ROOT6)
    rows = random_channel_rows(joints, 6, np.random.default_rng(6))
    text = bvh_text_from_spec(joints, rows)
    m = parse_text(text)
    assert m.skeleton.translated_joints.tolist() == [1, 2]
    np.testing.assert_array_equal(m.joint_translations[:, 0], rows[:, 6:9])
    np.testing.assert_array_equal(m.joint_translations[:, 1], rows[:, 12:15])
    assert_matches_reference(m, text)


def test_rotation_channels_on_fewer_than_three_axes() -> None:
    joints = chain(ROOT6, ("Xrotation",), ("Zrotation", "Yrotation"))
    rows = random_channel_rows(joints, 4, np.random.default_rng(8))
    text = bvh_text_from_spec(joints, rows)
    m = parse_text(text)
    assert [m.skeleton.rotation_order(j) for j in range(3)] == ["ZXY", "X", "ZY"]
    assert_matches_reference(m, text)


def test_end_sites() -> None:
    joints = [
        JointSpec("Hips", -1, (0.0, 1.0, 0.0), ROOT6),
        JointSpec("Head", 0, (0.0, 0.5, 0.0), rot_channels("ZXY"), end_sites=((0.0, 0.2, 0.0),)),
        JointSpec(
            "Hand", 0, (0.6, 0.4, 0.0), rot_channels("XYZ"), end_sites=((0.1, 0.0, 0.0), (0.0, 0.0, 0.1))
        ),
    ]
    rows = random_channel_rows(joints, 3, np.random.default_rng(9))
    text = bvh_text_from_spec(joints, rows)
    m = parse_text(text)
    assert m.skeleton.end_site_parents.tolist() == [1, 2, 2]
    np.testing.assert_array_equal(
        m.skeleton.end_site_offsets, [[0.0, 0.2, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, 0.1]]
    )
    assert m.end_site_positions().shape == (3, 3, 3)
    assert_matches_reference(m, text)


# --------------------------------------------------------------------------------------------
# text variants: whitespace, line ends, gzip, numbers, names, frame time
# --------------------------------------------------------------------------------------------


def _same_motion(a: motion.Motion, b: motion.Motion) -> None:
    assert a.skeleton.names == b.skeleton.names
    assert a.skeleton.channels == b.skeleton.channels
    np.testing.assert_array_equal(a.skeleton.parents, b.skeleton.parents)
    np.testing.assert_array_equal(a.skeleton.offsets, b.skeleton.offsets)
    np.testing.assert_array_equal(a.skeleton.end_site_offsets, b.skeleton.end_site_offsets)
    np.testing.assert_array_equal(a.root_positions, b.root_positions)
    np.testing.assert_array_equal(a.rotations, b.rotations)
    assert a.fps == b.fps


@pytest.mark.parametrize(
    ("indent", "newline", "sep"),
    [
        ("    ", "\n", " "),
        ("\t", "\r\n", "\t"),
        ("  ", "\r\n", "  "),
        ("\t \t", "\n", " \t "),
    ],
    ids=["spaces-lf", "tabs-crlf", "double-spaces-crlf", "mixed"],
)
def test_whitespace_and_line_ends_do_not_matter(indent: str, newline: str, sep: str) -> None:
    joints = chain()
    rows = random_channel_rows(joints, 4, np.random.default_rng(10))
    plain = parse_text(bvh_text_from_spec(joints, rows))
    variant_text = bvh_text_from_spec(joints, rows, indent=indent, newline=newline, sep=sep)
    assert (newline in variant_text) and (sep in variant_text)
    _same_motion(plain, parse_text(variant_text))


def test_tabs_after_frames_and_trailing_blank_lines() -> None:
    text = bvh_text_from_spec(chain(), random_channel_rows(chain(), 3, np.random.default_rng(11)))
    text = text.replace("Frames: 3", "Frames:\t3").replace("Frame Time: ", "Frame Time:\t") + "\n\n  \n"
    m = parse_text(text)
    assert m.num_frames == 3 and m.fps == 30.0


def test_gzip_is_detected_by_content(tmp_path: Path) -> None:
    joints = chain()
    text = bvh_text_from_spec(joints, random_channel_rows(joints, 5, np.random.default_rng(12)))
    plain = parse_text(text)
    packed = gzip.compress(text.encode())
    _same_motion(plain, parse_bvh(packed))
    (tmp_path / "walk.bvh.gz").write_bytes(packed)
    (tmp_path / "disguised.bvh").write_bytes(packed)  # gzip content without a .gz name
    (tmp_path / "plain.bvh.gz").write_bytes(text.encode())  # plain text with a .gz name
    for name, stem in [("walk.bvh.gz", "walk"), ("disguised.bvh", "disguised"), ("plain.bvh.gz", "plain")]:
        m = read_bvh(tmp_path / name)
        _same_motion(plain, m)
        assert m.name == stem


def test_numbers_with_exponents_parse() -> None:
    # Bandai-Namco files write small numbers as 5.1072e-06; the general path must take them.
    joints = chain()
    rows = np.zeros((3, 12))
    rows[0, 0] = 5.1072e-06
    rows[1, 3] = -1.25e-3
    rows[2, 1] = 2.5e2
    text = bvh_text_from_spec(joints, rows, number_format="%.6g").replace(
        "OFFSET 1 90 -2", "OFFSET 1e0 9.0E+01 -2"
    )
    assert "5.1072e-06" in text and "9.0E+01" in text
    m = parse_text(text)
    assert m.root_positions[0, 0] == 5.1072e-06
    assert m.root_positions[2, 1] == 250.0
    np.testing.assert_array_equal(m.skeleton.offsets[0], [1.0, 90.0, -2.0])
    assert_matches_reference(m, text)


def test_joint_names_are_kept() -> None:
    joints = [
        JointSpec("mixamorig:Hips", -1, (0.0, 0.0, 0.0), ROOT6),
        JointSpec("Left Up Leg", 0, (0.1, 0.0, 0.0), rot_channels("ZXY")),
        JointSpec(
            "joint_LeftFoot.001", 1, (0.0, -0.5, 0.0), rot_channels("ZXY"), end_sites=((0.0, 0.0, 0.1),)
        ),
    ]
    rows = random_channel_rows(joints, 2, np.random.default_rng(13))
    m = parse_text(bvh_text_from_spec(joints, rows))
    assert m.skeleton.names == ("mixamorig:Hips", "Left Up Leg", "joint_LeftFoot.001")
    assert m.skeleton.index("Left Up Leg") == 1
    again = parse_text(bvh_text(m))
    assert again.skeleton.names == m.skeleton.names


@pytest.mark.parametrize(
    ("frame_time", "fps"),
    [
        ("0.008333", 120.0),
        ("0.00833333", 120.0),
        ("0.0083333333", 120.0),
        ("0.016667", 60.0),
        ("0.033333", 30.0),
        ("0.0333333", 30.0),
        ("0.04", 25.0),
        ("0.1", 10.0),
        ("0.0125", 80.0),
        ("0.0095", 1.0 / 0.0095),  # 105.26 fps is not near an integer rate: kept as is
        ("0.3", 1.0 / 0.3),
    ],
)
def test_fps_from_frame_time(frame_time: str, fps: float) -> None:
    m = parse_text(bvh_text_from_spec(chain(), np.zeros((2, 12)), frame_time=frame_time))
    assert m.fps == pytest.approx(fps, rel=1e-12, abs=0.0)


def test_read_bvh_names_the_file_in_errors(tmp_path: Path) -> None:
    p = tmp_path / "broken.bvh"
    p.write_text("HIERARCHY\nROOT a\n{\n")
    with pytest.raises(BvhError) as info:
        read_bvh(p)
    assert info.value.source == str(p) and str(p) in str(info.value)
    with pytest.raises(BvhError, match="cannot read"):
        read_bvh(tmp_path / "missing.bvh")


# --------------------------------------------------------------------------------------------
# golden values computed by hand
# --------------------------------------------------------------------------------------------

GOLDEN = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Knee
  {
    OFFSET 0 -10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Ankle
    {
      OFFSET 0 -5 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 0 2
      }
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.033333
1 2 3 90 0 0 0 90 0 0 0 0
0 0 0 0 90 90 0 0 0 0 0 0
0 0 0 0 0 0 0 0 0 0 0 0
"""


def test_golden_chain_global_positions() -> None:
    """Hand-computed positions of a 3-joint chain with 90-degree rotations.

    Rz(90) takes (x, y, z) to (-y, x, z); Rx(90) takes (x, y, z) to (x, -z, y); Ry(90) takes
    (x, y, z) to (z, y, -x). Rotation channels are intrinsic, in file order: R = Rz Rx Ry.

    Frame 0: root at (1, 2, 3), root rotation Rz(90); Knee rotation Rx(90); Ankle identity.
      Knee  = (1, 2, 3) + Rz90 (0, -10, 0) = (1, 2, 3) + (10, 0, 0) = (11, 2, 3)
      Ankle = Knee + Rz90 Rx90 (0, -5, 0) = Knee + Rz90 (0, 0, -5) = (11, 2, 3) + (0, 0, -5) = (11, 2, -2)
      End   = Ankle + Rz90 Rx90 (0, 0, 2) = Ankle + Rz90 (0, -2, 0) = (11, 2, -2) + (2, 0, 0) = (13, 2, -2)
    Frame 1: root at (0, 0, 0), root rotation Rz(0) Rx(90) Ry(90) (extrinsic reading would give
    Ry(90) Rx(90) instead and put the Knee at (-10, 0, 0)).
      Knee  = Rx90 Ry90 (0, -10, 0) = Rx90 (0, -10, 0) = (0, 0, -10)
      Ankle = Knee + Rx90 Ry90 (0, -5, 0) = (0, 0, -10) + (0, 0, -5) = (0, 0, -15)
      End   = Ankle + Rx90 Ry90 (0, 0, 2) = Ankle + Rx90 (2, 0, 0) = (0, 0, -15) + (2, 0, 0) = (2, 0, -15)
    Frame 2: rest pose: Hips (0, 0, 0), Knee (0, -10, 0), Ankle (0, -15, 0), End (0, -15, 2).
    """
    m = parse_text(GOLDEN)
    expected = np.array(
        [
            [[1.0, 2.0, 3.0], [11.0, 2.0, 3.0], [11.0, 2.0, -2.0]],
            [[0.0, 0.0, 0.0], [0.0, 0.0, -10.0], [0.0, 0.0, -15.0]],
            [[0.0, 0.0, 0.0], [0.0, -10.0, 0.0], [0.0, -15.0, 0.0]],
        ]
    )
    expected_end = np.array([[[13.0, 2.0, -2.0]], [[2.0, 0.0, -15.0]], [[0.0, -15.0, 2.0]]])
    np.testing.assert_allclose(m.global_positions(), expected, atol=1e-12, rtol=0)
    np.testing.assert_allclose(m.end_site_positions(), expected_end, atol=1e-12, rtol=0)
    assert m.fps == 30.0 and m.num_frames == 3


# --------------------------------------------------------------------------------------------
# errors: a BvhError naming the line and the problem
# --------------------------------------------------------------------------------------------

BASE_LINES = [
    "HIERARCHY",  # 1
    "ROOT Hips",  # 2
    "{",  # 3
    "\tOFFSET 0 0 0",  # 4
    "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",  # 5
    "\tJOINT Chest",  # 6
    "\t{",  # 7
    "\t\tOFFSET 0 10 0",  # 8
    "\t\tCHANNELS 3 Zrotation Xrotation Yrotation",  # 9
    "\t\tEnd Site",  # 10
    "\t\t{",  # 11
    "\t\t\tOFFSET 0 5 0",  # 12
    "\t\t}",  # 13
    "\t}",  # 14
    "}",  # 15
    "MOTION",  # 16
    "Frames: 3",  # 17
    "Frame Time: 0.033333",  # 18
    "0.0 90.0 0.0 1.5 -2.5 10.0 20.0 30.0 40.0",  # 19
    "0.5 91.0 0.0 1.5 -2.5 10.0 20.0 30.0 40.0",  # 20
    "1.0 92.0 0.0 1.5 -2.5 10.0 20.0 30.0 40.0",  # 21
]


def base_text(newline: str = "\n") -> str:
    return newline.join(BASE_LINES) + newline


def edit(changes: dict[int, str | None], newline: str = "\n") -> str:
    """BASE_LINES with 1-based line ``k`` replaced by ``changes[k]`` (``None`` deletes it)."""
    out = []
    for k, line in enumerate(BASE_LINES, start=1):
        new = changes.get(k, line)
        if new is not None:
            out.append(new)
    return newline.join(out) + newline


def eof_lines(text: str) -> set[int]:
    """Acceptable line numbers for "the file ends too early": the last line, or the empty line after
    the final newline."""
    n = text.count("\n")
    return {n, n + 1}


def test_base_text_is_valid() -> None:
    m = parse_text(base_text())
    assert m.num_frames == 3 and m.skeleton.names == ("Hips", "Chest")


ROW = "0.0 90.0 0.0 1.5 -2.5 10.0 20.0 30.0 40.0"


def channels9(listing: str) -> str:
    """The base text with line 9 (Chest's CHANNELS) replaced."""
    return edit({9: "\t\tCHANNELS " + listing})


NO_MOTION = edit({k: None for k in range(16, 22)})
NO_ROWS = edit({19: None, 20: None, 21: None})
NON_FINITE = r"(non-finite|not( a)? finite)"

ERROR_CASES: list[tuple[str, str, int | set[int], str]] = [
    # (id, text, expected line(s), regex the message must match)
    ("missing-motion", NO_MOTION, eof_lines(NO_MOTION), r"MOTION"),
    ("frames-not-a-number", edit({17: "Frames: abc"}), 17, r"Frames.*'abc'.*not an integer"),
    ("frames-negative", edit({17: "Frames: -2"}), 17, r"Frames"),
    ("frames-missing", edit({17: None}), 17, r"Frames"),
    ("frame-time-not-a-number", edit({18: "Frame Time: fast"}), 18, r"Frame Time.*'fast'"),
    ("frame-time-zero", edit({18: "Frame Time: 0"}), 18, r"Frame Time"),
    ("non-numeric-value", edit({20: ROW.replace("-2.5", "abc")}), 20, r"frame 1.*'abc'.*not a number"),
    ("non-numeric-exponent-path", edit({19: ROW.replace("90.0", "9e1"), 21: ROW.replace("30.0", "3O.0")}), 21,
     r"frame 2.*'3O\.0'"),
    ("too-few-values", edit({20: " ".join(ROW.split()[:8])}), 20, r"frame 1 has 8 values, expected 9"),
    ("too-many-values", edit({19: ROW + " 50.0"}), 19, r"frame 0 has 10 values, expected 9"),
    ("no-frame-lines", NO_ROWS, eof_lines(NO_ROWS), r"0 of the 3"),
    ("truncated-last-line", edit({21: " ".join(ROW.split()[:5])}), 21, r"frame 2 has 5 values.*cut short"),
    ("mixed-decimal-commas", edit({20: ROW.replace("1.5", "1,5")}), 20, r"'1,5' is not a number.*commas"),
    ("nan-value", edit({20: ROW.replace("20.0", "nan")}), 20, r"frame 1.*" + NON_FINITE),
    ("inf-value", edit({19: ROW.replace("40.0", "-inf")}), 19, r"frame 0.*" + NON_FINITE),
    ("overflowing-value", edit({21: ROW.replace("10.0", "1e999")}), 21, r"frame 2.*" + NON_FINITE),
    ("nan-offset", edit({8: "\t\tOFFSET 0 nan 0"}), 8, r"OFFSET.*'nan'.*finite"),
    ("offset-not-a-number", edit({8: "\t\tOFFSET 0 ten 0"}), 8, r"OFFSET.*'ten'.*not a number"),
    ("offset-too-short", edit({12: "\t\t\tOFFSET 0 5"}), 12, r"OFFSET needs 3 numbers"),
    ("unknown-channel", channels9("3 Zrotation Wrotation Yrotation"), 9, r"unknown channel 'Wrotation'"),
    ("channels-count-larger", channels9("3 Zrotation Xrotation"), 9, r"declares 3 channels but lists 2"),
    ("channels-count-bad", channels9("three Zrotation Xrotation Yrotation"), 9, r"CHANNELS count"),
    ("channels-count-over-6", channels9("7 Zrotation Xrotation Yrotation"), 9, r"CHANNELS count 7"),
    ("channel-twice", channels9("3 Zrotation Xrotation Zrotation"), 9, r"listed twice"),
    ("missing-close-brace", edit({14: None}), 14, r"missing '\}'"),
    ("extra-close-brace", edit({15: "}\n}"}), 16, r"unbalanced '\}'"),
    ("missing-open-brace", edit({7: None}), 7, r"expected '\{' after JOINT"),
    ("duplicate-joint-name", edit({6: "\tJOINT Hips"}), 6, r"duplicate joint name 'Hips'"),
    ("joint-without-name", edit({6: "\tJOINT"}), 6, r"JOINT without a name"),
    ("joint-without-offset", edit({8: None}), 13, r"'Chest' has no OFFSET"),
    ("joint-without-channels", edit({9: None}), 13, r"'Chest' has no CHANNELS"),
    ("end-site-without-offset", edit({12: None}), 12, r"End Site without OFFSET"),
    ("missing-hierarchy", edit({1: "HIERARCHIE"}), 1, r"expected HIERARCHY"),
    ("unexpected-token", edit({10: "\t\tEnd Sight", 11: "\t\t{ banana"}), 11, r"unexpected 'banana'"),
]  # fmt: skip


def _check_error(text: str | bytes, line: int | set[int] | None, pattern: str, **kwargs: object) -> BvhError:
    data = text.encode() if isinstance(text, str) else text
    with pytest.raises(BvhError) as info:
        parse_bvh(data, **kwargs)  # type: ignore[arg-type]
    err = info.value
    lines: set[int | None] = set(line) if isinstance(line, set) else {line}
    assert err.line in lines, f"reported line {err.line}, expected {sorted(lines, key=str)}: {err}"
    assert re.search(pattern, err.problem), f"message {err.problem!r} does not match {pattern!r}"
    if err.line is not None:
        assert f":{err.line}: " in str(err), f"the message {str(err)!r} does not show the line"
    return err


@pytest.mark.parametrize(
    ("text", "line", "pattern"), [c[1:] for c in ERROR_CASES], ids=[c[0] for c in ERROR_CASES]
)
def test_malformed_file_raises_bvh_error_naming_line(text: str, line: int | set[int], pattern: str) -> None:
    _check_error(text, line, pattern)


@pytest.mark.parametrize(
    ("text", "line", "pattern"), [c[1:] for c in ERROR_CASES], ids=[c[0] for c in ERROR_CASES]
)
def test_error_lines_are_the_same_with_crlf_and_gzip(text: str, line: int | set[int], pattern: str) -> None:
    crlf = text.replace("\n", "\r\n")
    _check_error(crlf, line, pattern)
    _check_error(gzip.compress(crlf.encode()), line, pattern)


def test_joint_limit() -> None:
    text = base_text()
    assert parse_text(text, limits=BvhLimits(max_joints=2)).num_joints == 2
    _check_error(text, 6, r"1-joint limit", limits=BvhLimits(max_joints=1))


def test_frame_limit() -> None:
    text = base_text()
    assert parse_text(text, limits=BvhLimits(max_frames=3)).num_frames == 3
    _check_error(text, 17, r"Frames: 3 is over the 2-frame limit", limits=BvhLimits(max_frames=2))


def test_byte_limit() -> None:
    text = base_text()
    with pytest.raises(BvhError, match="byte limit"):
        parse_text(text, limits=BvhLimits(max_bytes=100))
    with pytest.raises(BvhError, match="byte limit"):
        parse_bvh(gzip.compress(text.encode()), limits=BvhLimits(max_bytes=100))


@pytest.mark.parametrize("data", [b"", b"   \n\r\n\t\n"], ids=["empty", "blank"])
def test_empty_file(data: bytes) -> None:
    with pytest.raises(BvhError, match="empty") as info:
        parse_bvh(data)
    assert info.value.line in (None, 1)


def test_corrupt_gzip() -> None:
    packed = gzip.compress(base_text().encode())
    with pytest.raises(BvhError, match="gzip"):
        parse_bvh(packed[:10] + bytes(b ^ 0x5A for b in packed[10:40]) + packed[40:])
    with pytest.raises(BvhError, match="truncated"):
        parse_bvh(packed[: len(packed) // 2])
    with pytest.raises(BvhError, match="gzip"):
        parse_bvh(packed[:-8] + b"\0\0\0\0" + packed[-4:])  # wrong CRC


def test_multi_member_gzip_is_read_whole() -> None:
    text = base_text().encode()
    cut = text.index(b"0.5 91.0")  # second frame line
    packed = gzip.compress(text[:cut]) + gzip.compress(text[cut:])  # as `cat a.gz b.gz` makes
    assert gzip.decompress(packed) == text
    assert parse_bvh(packed).num_frames == 3


def test_unknown_units_argument() -> None:
    with pytest.raises(BvhError, match="unknown units"):
        parse_text(base_text(), units="furlong")
    assert parse_text(base_text(), units="cm").units == "cm"


@pytest.mark.parametrize(
    "rows",
    [
        [ROW + " 50.0", " ".join(ROW.split()[:-1]), ROW],  # 10 + 8 + 9 values on 3 lines
        [ROW + " " + ROW, "", ROW],  # 18 + 0 + 9 values: a blank line makes 3 lines
    ],
    ids=["plain-decimals", "blank-line"],
)
def test_values_that_add_up_but_not_per_line_are_rejected(rows: list[str]) -> None:
    text = edit({19: rows[0], 20: rows[1], 21: rows[2]})
    _check_error(text, 19, r"frame 0 has (10|18) values, expected 9")


@pytest.mark.parametrize("n_lines", [19, 20])
def test_file_ending_without_newline_inside_the_frames(n_lines: int) -> None:
    text = "\n".join(BASE_LINES[:n_lines])  # no final newline, the last frame line is line n_lines
    notes: list[ReadWarning] = []
    m = parse_bvh(text.encode(), warnings=notes)
    assert m.num_frames == n_lines - 18
    assert [(w.code, w.line) for w in notes] == [("frame_count", 17)]


def test_file_ending_without_newline_after_frame_time() -> None:
    text = "\n".join(BASE_LINES[:18])
    _check_error(text, eof_lines(text), r"0 of the 3")


def test_channels_listing_more_names_than_its_count() -> None:
    text = channels9("3 Zrotation Xrotation Yrotation Xposition")
    _check_error(text, 9, r"CHANNELS declares 3 channels but lists 4")


def test_huge_declared_frame_count_does_not_allocate_it() -> None:
    # Regression: the slow path used to allocate Frames x channels floats up front (92 GiB here,
    # a MemoryError instead of a BvhError for a 110 KB file within the default limits).
    n = 1024  # the default joint limit, 6 channels each
    lines = ["HIERARCHY", "ROOT j0", "{", "OFFSET 0 0 0", "CHANNELS 6 " + " ".join(ROOT6)]
    for i in range(1, n):
        lines += [f"JOINT j{i}", "{", "OFFSET 0 1 0", "CHANNELS 6 " + " ".join(ROOT6)]
    lines += ["}"] * n + ["MOTION", "Frames: 2000000", "Frame Time: 0.1", " ".join(["0"] * (6 * n))]
    data = "\n".join(lines).encode()
    tracemalloc.start()
    try:
        with pytest.raises(BvhError, match="joint-frame limit") as info:
            parse_bvh(data)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert info.value.line == len(lines) - 2  # the Frames: line
    assert peak < 1 << 30, f"reading a {len(data)}-byte file allocated {peak / 2**30:.1f} GiB"
    # within the joint-frame limit, the one line present is read (a warning says Frames: is off)
    notes: list[ReadWarning] = []
    m = parse_bvh(data, limits=BvhLimits(max_joint_frames=2_000_000 * n), warnings=notes)
    assert m.num_frames == 1 and [w.code for w in notes] == ["missing_end_site", "frame_count"]


def test_huge_finite_values_give_bvh_error_or_finite_positions() -> None:
    # Regression: finite values such as 1e308 used to overflow in the FK of detect_units (a
    # RuntimeWarning, an error under this project's pytest settings).
    # Root X position 1e308 on every frame plus Chest's OFFSET 1e308 along X: the sum overflows.
    big_row = ROW.replace("0.0 90.0", "1e308 90.0", 1)
    text = edit({8: "\t\tOFFSET 1e308 0 0", 19: big_row, 20: big_row, 21: big_row})
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # as in pyproject's pytest settings
        try:
            m = parse_text(text)
        except BvhError:
            return
        assert np.isfinite(m.global_positions()).all()


# --------------------------------------------------------------------------------------------
# writing and the round trip
# --------------------------------------------------------------------------------------------

ROUND_TRIP_SKELETONS: dict[str, list[JointSpec]] = {
    "cmu-like": chain(POSITION_XYZ + rot_channels("ZYX"), rot_channels("ZXY"), rot_channels("ZXY")),
    "bandai-like": chain(ROOT6, ROOT6, ROOT6),
    "three-channel-root": chain(rot_channels("YXZ"), rot_channels("XZY"), rot_channels("YZX")),
    "partial-positions": chain(
        ("Yposition", *rot_channels("XYZ")), ("Zposition", *rot_channels("ZYX")), ("Xrotation", "Zrotation")
    ),
    **{
        f"order-{o}": chain(POSITION_XYZ + rot_channels(o), rot_channels(o), rot_channels(o))
        for o in TAIT_BRYAN_ORDERS
    },
}


def _channel_columns(joints: list[JointSpec]) -> tuple[list[int], list[tuple[str, list[int]]]]:
    """Position columns, and per joint with rotations its order and rotation columns."""
    pos_cols: list[int] = []
    rot_groups: list[tuple[str, list[int]]] = []
    col = 0
    for spec in joints:
        order, cols = "", []
        for c in spec.channels:
            if c.endswith("position"):
                pos_cols.append(col)
            else:
                order += c[0]
                cols.append(col)
            col += 1
        if order:
            rot_groups.append((order, cols))
    return pos_cols, rot_groups


def _round_trip(text: str) -> tuple[motion.Motion, str, motion.Motion]:
    m = parse_text(text)
    written = bvh_text(m)
    return m, written, parse_text(written)


def _assert_same_skeleton(a: motion.Motion, b: motion.Motion) -> None:
    sa, sb = a.skeleton, b.skeleton
    assert sa.names == sb.names, "names"
    assert sa.parents.tolist() == sb.parents.tolist(), "parents"
    assert sa.channels == sb.channels, "channel orders"
    np.testing.assert_allclose(sb.offsets, sa.offsets, atol=1e-6, rtol=0, err_msg="offsets")
    assert sa.end_site_parents.tolist() == sb.end_site_parents.tolist(), "End Site parents"
    np.testing.assert_allclose(
        sb.end_site_offsets, sa.end_site_offsets, atol=1e-6, rtol=0, err_msg="End Sites"
    )


@pytest.mark.parametrize("name", list(ROUND_TRIP_SKELETONS))
def test_round_trip_with_canonical_angles_reproduces_the_channels(name: str) -> None:
    joints = ROUND_TRIP_SKELETONS[name]
    rows = random_channel_rows(joints, 40, np.random.default_rng(sum(map(ord, name))))
    text = bvh_text_from_spec(joints, rows, number_format="%.9f")
    m, written, again = _round_trip(text)
    _assert_same_skeleton(m, again)
    assert again.num_frames == m.num_frames and again.fps == m.fps
    table = read_raw_bvh(written.encode()).values
    # Angles in the canonical range (first/last in (-180, 180], middle in [-90, 90], away from
    # gimbal lock) come back as the same numbers; everything to 1e-6.
    np.testing.assert_allclose(table, rows, atol=1e-6, rtol=0)
    np.testing.assert_allclose(again.global_positions(), m.global_positions(), atol=1e-5, rtol=0)


@pytest.mark.parametrize("name", list(ROUND_TRIP_SKELETONS))
def test_round_trip_with_any_angles_reproduces_the_rotations(name: str) -> None:
    joints = ROUND_TRIP_SKELETONS[name]
    rng = np.random.default_rng(1000 + sum(map(ord, name)))
    rows = random_channel_rows(joints, 60, rng)
    pos_cols, rot_groups = _channel_columns(joints)
    rot_cols = [c for _, cols in rot_groups for c in cols]
    rows[:, rot_cols] = rng.uniform(-720.0, 720.0, (rows.shape[0], len(rot_cols)))  # far outside
    for _, cols in rot_groups:  # a few gimbal-locked poses: middle angle exactly +-90
        if len(cols) == 3:
            rows[:4, cols[1]] = [90.0, -90.0, 270.0, -270.0]
    text = bvh_text_from_spec(joints, rows, number_format="%.9f")
    m, written, again = _round_trip(text)
    _assert_same_skeleton(m, again)
    table = read_raw_bvh(written.encode()).values
    np.testing.assert_allclose(table[:, pos_cols], rows[:, pos_cols], atol=1e-6, rtol=0, err_msg="positions")
    for order, cols in rot_groups:
        angle = rotation_angle(euler_matrix(order, table[:, cols]), euler_matrix(order, rows[:, cols]))
        assert angle.max() < 1e-6, f"order {order}, columns {cols}: rotations differ by {angle.max():.2e} rad"
    np.testing.assert_allclose(again.global_positions(), m.global_positions(), atol=1e-5, rtol=0)


def test_written_text_is_readable_by_the_independent_reader() -> None:
    joints = ROUND_TRIP_SKELETONS["partial-positions"]
    rows = random_channel_rows(joints, 5, np.random.default_rng(77))
    m = parse_text(bvh_text_from_spec(joints, rows))
    written = bvh_text(m)
    assert written.startswith("HIERARCHY\nROOT Hips\n")
    assert "\r" not in written and "\nMOTION\nFrames: 5\nFrame Time: 0.033333" in written
    raw = read_raw_bvh(written.encode())
    assert raw.names == ["Hips", "Thigh", "Shin"] and raw.parents == [-1, 0, 1]
    assert raw.end_site_parents == [2] and raw.end_site_offsets == [[0.0, -8.0, 12.0]]
    np.testing.assert_allclose(reference_fk(raw).positions, m.global_positions(), atol=1e-5)


def test_round_trip_of_the_golden_file_and_of_fps() -> None:
    m, written, again = _round_trip(GOLDEN.replace("0.033333", "0.008333"))
    assert m.fps == 120.0 and again.fps == 120.0
    _assert_same_skeleton(m, again)
    np.testing.assert_allclose(again.global_positions(), m.global_positions(), atol=1e-6)


def test_write_bvh_to_paths_and_streams(tmp_path: Path) -> None:
    joints = ROUND_TRIP_SKELETONS["cmu-like"]
    m = parse_text(bvh_text_from_spec(joints, random_channel_rows(joints, 6, np.random.default_rng(21))))
    write_bvh(m, tmp_path / "out.bvh")
    write_bvh(m, str(tmp_path / "out.bvh.gz"))
    stream = io.StringIO()
    write_bvh(m, stream)
    assert (tmp_path / "out.bvh.gz").read_bytes()[:2] == b"\x1f\x8b"
    assert (tmp_path / "out.bvh").read_text() == stream.getvalue() == bvh_text(m)
    for name in ("out.bvh", "out.bvh.gz"):
        again = read_bvh(tmp_path / name)
        _assert_same_skeleton(m, again)
        np.testing.assert_allclose(again.global_positions(), m.global_positions(), atol=1e-5)


def test_writing_a_rotating_joint_without_rotation_channels_fails() -> None:
    joints = chain(ROOT6, POSITION_XYZ, rot_channels("ZXY"))
    m = parse_text(bvh_text_from_spec(joints, random_channel_rows(joints, 2, np.random.default_rng(4))))
    assert parse_text(bvh_text(m)).num_joints == 3  # no rotation read, none to write: fine
    q = m.rotations.copy()
    q[:, 1] = [0.0, 0.0, np.sin(0.25), np.cos(0.25)]
    rotated = motion.Motion(m.skeleton, m.root_positions, q, m.fps, m.joint_translations, m.units, m.name)
    with pytest.raises(motion.ExportError, match="'Thigh' rotates"):
        bvh_text(rotated)


END_SITE_FIRST = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 3 Zrotation Xrotation Yrotation
  End Site
  {
    OFFSET 0 -1 0
  }
  JOINT Chest
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 1
Frame Time: 0.1
10 20 30 40 50 60
"""


def test_round_trip_keeps_end_site_order_when_an_end_site_precedes_a_joint() -> None:
    m, _, again = _round_trip(END_SITE_FIRST)
    assert m.skeleton.end_site_parents.tolist() == [0, 1]  # as read: file order
    _assert_same_skeleton(m, again)


def test_round_trip_keeps_end_sites_when_an_end_site_precedes_a_joint() -> None:
    # The same End Sites come back at the same places.
    m, _, again = _round_trip(END_SITE_FIRST)

    def sites(x: motion.Motion) -> list[tuple[int, list[float], list[float]]]:
        sk = x.skeleton
        pos = x.end_site_positions()[0]
        return sorted(
            (int(p), off.tolist(), np.round(q, 6).tolist())
            for p, off, q in zip(sk.end_site_parents, sk.end_site_offsets, pos, strict=True)
        )

    assert [s[:2] for s in sites(m)] == [(0, [0.0, -1.0, 0.0]), (1, [0.0, 5.0, 0.0])]
    assert sites(again) == sites(m)


def test_utf8_byte_order_mark_is_accepted() -> None:
    from motion.samples import sample_path

    text = gzip.decompress(sample_path("walk").read_bytes())
    with_bom = parse_bvh(b"\xef\xbb\xbf" + text)
    plain = parse_bvh(text)
    np.testing.assert_array_equal(with_bom.rotations, plain.rotations)


def test_gzip_members_larger_than_an_inflated_piece_are_read_once() -> None:
    # Regression: when a member's end came in a call cut by the output limit, the bytes after it
    # stayed in zlib's unconsumed_tail and were fed again after the end: the reader looped for ever
    # (a two-member gzip whose first member inflates past 1 MiB; its memory grew without bound).
    # In a child process with a hang guard, so that a regression fails instead of hanging the run.
    import subprocess
    import sys

    code = (
        "import gzip; from motion.bvh import inflate_chunks\n"
        "one = b'0.5 ' * 2000\n"
        "out = b''.join(inflate_chunks(gzip.compress(one) * 3, 1 << 20, 's', chunk=1024))\n"
        "assert out == one * 3, len(out)\n"
        "print('ok')\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]
    text = base_text().encode()
    cut = text.index(b"0.5 91.0")
    packed = gzip.compress(text[:cut]) + gzip.compress(text[cut:])
    from motion.bvh import inflate_chunks

    assert b"".join(inflate_chunks(packed, 1 << 20, "s", chunk=16)) == text
