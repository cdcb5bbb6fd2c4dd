"""Ground frames, mirroring, resampling and motion container behaviour."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from motion import Motion, MotionError
from motion import rotations as rot
from motion.ground import add_ground_root, from_ground_frame, ground_frames, heading, to_ground_frame
from motion.mirror import mirror, mirror_label, mirror_map
from motion.resample import resample, sample_at

from .synthetic import rerigged, walking_biped


@pytest.mark.parametrize("heading_deg", [0.0, 90.0, -135.0])
def test_heading_follows_walking_direction(heading_deg: float) -> None:
    m = walking_biped(heading_deg=heading_deg)
    h = heading(m)
    np.testing.assert_allclose(np.angle(np.exp(1j * (h - np.radians(heading_deg)))), 0.0, atol=0.05)


def test_ground_frame_round_trip_and_forward_axis() -> None:
    m = walking_biped(heading_deg=90.0)
    pos = m.global_positions()
    origin, h = ground_frames(m, pos)
    local = to_ground_frame(pos, origin, h)
    np.testing.assert_allclose(from_ground_frame(local, origin, h), pos, atol=1e-12)
    # the left thigh is on the body's left: +X in the ground frame
    assert np.all(local[:, m.skeleton.index("lThigh"), 0] > 0)
    np.testing.assert_allclose(local[:, 0, [0, 2]], 0.0, atol=1e-12)


def test_add_ground_root_keeps_global_positions() -> None:
    m = walking_biped(heading_deg=30.0)
    g = add_ground_root(m, smooth_s=0.2)
    assert g.skeleton.names[0] == "ground" and g.num_joints == m.num_joints + 1
    np.testing.assert_allclose(g.global_positions()[:, 1:], m.global_positions(), atol=1e-12)
    np.testing.assert_allclose(g.root_positions[:, 1], 0.0)
    with pytest.raises(MotionError):
        add_ground_root(g)


def test_mirror_pairs_and_exact_reflection() -> None:
    m = walking_biped()
    partner, side = mirror_map(m.skeleton.names)
    assert m.skeleton.names[partner[m.skeleton.index("lThigh")]] == "rThigh"
    assert side[m.skeleton.index("lHand")] == 1 and side[m.skeleton.index("rHand")] == -1
    assert side[m.skeleton.index("spine")] == 0
    mm = mirror(m)
    expected = m.global_positions()[:, partner] * np.array([-1.0, 1, 1])
    np.testing.assert_allclose(mm.global_positions(), expected, atol=1e-12)
    np.testing.assert_allclose(mirror(mm).global_positions(), m.global_positions(), atol=1e-12)


def mean_angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per joint, the angle (degrees) between the mean rotations of ``a`` and ``b`` ``(F, J, 4)``."""

    def mean(q: np.ndarray) -> np.ndarray:
        signs = np.sign(np.einsum("fjk,jk->fj", q, q[0]))
        total = (q * signs[..., None]).sum(axis=0)
        return total / np.linalg.norm(total, axis=-1, keepdims=True)

    dots = np.abs((mean(a) * mean(b)).sum(axis=-1))
    return np.degrees(2 * np.arccos(np.clip(dots, 0.0, 1.0)))


def test_mirror_keeps_the_skeletons_conventions() -> None:
    # a T-pose rig: the plain reflection (M L M, M o) everywhere, bit for bit
    m = walking_biped()
    partner, _ = mirror_map(m.skeleton.names)
    mm = mirror(m)
    np.testing.assert_array_equal(mm.rotations, m.rotations[:, partner] * np.array([1.0, -1, -1, 1]))
    np.testing.assert_array_equal(mm.skeleton.offsets, m.skeleton.offsets[partner] * np.array([-1.0, 1, 1]))
    # the same motion on a rig whose bones run along local axes: the mirror image keeps the rig
    # (same offsets, rotations like the clip's own), so a clip and its mirror image can be cut
    # together and blended; the plain reflection reversed every bone and turned every frame
    # half way round (blending across such a cut spread 180-degree jumps over the window)
    quarter = rot.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.pi / 2)
    r = rerigged(m, quarter)
    np.testing.assert_allclose(r.global_positions(), m.global_positions(), atol=1e-12)
    rm = mirror(r)
    np.testing.assert_allclose(rm.global_positions(), mm.global_positions(), atol=1e-12)
    np.testing.assert_allclose(mirror(rm).global_positions(), r.global_positions(), atol=1e-12)
    np.testing.assert_allclose(rm.skeleton.offsets, r.skeleton.offsets, atol=1e-12)
    np.testing.assert_allclose(rm.skeleton.end_site_offsets, r.skeleton.end_site_offsets, atol=1e-12)
    assert mean_angles_deg(rm.rotations, r.rotations).max() < 10.0
    # the mirror image of the T-pose rig, re-rigged, is the mirror image of the re-rigged motion
    np.testing.assert_allclose(
        np.abs((rerigged(mm, quarter).rotations * rm.rotations).sum(-1)), 1.0, atol=1e-9
    )


