"""Rotation transfer and root placement: round trips, kept skeleton, scaled root path, rest
rotations of unmapped joints, bad input."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from motion import MotionError
from motion import rotations as rot
from motion.io import load_motion
from motion.retarget import retarget
from motion.retarget.transfer import _frame, frame_matrix, shortest_arc

from .characters import LIMBS, angle_deg, bone_directions, character, renamed_limbs, walk


def test_shortest_arc_and_frames() -> None:
    a = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    b = np.array([[0.0, 3.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]])
    q = shortest_arc(a, b)
    moved = rot.rotate(q, a / np.linalg.norm(a, axis=1, keepdims=True))
    np.testing.assert_allclose(moved[:3], b[:3] / np.linalg.norm(b[:3], axis=1, keepdims=True), atol=1e-12)
    np.testing.assert_allclose(q[3], rot.IDENTITY)  # a zero vector: no rotation
    m = frame_matrix(np.array([0.0, 2.0, 0.0]), np.array([1.0, 0.5, 0.0]))
    np.testing.assert_allclose(m, np.eye(3), atol=1e-12)


def test_round_trip_within_one_degree() -> None:
    """A -> B -> A: the CMU-Daz walk onto the 31-joint CMU skeleton (other spine, no fingers, other
    proportions, other units) and back onto the walk's own skeleton."""
    a = walk(240)
    b = load_motion("sample:start-walk-stop").slice(0, 1)
    there = retarget(a, b, feet="free")
    back = retarget(there, a.slice(0, 1), feet="free")
    err = angle_deg(bone_directions(a, LIMBS), bone_directions(back, LIMBS))
    assert err.max() < 1.0, f"limbs off by up to {err.max():.3f} deg after a round trip"
    cmu_limbs = (("LeftHip", "LeftKnee"), ("RightKnee", "RightAnkle"), ("LeftShoulder", "LeftElbow"))
    mid = angle_deg(
        bone_directions(a, LIMBS[:1] + LIMBS[3:4] + LIMBS[4:5]), bone_directions(there, cmu_limbs)
    )
    assert mid.max() < 1.0


def test_output_keeps_the_characters_skeleton_and_units() -> None:
    src = walk(90)
    char = character("bandai-namco", scale=0.01)  # metres
    char = replace(char, units="m")
    out = retarget(src, char)
    assert out.skeleton is char.skeleton and out.units == "m" and out.fps == src.fps
    assert out.num_frames == src.num_frames
    np.testing.assert_array_equal(out.joint_translations, np.repeat(char.joint_translations, 90, axis=0))


def test_root_path_scales_with_hip_height() -> None:
    src = walk(240)
    for scale in (0.8, 1.25):
        char = character("mixamo", scale=scale)
        out = retarget(src, char)
        hs, ho = src.global_positions()[:, 0], out.global_positions()[:, 0]
        path_s = np.linalg.norm(np.diff(hs[:, [0, 2]], axis=0), axis=1).sum()
        path_o = np.linalg.norm(np.diff(ho[:, [0, 2]], axis=0), axis=1).sum()
        ref = character("mixamo", scale=1.0)
        expected = scale * retarget(src, ref).global_positions()[:, 0, 1].mean() / hs[:, 1].mean()
        assert path_o / path_s == pytest.approx(scale * expected / scale, rel=0.05)
        # the hips stand at the character's height: the scaled source's, above its floor
        assert ho[:, 1].mean() / hs[:, 1].mean() == pytest.approx(expected, rel=0.05)


def test_unmapped_joints_keep_their_rest_rotation() -> None:
    src = load_motion("sample:start-walk-stop").slice(0, 120)  # no fingers, no eyes
    char = character("humanoid")
    out = retarget(src, char)
    for name in ("lIndex1", "rThumb2", "leftEye"):
        j = char.skeleton.index(name)
        np.testing.assert_allclose(
            out.rotations[:, j], np.repeat(char.rotations[:1, j], 120, axis=0), atol=1e-12
        )


def test_zero_and_first_rest_poses_give_the_same_directions() -> None:
    src = walk(60)
    first = character("unreal")
    zero = replace(first, rotations=np.tile(rot.IDENTITY, first.rotations.shape[:2] + (1,)))
    a = retarget(src, first, feet="free")
    b = retarget(src, zero, feet="free")
    limbs = renamed_limbs("unreal")
    assert angle_deg(bone_directions(a, limbs), bone_directions(b, limbs)).max() < 1e-3


def test_non_finite_input_is_an_error() -> None:
    src = walk(10)
    bad = np.array(src.rotations, copy=True)
    bad[3, 5] = np.nan
    with pytest.raises(MotionError, match="motion has non-finite rotations"):
        retarget(replace(src, rotations=bad), character("mixamo"))


BOXING = Path(__file__).resolve().parents[2] / "data" / "bvh-corpus" / "Boxing_Toes.bvh.gz"


def test_collars_starting_at_one_point_take_the_shoulders_axis() -> None:
    """A chest whose neck and both collars start at one point (the corpus's Boxing_Toes: the
    collars' rest bones have zero length) spans its left-right axis with the shoulders below them.
    Before, the rest frame had no lateral axis and the retarget died in scipy on a null matrix."""
    src = load_motion(BOXING).slice(0, 300)
    out = retarget(src, load_motion("sample:walk").slice(0, 1), feet="free")
    ps, pt = src.global_positions(), out.global_positions()
    sn, tn = src.skeleton.names, out.skeleton.names
    s_axis = ps[:, sn.index("LeftShoulder")] - ps[:, sn.index("RightShoulder")]
    t_axis = pt[:, tn.index("lShldr")] - pt[:, tn.index("rShldr")]
    unit = lambda v: v / np.linalg.norm(v, axis=-1, keepdims=True)  # noqa: E731
    assert angle_deg(unit(s_axis), unit(t_axis)).max() < 5.0


def test_a_frame_without_axes_takes_the_nearest_good_frames_and_a_rest_pose_without_is_refused() -> None:
    up = np.tile([0.0, 1.0, 0.0], (5, 1))
    lateral = np.tile([1.0, 0.0, 0.0], (5, 1))
    lateral[2] = 0.0  # coincident left and right joints
    lateral[3] = [0.0, 2.0, 0.0]  # left-right along up
    m = _frame(up, lateral, "the chest's axes", rest=False)
    np.testing.assert_allclose(m, np.tile(np.eye(3), (5, 1, 1)), atol=1e-12)
    with pytest.raises(MotionError, match="the chest's axes do not span a plane in every frame"):
        _frame(up, np.zeros((5, 3)), "the chest's axes", rest=False)
    with pytest.raises(MotionError, match="rest pose: the chest's axes do not span a plane: a zero-length"):
        _frame(up[:1], lateral[2:3], "rest pose: the chest's axes", rest=True)