@pytest.mark.parametrize(
    ("label", "mirrored"),
    [
        ("wave-left-hand", "wave-right-hand"),
        ("walk-turn-right", "walk-turn-left"),
        ("raiseLeftHand", "raiseRightHand"),
        ("Walk Left", "Walk Right"),
        ("LEFT_HAND", "RIGHT_HAND"),
        ("left", "right"),
        ("walk", "walk"),
        ("bright", "bright"),
        ("leftover", "leftover"),
        ("Leftover", "Leftover"),
    ],
)
def test_mirror_label_exchanges_the_side_a_label_names(label: str, mirrored: str) -> None:
    assert mirror_label(label) == mirrored
    assert mirror_label(mirrored) == label


@pytest.mark.parametrize(
    ("names", "pairs"),
    [
        (("LeftArm", "RightArm", "Spine"), {"LeftArm": "RightArm"}),
        (("Hand_L", "Hand_R", "Head"), {"Hand_L": "Hand_R"}),
        (("lhand", "rhand", "lowerback"), {"lhand": "rhand"}),
        (("CC_Base_L_Foot", "CC_Base_R_Foot"), {"CC_Base_L_Foot": "CC_Base_R_Foot"}),
        (("hand.L", "hand.R"), {"hand.L": "hand.R"}),
    ],
)
def test_mirror_map_spellings(names: tuple[str, ...], pairs: dict[str, str]) -> None:
    partner, side = mirror_map(names)
    for left, right in pairs.items():
        assert names[partner[names.index(left)]] == right
        assert side[names.index(left)] == 1
    assert sum(side == 0) == len(names) - 2 * len(pairs)


def test_resample_halves_and_keeps_shape() -> None:
    m = walking_biped(frames=121, fps=60.0)
    r = resample(m, 30.0)
    assert r.fps == 30.0 and r.num_frames == 61
    np.testing.assert_allclose(r.global_positions(), m.global_positions()[::2], atol=1e-12)
    up = resample(m, 120.0)
    assert up.num_frames == 241
    # halfway samples are slerps: their rotation is halfway between the neighbours
    a, b, mid = m.rotations[10], m.rotations[11], up.rotations[21]
    np.testing.assert_allclose(rot.angle_between(a, mid), rot.angle_between(mid, b), atol=1e-9)
    with pytest.raises(MotionError):
        resample(m, 0.0)
    with pytest.raises(MotionError):
        sample_at(m, np.array([-1.0]))


def test_motion_validation_and_slicing() -> None:
    m = walking_biped(frames=10)
    with pytest.raises(MotionError):
        Motion(m.skeleton, m.root_positions[:5], m.rotations, 30.0)
    with pytest.raises(MotionError):
        replace(m, fps=0.0)
    with pytest.raises(MotionError):
        replace(m, units="furlongs")
    with pytest.raises(MotionError):
        m.slice(20)
    s = m.slice(2, 5)
    assert s.num_frames == 3
    np.testing.assert_allclose(s.global_positions(), m.global_positions()[2:5])
    cm = m.to_units("cm")
    np.testing.assert_allclose(cm.global_positions(), m.global_positions() * 100)
    with pytest.raises(MotionError):
        m.with_units("unknown").to_units("m")


def test_body_root_is_the_hips_even_under_a_static_root() -> None:
    from motion import Skeleton
    from motion.ground import body_root
    from motion.skeleton import default_channels

    m = walking_biped(frames=30)
    assert m.skeleton.names[body_root(m.skeleton)] == "hips"
    # a Bandai-style static joint 0 above the hips: the ground frame follows the hips
    sk = m.skeleton
    names = ("joint_Root", *sk.names)
    channels = list(default_channels(len(names)))
    channels[1] = channels[0]  # the hips carry positions too, as in Bandai-Namco files
    static = Skeleton(
        names,
        np.concatenate(([-1], sk.parents + 1)),
        np.concatenate((np.zeros((1, 3)), sk.offsets)),
        tuple(channels),
    )
    rot0 = np.concatenate((rot.identity((30, 1)), m.rotations), axis=1)
    jt = m.root_positions[:, None]
    moved = Motion(static, np.zeros((30, 3)), rot0, 30.0, jt, "m")
    assert static.names[body_root(static)] == "hips"
    origin, _ = ground_frames(moved)
    np.testing.assert_allclose(origin, m.root_positions[:, [0, 2]], atol=1e-12)
